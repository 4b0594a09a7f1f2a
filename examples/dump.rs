fn main() {
    let p = std::env::args().nth(1).unwrap();
    let s = diffsvg::Scene::load(&p, diffsvg::Sizing::Width(300)).unwrap();
    println!("{}", s.to_svg_string());
}

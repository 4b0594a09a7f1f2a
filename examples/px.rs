fn main() {
    let a: Vec<String> = std::env::args().collect();
    let p = &a[1];
    let (x0, y0, n): (u32, u32, u32) = (
        a[2].parse().unwrap(),
        a[3].parse().unwrap(),
        a[4].parse().unwrap(),
    );
    let w: u32 = a.get(5).map(|s| s.parse().unwrap()).unwrap_or(300);
    let data = std::fs::read(p).unwrap();
    let tree = diffsvg::scene::svg_in::parse_tree(&data, p.as_ref()).unwrap();
    let sz = diffsvg::Sizing::Width(w);
    let s = diffsvg::scene::svg_in::from_tree(&tree, p.as_ref(), sz).unwrap();
    let ours = diffsvg::raster::render(&s, &Default::default());
    let r = diffsvg::reference::render_resvg(&tree, p.as_ref(), sz).unwrap();
    for y in y0..y0 + n {
        let row: Vec<String> = (x0..x0 + n)
            .map(|x| {
                format!(
                    "{:3}/{:3}",
                    (ours.get(x, y)[3] * 255.0).round(),
                    (r.get(x, y)[3] * 255.0).round()
                )
            })
            .collect();
        println!("{}", row.join(" "));
    }
}

//! Analytic gradients against central finite differences on random scenes.

use diffsvg::gradcheck::check;
use diffsvg::loss::Loss;
use diffsvg::raster::{RenderOptions, render};
use diffsvg::scene::ParamGroup;
use diffsvg::{Image, Scene, Sizing};

/// Asserts every group agrees to 1e-2 (relative, absolute below 1e-3 of the group's scale).
pub fn assert_agrees(name: &str, scene: &Scene, target: &Image, loss: Loss, bg: Option<[f32; 4]>) {
    let (grad, numeric, groups) = check(scene, target, loss, &RenderOptions::default(), bg, None);
    assert!(
        grad.iter().all(|g| g.is_finite()),
        "{name}: non-finite gradient"
    );
    for g in &groups {
        println!(
            "{name}: {:>9} n={:3} worst {:.2e} (analytic {:.4e}, numeric {:.4e}, slot {})",
            g.group.name(),
            g.checked,
            g.worst,
            g.worst_pair.0,
            g.worst_pair.1,
            g.worst_index
        );
    }
    for g in &groups {
        assert!(
            g.worst <= 1e-2,
            "{name}: {} gradient off by {:.3e} at slot {}: analytic {} vs numeric {}",
            g.group.name(),
            g.worst,
            g.worst_index,
            g.worst_pair.0,
            g.worst_pair.1
        );
    }
    let _ = numeric;
}

/// A target: the scene rendered with all parameters nudged, over the same background.
pub fn nudged_target(scene: &Scene, amount: f64, bg: Option<[f32; 4]>) -> Image {
    let mut t = scene.clone();
    let mut p = t.params();
    let layout = diffsvg::scene::ParamLayout::new(scene);
    for (i, v) in p.iter_mut().enumerate() {
        let k = ((i * 7919) % 13) as f64 / 13.0 - 0.5;
        *v += match layout.slots[i].group {
            ParamGroup::Points => 3.0 * amount * k,
            ParamGroup::StrokeWidth => amount * k,
            _ => 0.2 * amount * k,
        };
    }
    t.set_params(&p);
    let mut img = render(&t, &RenderOptions::default());
    if let Some(bg) = bg {
        img.over_background(bg);
    }
    img
}

fn scene(svg: &str) -> Scene {
    Scene::from_svg_str(svg, "test.svg", Sizing::Natural).unwrap()
}

#[test]
fn filled_curves_solid() {
    let s = scene(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="48" height="40">
        <path id="a" d="M 5 5 C 20 0 40 10 38 30 L 10 35 Z" fill="rgb(200,40,30)" fill-opacity="0.8"/>
        <path id="b" d="M 20 8 Q 45 20 25 36 L 12 20 Z" fill="rgb(20,90,200)" fill-opacity="0.6" fill-rule="evenodd"/>
        </svg>"#,
    );
    let bg = Some([1.0, 1.0, 1.0, 1.0]);
    assert_agrees(
        "filled_curves_solid",
        &s,
        &nudged_target(&s, 1.0, bg),
        Loss::Mse,
        bg,
    );
}

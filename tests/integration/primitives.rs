//! Circles, ellipses and rectangles with their own parameters: fitted from the command
//! line, checked against finite differences, written back as themselves.

use diffsvg::loss::Loss;
use diffsvg::raster::{RenderOptions, render};
use diffsvg::scene::{ParamGroup, ParamLayout, Shape};
use diffsvg::{Scene, Sizing};
use std::path::PathBuf;

use crate::common::{diffsvg, json_summary, s, scratch, write};
use crate::gradients::{assert_agrees, nudged_target};

/// Writes `svg` as `NAME.svg` into `dir` and its rendering as `NAME.png`: the start and
/// the target of a fit.
fn svg_and_picture(dir: &std::path::Path, name: &str, svg: &str) -> (PathBuf, PathBuf) {
    let src = write(dir, &format!("{name}.svg"), svg);
    let png = dir.join(format!("{name}.png"));
    let scene = Scene::load(&src, Sizing::Natural).unwrap();
    render(&scene, &RenderOptions::default())
        .save_png(&png)
        .unwrap();
    (src, png)
}

/// DiffVG's single_circle: a circle's center and radius recovered from a picture of it,
/// to a thousandth of a pixel, and the SVG written back holds a `<circle>`.
#[test]
fn single_circle_recovers_center_and_radius() {
    let dir = scratch("single-circle");
    let (_, png) = svg_and_picture(
        &dir,
        "target",
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64">
          <circle cx="30.3" cy="34.6" r="17.25" fill="#4c7fcc"/></svg>"##,
    );
    let start = write(
        &dir,
        "start.svg",
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64">
          <circle cx="26" cy="38" r="12" fill="#4c7fcc"/></svg>"##,
    );
    let out_svg = dir.join("fit.svg");
    let sum = json_summary(&diffsvg(&[
        "fit",
        s(&start),
        s(&png),
        "-o",
        s(&out_svg),
        "--iters",
        "400",
        "--freeze",
        "colors,opacities",
        "--schedule",
        "cosine",
        "--lr-points",
        "0.5",
        "--json",
    ]));
    assert!(sum["psnr"].as_f64().unwrap() > 60.0, "{sum}");
    let text = std::fs::read_to_string(&out_svg).unwrap();
    assert!(
        text.contains("<circle") && !text.contains("<path"),
        "{text}"
    );
    let fitted = Scene::load(&out_svg, Sizing::Natural).unwrap();
    // Read back through the file: four decimals.
    let mut shapes = Vec::new();
    fitted.for_each_path(|p| shapes.push(p.primitive.clone().map(|q| q.shape)));
    let Some(Some(Shape::Circle { center, r })) = shapes.first().cloned() else {
        panic!("{shapes:?}")
    };
    let err = (center[0] - 30.3)
        .abs()
        .max((center[1] - 34.6).abs())
        .max((r - 17.25).abs());
    assert!(err <= 1e-3, "center {center:?}, r {r}: off by {err:.2e} px");
}

/// Rectangles, circles, an ellipse, a turned group of two shapes, a scaled group of one
/// (the circle's own transform) and a skewed group of two filled paths (a general affine
/// transform).
const DRAWING: &str = include_str!("../../svg-samples/shapes/drawing.svg");

/// Every primitive parameter (positions, sizes, corner radii, rotations) and its paints
/// against central differences, on shapes under rotated and scaled groups, with strokes.
#[test]
fn primitive_parameters_match_differences() {
    let scene = Scene::from_svg_str(DRAWING, "drawing.svg", Sizing::Natural).unwrap();
    let mut kinds = Vec::new();
    scene.for_each_path(|p| kinds.push(p.primitive.as_ref().map(|q| q.element())));
    assert_eq!(
        kinds,
        [
            Some("rect"),
            Some("rect"),
            Some("rect"),
            Some("ellipse"),
            Some("circle"),
            Some("circle"),
            None,
            None
        ]
    );
    let layout = ParamLayout::new(&scene);
    assert!(
        layout
            .slots
            .iter()
            .any(|s| s.group == ParamGroup::Transform),
        "rotations are parameters"
    );
    let target = nudged_target(&scene, 1.0, None);
    assert_agrees("primitives", &scene, &target, Loss::Mse, None);
}

/// Nested groups whose transforms are parameters (a path, strokes, a rounded rectangle, an
/// ellipse and a circle in them), beside a skewed group of two fills (a general affine
/// transform parameter).
const NESTED: &str = r##"<svg xmlns="http://www.w3.org/2000/svg" width="80" height="60">
  <rect width="80" height="60" fill="#f0ece0"/>
  <g id="outer" transform="translate(6 4) rotate(12 40 30)">
    <path id="blob" d="M10 10 C30 0 40 20 30 30 Q20 40 10 30 Z" fill="#3366aa"
          stroke="#112244" stroke-width="2"/>
    <g id="inner" transform="translate(40 20) scale(0.8) rotate(-20)">
      <rect id="r" x="0" y="0" width="20" height="12" rx="3" fill="#cc4422"/>
      <ellipse id="e" cx="10" cy="24" rx="8" ry="4" fill="#22aa66"/>
      <circle id="c" cx="26" cy="20" r="5" fill="#eeaa00" stroke="#553300" stroke-width="1.5"/>
    </g>
  </g>
  <g id="kept" transform="skewX(20)"><path d="M5 50 L20 50 L15 58 Z" fill="#777"/>
    <path d="M20 40 L30 40 L25 48 Z" fill="#555"/></g>
</svg>"##;

/// Group transforms as parameters: each group's translation, angle and scale, and the
/// local values of what it holds, against central differences; and the file draws as
/// resvg draws it.
#[test]
fn group_transforms_match_differences() {
    let scene = Scene::from_svg_str(NESTED, "nested.svg", Sizing::Natural).unwrap();
    let layout = ParamLayout::new(&scene);
    // Outer and inner as similarities; the skewed pair of fills as a general map.
    assert_eq!(layout.transforms.len(), 3);
    let lens: Vec<usize> = diffsvg::scene::structure::Structure::of(&scene)
        .transforms
        .iter()
        .map(|t| t.len)
        .collect();
    assert_eq!(lens, [4, 4, 6]);
    let target = nudged_target(&scene, 1.0, None);
    assert_agrees("group transforms", &scene, &target, Loss::Mse, None);
    let dir = scratch("group-transforms");
    let file = write(&dir, "nested.svg", NESTED);
    let parity =
        diffsvg::reference::parity(&file, Sizing::Natural, &RenderOptions::default()).unwrap();
    assert!(parity.passes(), "{:?}", parity.comparison);
}

/// A drawing of rectangles, circles and ellipses (rotated and scaled by their groups) and
/// a skewed group of paths, perturbed in those parameters and fitted back: ≥ 45 dB,
/// written back with the same elements and the two groups' transforms.
#[test]
fn primitives_drawing_is_fitted_back_as_itself() {
    let dir = scratch("primitives-fit");
    let (src, png) = svg_and_picture(&dir, "drawing", DRAWING);
    let perturbed = dir.join("perturbed.svg");
    let out = diffsvg(&[
        "perturb",
        s(&src),
        "-o",
        s(&perturbed),
        "--seed",
        "5",
        "--points",
        "8",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out_svg = dir.join("fit.svg");
    let sum = json_summary(&diffsvg(&[
        "fit",
        s(&perturbed),
        s(&png),
        "-o",
        s(&out_svg),
        "--iters",
        "600",
        "--until-psnr",
        "50",
        "--json",
    ]));
    let (initial, psnr) = (
        sum["initial_psnr"].as_f64().unwrap(),
        sum["psnr"].as_f64().unwrap(),
    );
    assert!(
        initial < 30.0,
        "the perturbation should hurt: {initial:.2} dB"
    );
    assert!(psnr >= 45.0, "{initial:.2} → {psnr:.2} dB");
    let text = std::fs::read_to_string(&out_svg).unwrap();
    let count = |tag: &str| text.matches(&format!("<{tag} ")).count();
    assert_eq!(
        (
            count("rect"),
            count("circle"),
            count("ellipse"),
            count("path")
        ),
        (3, 2, 1, 2),
        "{text}"
    );
    // The turned group of two shapes, the skewed one of two paths and the scaled circle
    // keep their transforms (parameters); the circle's is written on a `<g>` around it
    // when the circle writes a `rotate` of its own (where its outline starts), else on
    // the `<circle>`.
    assert_eq!(text.matches("transform=\"matrix(").count(), 3, "{text}");
}

/// `fit --free-shapes`: the same drawing fitted with its shapes' outlines as free paths,
/// written back as `<path>`s.
#[test]
fn free_shapes_are_fitted_as_paths() {
    let dir = scratch("primitives-free");
    let (src, png) = svg_and_picture(&dir, "drawing", DRAWING);
    let out_svg = dir.join("fit.svg");
    let sum = json_summary(&diffsvg(&[
        "fit",
        s(&src),
        s(&png),
        "-o",
        s(&out_svg),
        "--iters",
        "5",
        "--free-shapes",
        "--json",
    ]));
    assert!(sum["psnr"].as_f64().unwrap() > 40.0, "{sum}");
    let text = std::fs::read_to_string(&out_svg).unwrap();
    assert_eq!(text.matches("<path ").count(), 8, "{text}");
    assert!(
        !text.contains("<circle") && !text.contains("<rect"),
        "{text}"
    );
}

//! Numerically hard inputs: the image and every gradient stay finite, and where the
//! rendering is a differentiable function of the parameters the gradient agrees with
//! central finite differences (chord counts held fixed).

use diffsvg::Sizing;
use diffsvg::gradcheck::{analytic, check};
use diffsvg::image_io::Image;
use diffsvg::loss::Loss;
use diffsvg::raster::{RenderOptions, render};
use diffsvg::scene::{FRAME_IDENTITY, LineCap, LineJoin, ParamGroup, ParamLayout};
use diffsvg::scene::{Fill, FillRule, Node, Paint, Path, Scene, Stroke};

const W: u32 = 32;

/// A fixed, non-uniform target so that no pixel's loss sits at a kink by accident.
fn target() -> Image {
    let mut t = Image::new(W, W);
    for (k, p) in t.data.iter_mut().enumerate() {
        let (x, y) = ((k % W as usize) as f32, (k / W as usize) as f32);
        *p = [0.3 + 0.01 * x, 0.5 - 0.01 * y, 0.4, 0.6 + 0.005 * (x + y)];
    }
    t
}

fn svg(body: &str) -> Scene {
    let text =
        format!(r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{W}">{body}</svg>"#);
    Scene::from_svg_str(&text, "hard.svg", Sizing::Natural).unwrap()
}

fn fill(d: &[[f64; 2]], closed: bool) -> Path {
    let mut p = Path::new("p");
    p.move_to(d[0]);
    for c in d[1..].chunks(3) {
        p.cubic_to(c[0], c[1], c[2]);
    }
    if closed {
        p.close();
    }
    p.fill = Some(Fill {
        paint: Paint::Solid([0.8, 0.3, 0.1]),
        opacity: 0.9,
        rule: FillRule::NonZero,
    });
    p
}

fn scene_of(paths: Vec<Path>) -> Scene {
    let mut s = Scene::new(W, W);
    s.nodes = paths.into_iter().map(Node::Path).collect();
    s
}

/// Renders and differentiates `scene`; asserts everything is finite and returns the
/// gradient.
fn finite(name: &str, scene: &Scene) -> Vec<f64> {
    let img = render(scene, &RenderOptions::default());
    assert!(
        img.data
            .iter()
            .flatten()
            .all(|v| v.is_finite() && (-1e-6..=1.0 + 1e-6).contains(v)),
        "{name}: image has non-finite or out-of-range values"
    );
    let (l, g) = analytic(scene, &target(), Loss::Mse, &RenderOptions::default(), None);
    assert!(l.is_finite(), "{name}: loss {l}");
    assert!(
        g.iter().all(|v| v.is_finite()),
        "{name}: non-finite gradient"
    );
    g
}

/// [`finite`], then central differences on every parameter.
fn agrees(name: &str, scene: &Scene) {
    finite(name, scene);
    agrees_on(name, scene, None);
}

/// Central differences on the parameters `which` (all when `None`), with the clamped
/// winding integral (the default) and with exact overlaps.
fn agrees_on(name: &str, scene: &Scene, which: Option<&[usize]>) {
    for exact_overlaps in [false, true] {
        let opts = RenderOptions {
            exact_overlaps,
            ..RenderOptions::default()
        };
        let (_, _, groups) = check(scene, &target(), Loss::Mse, &opts, None, which);
        for g in groups {
            println!("{name} (exact overlaps {exact_overlaps}): {g}");
            assert!(
                g.worst <= 1e-2,
                "{name} (exact overlaps {exact_overlaps}): {g}"
            );
        }
    }
}

#[test]
fn cubic_with_four_coincident_points() {
    // A closed path whose middle segment has collapsed to a point.
    let p = fill(
        &[
            [4.0, 4.0],
            [12.0, 2.0],
            [20.0, 3.0],
            [24.0, 8.0],
            [24.0, 8.0],
            [24.0, 8.0],
            [24.0, 8.0],
            [20.0, 20.0],
            [10.0, 26.0],
            [5.0, 20.0],
        ],
        true,
    );
    agrees("four coincident points", &scene_of(vec![p]));
    // A path that is nothing but one point.
    let p = fill(&[[10.3, 10.7]; 4], true);
    finite("single point path", &scene_of(vec![p]));
}

#[test]
fn zero_length_and_coincident_control_points() {
    let s = svg(
        r#"<path id="z" d="M 4 4 L 4 4 L 20 5 L 20 5 C 20 5 20 5 26 20 C 26 20 10 28 10 28 L 4 4 Z"
                fill="rgb(30,80,200)" fill-opacity="0.8"
                stroke="rgb(200,60,20)" stroke-width="2" stroke-opacity="0.7" stroke-linejoin="round"/>
           <path id="dot" d="M 16 16 L 16 16" stroke="black" stroke-width="4" stroke-linecap="round" stroke-opacity="0.5"/>"#,
    );
    finite("zero-length segments", &s);
    // The analytic gradient with respect to the coincident points is the one-sided
    // derivative; check only the closed fill, where every degenerate point is interior to
    // a smooth boundary.
    let p = fill(
        &[
            [4.0, 4.0],
            [4.0, 4.0],
            [20.0, 5.0],
            [20.0, 5.0],
            [20.0, 5.0],
            [26.0, 20.0],
            [26.0, 20.0],
            [10.0, 28.0],
            [10.0, 28.0],
            [10.0, 28.0],
        ],
        true,
    );
    agrees("coincident control points", &scene_of(vec![p]));
}

#[test]
fn cusp_and_collinear_control_points() {
    // A cusp: control points crossed over.
    let p = fill(
        &[
            [4.0, 16.0],
            [28.0, 4.0],
            [4.0, 4.0],
            [28.0, 16.0],
            [24.0, 28.0],
            [8.0, 28.0],
            [4.0, 16.0],
        ],
        true,
    );
    agrees("cusp", &scene_of(vec![p]));
    // Collinear control points, including ones that backtrack along the line.
    let p = fill(
        &[
            [4.0, 4.0],
            [12.0, 12.0],
            [2.0, 2.0],
            [20.0, 20.0],
            [24.0, 10.0],
            [20.0, 6.0],
            [4.0, 4.0],
        ],
        true,
    );
    agrees("collinear", &scene_of(vec![p]));
    // The same as strokes with every join style.
    for join in ["miter", "round", "bevel"] {
        let s = svg(&format!(
            r#"<path id="c" d="M 4 16 C 28 4 4 4 28 16" fill="none" stroke="rgb(20,120,60)"
                 stroke-width="3" stroke-opacity="0.8" stroke-linejoin="{join}"/>"#
        ));
        finite("cusp stroke", &s);
    }
}

#[test]
fn edges_on_pixel_boundaries_and_centers() {
    // Axis-aligned edges exactly on pixel boundaries: a kink of the rendering, where the
    // gradient is the mean of the one-sided derivatives (what central differences see).
    let s = svg(
        r#"<rect id="grid" x="4" y="6" width="12" height="10" fill="rgb(200,0,0)" fill-opacity="0.7"/>"#,
    );
    agrees("on pixel boundaries", &s);
    // Through pixel centers, horizontal and vertical.
    let s = svg(
        r#"<rect id="centers" x="4.5" y="6.5" width="12" height="10" fill="rgb(200,0,0)" fill-opacity="0.7"/>"#,
    );
    agrees("through pixel centers", &s);
    // A rectangle's gradient is not zero just because its edges are pixel-aligned.
    let g = finite(
        "on pixel boundaries",
        &svg(r#"<rect id="r" x="4" y="6" width="12" height="10" fill="red"/>"#),
    );
    assert!(g[..8].iter().any(|v| v.abs() > 1e-5), "{g:?}");
}

#[test]
fn self_intersecting_nonzero_and_evenodd() {
    for rule in ["nonzero", "evenodd"] {
        let s = svg(&format!(
            r#"<path id="star" d="M 16 2 L 24 28 L 2 11 L 30 11 L 8 28 Z" fill="rgb(90,20,160)"
                 fill-opacity="0.8" fill-rule="{rule}"/>"#
        ));
        // With exact overlaps, pixels holding crossings are integrated exactly (issue 29),
        // and the horizontal edge lies on the pixel line y = 11 through two of the
        // crossings: the cells on both sides of it take their gradient from the windings
        // on both sides. By default they get the clamped winding integral.
        finite(rule, &s);
        agrees(rule, &s);
    }
}

#[test]
fn tiny_and_offscreen_shapes() {
    let s = svg(
        r#"<rect id="tiny" x="10.2" y="10.3" width="0.01" height="0.01" fill="rgb(0,0,0)" fill-opacity="0.9"/>"#,
    );
    agrees("0.01 px square", &s);
    let s = svg(r#"<circle id="out" cx="-40" cy="16" r="10" fill="red" fill-opacity="0.9"/>"#);
    let g = finite("wholly outside", &s);
    assert!(
        g.iter().take(26).all(|v| *v == 0.0),
        "an invisible shape has no gradient"
    );
    let s = svg(
        r#"<circle id="part" cx="-2.3" cy="29.6" r="10" fill="rgb(200,20,20)" fill-opacity="0.9"/>"#,
    );
    agrees("partly outside", &s);
}

#[test]
fn huge_coordinates_and_tiny_segments() {
    // A triangle with far-away corners that crosses the canvas.
    let mut p = Path::new("far");
    p.move_to([-1.0e6, 3.7]);
    p.line_to([1.0e6, 9.2]);
    p.line_to([15.3, 1.0e6]);
    p.close();
    p.fill = Some(Fill {
        paint: Paint::Solid([0.2, 0.6, 0.3]),
        opacity: 0.8,
        rule: FillRule::NonZero,
    });
    let s = scene_of(vec![p]);
    finite("coordinates near 1e6", &s);
    let img = render(&s, &RenderOptions::default());
    // Row 20 is fully inside: its alpha is the fill opacity.
    assert!((img.get(16, 20)[3] - 0.8).abs() < 1e-4);
    // Many segments of 1e-6 px along an otherwise ordinary square.
    let mut p = Path::new("fine");
    p.move_to([6.0, 6.0]);
    let mut x = 6.0;
    for _ in 0..200 {
        x += 1e-6;
        p.line_to([x, 6.0 + 1e-6]);
    }
    p.line_to([20.0, 6.5]);
    p.line_to([20.0, 20.0]);
    p.line_to([6.0, 20.0]);
    p.close();
    p.fill = Some(Fill {
        paint: Paint::Solid([0.2, 0.6, 0.3]),
        opacity: 0.8,
        rule: FillRule::NonZero,
    });
    let s = scene_of(vec![p]);
    finite("segments of 1e-6", &s);
    let area: f64 = render(&s, &RenderOptions::default())
        .data
        .iter()
        .map(|p| p[3] as f64)
        .sum::<f64>()
        / 0.8;
    let exact = 14.0 * 14.0 - 0.5 * 14.0 * 0.5;
    assert!((area - exact).abs() < 0.05, "{area} vs {exact}");
}

fn stroked(width: f64, join: LineJoin, pts: &[[f64; 2]]) -> Scene {
    let mut p = Path::new("s");
    p.move_to(pts[0]);
    for q in &pts[1..] {
        p.line_to(*q);
    }
    p.stroke = Some(Stroke {
        paint: Paint::Solid([0.1, 0.2, 0.7]),
        opacity: 0.8,
        width,
        join,
        cap: LineCap::Butt,
        miter_limit: 400.0,
        dash: None,
        dash_offset: 0.0,
        frame: FRAME_IDENTITY,
    });
    scene_of(vec![p])
}

#[test]
fn extreme_stroke_widths() {
    let pts = [[4.0, 6.0], [26.0, 10.0], [12.0, 25.0]];
    let g = finite("width 0", &stroked(0.0, LineJoin::Miter, &pts));
    assert!(
        g.iter().all(|v| *v == 0.0),
        "a zero-width stroke draws and moves nothing"
    );
    // At width 1e-4 a finite-difference step changes each pixel by about 1e-7, which is
    // f32 rounding. Colors and opacity are checked by differences; the width gradient
    // against its thin-stroke limit (coverage grows linearly with width, so ∂L/∂width
    // barely changes between 1e-4 and 1e-3); the points for finiteness.
    let thin = stroked(1e-4, LineJoin::Round, &pts);
    let g4 = finite("width 1e-4", &thin);
    let g3 = finite("width 1e-3", &stroked(1e-3, LineJoin::Round, &pts));
    let layout = ParamLayout::new(&thin);
    let wi = (0..layout.len())
        .find(|&i| layout.slots[i].group == ParamGroup::StrokeWidth)
        .unwrap();
    assert!(
        (g4[wi] - g3[wi]).abs() <= 2e-2 * g3[wi].abs(),
        "width gradient {} vs {}",
        g4[wi],
        g3[wi]
    );
    let which: Vec<usize> = (0..layout.len())
        .filter(|&i| {
            !matches!(
                layout.slots[i].group,
                ParamGroup::Points | ParamGroup::StrokeWidth
            )
        })
        .collect();
    agrees_on("width 1e-4", &thin, Some(&which));
    let s = stroked(200.0, LineJoin::Round, &pts);
    agrees("width 200", &s);
    // At width 200 everything past the butt cap at the start is covered once: the joins
    // and the overlap of the two arms do not add up beyond full coverage.
    let img = render(&s, &RenderOptions::default());
    assert!((img.get(16, 16)[3] - 0.8).abs() < 1e-5);
    assert!((img.get(31, 31)[3] - 0.8).abs() < 1e-5);
}

#[test]
fn miter_join_at_one_degree() {
    // Two segments meeting at 1°: the miter tip is 1/sin(0.5°) ≈ 115 half-widths out.
    let a = 1.0f64.to_radians();
    let pts = [
        [4.0, 16.0],
        [28.0, 16.0],
        [28.0 - 24.0 * a.cos(), 16.0 + 24.0 * a.sin()],
    ];
    agrees("1° miter", &stroked(1.5, LineJoin::Miter, &pts));
    agrees("1° bevel", &stroked(1.5, LineJoin::Bevel, &pts));
    agrees("1° round", &stroked(1.5, LineJoin::Round, &pts));
}

#[test]
fn hundred_translucent_shapes() {
    let mut body = String::new();
    for i in 0..100 {
        let (x, y) = (4.0 + (i % 10) as f64 * 2.3, 4.0 + (i / 10) as f64 * 2.1);
        body += &format!(
            r#"<circle id="c{i}" cx="{x}" cy="{y}" r="{}" fill="rgb({},{},{})" fill-opacity="0.3"/>"#,
            3.0 + (i % 7) as f64 * 0.5,
            (i * 37) % 256,
            (i * 91) % 256,
            (i * 53) % 256
        );
    }
    let s = svg(&body);
    finite("100 shapes", &s);
    // Finite differences on a sample of parameters across the stack.
    let n = ParamLayout::new(&s).len();
    let which: Vec<usize> = (0..n).step_by(37).collect();
    agrees_on("100 shapes", &s, Some(&which));
}

#[test]
fn colors_and_opacities_at_their_bounds() {
    let s = svg(
        r#"<rect id="black" x="3" y="3" width="14" height="14" fill="rgb(0,0,0)" fill-opacity="0.7"/>
           <rect id="white" x="12" y="12" width="16" height="16" fill="rgb(255,255,255)" fill-opacity="0.7"/>"#,
    );
    agrees("colors at 0 and 1", &s);
    // Opacity exactly 1 and 0: the rendering clamps opacity, so the function has a kink
    // there; the gradient is the derivative from inside [0, 1].
    let s = svg(
        r#"<rect id="opaque" x="3.5" y="3.5" width="14" height="14" fill="rgb(200,100,0)"/>
           <rect id="clear" x="12.5" y="12.5" width="16" height="16" fill="rgb(0,100,200)" fill-opacity="0"/>"#,
    );
    let g = finite("opacity at 0 and 1", &s);
    let layout = ParamLayout::new(&s);
    let params = s.params();
    let loss_at = |v: &[f64]| {
        let mut t = s.clone();
        t.set_params(v);
        Loss::Mse.value(&render(&t, &RenderOptions::default()), &target())
    };
    for (i, slot) in layout.slots.iter().enumerate() {
        if slot.group != ParamGroup::Opacity {
            continue;
        }
        let h = 1e-3;
        let mut v = params.clone();
        let inward = if params[i] >= 1.0 { -h } else { h };
        v[i] += inward;
        let one_sided = (loss_at(&v) - loss_at(&params)) / inward;
        assert!(
            (g[i] - one_sided).abs() <= 1e-2 * one_sided.abs().max(1e-6),
            "opacity slot {i}: analytic {} vs one-sided {one_sided}",
            g[i]
        );
    }
}

/// A linear gradient whose end points nearly coincide (issue 13): with `pad` it paints the
/// last stop, with `repeat` and `reflect` the gradient's mean color, as resvg does; the
/// gradient of that color reaches the stops, and no geometry gradient is invented.
/// Compared with resvg: needs the `reference` feature (on by default).
#[cfg(feature = "reference")]
#[test]
fn linear_gradient_of_near_zero_length_with_repeat_and_reflect() {
    for spread in ["pad", "repeat", "reflect"] {
        let svg = format!(
            r##"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{W}">
            <linearGradient id="g" x1="10" y1="10" x2="10.00001" y2="10" gradientUnits="userSpaceOnUse" spreadMethod="{spread}">
              <stop offset="0.1" stop-color="#ff0000"/><stop offset="0.4" stop-color="#00ff00" stop-opacity="0.5"/>
              <stop offset="0.8" stop-color="#0000ff"/></linearGradient>
            <path d="M3.3 3.1 L20.6 4.2 L18.1 19.7 L4.4 17.3 Z" fill="url(#g)"/></svg>"##
        );
        let tree = diffsvg::scene::parse_tree(svg.as_bytes(), "g.svg".as_ref()).unwrap();
        let scene = diffsvg::scene::from_tree(&tree, "g.svg".as_ref(), Sizing::Natural).unwrap();
        let ours = render(&scene, &RenderOptions::default());
        let theirs =
            diffsvg::reference::render_resvg(&tree, "g.svg".as_ref(), Sizing::Natural).unwrap();
        let cmp = diffsvg::metrics::compare(&ours.quantized(), &theirs);
        assert!(cmp.mae < 0.5, "{spread}: MAE {} / 255", cmp.mae);
        // The stops' parameters. (The polygon's points are checked by the other cases; the
        // gradient's geometry has no derivative here: a step of the end points leaves the
        // degenerate case, where the paint jumps.)
        finite(&format!("degenerate {spread}"), &scene);
        let layout = ParamLayout::new(&scene);
        let paint: Vec<usize> = (0..layout.slots.len())
            .filter(|&i| {
                !matches!(
                    layout.slots[i].group,
                    ParamGroup::Points | ParamGroup::PaintGeometry
                )
            })
            .collect();
        agrees_on(&format!("degenerate {spread}"), &scene, Some(&paint));
    }
}

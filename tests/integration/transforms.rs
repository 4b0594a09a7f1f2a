//! Group transforms as parameters beyond primitives.rs's similarities over solid paints:
//! gradient paints inside transformed groups, and general affine maps (skews, non-uniform
//! scales) over filled paths, a single shape's own transform; every transform slot
//! against central differences, and through a written file.

use diffsvg::gradcheck::check;
use diffsvg::loss::Loss;
use diffsvg::raster::{RenderOptions, render};
use diffsvg::scene::structure::Structure;
use diffsvg::scene::{ParamGroup, ParamLayout};
use diffsvg::{Scene, Sizing};
use std::path::Path;

use crate::gradients::nudged_target;

/// A turned and scaled group whose two shapes cover the canvas: one filled with a linear
/// gradient, one with a radial one (half transparent), so that the group's slots move
/// the picture through the paints alone; and a second group whose triangle has a radial
/// fill and a stroke with a linear gradient in `objectBoundingBox` units (a transform
/// that does not scale uniformly).
const GRADIENTS: &str = r##"<svg xmlns="http://www.w3.org/2000/svg" width="48" height="40">
  <defs>
    <linearGradient id="lin" gradientUnits="userSpaceOnUse" x1="6" y1="8" x2="40" y2="30">
      <stop offset="0.1" stop-color="#1f4e9c"/><stop offset="0.6" stop-color="#e0a030"/>
      <stop offset="0.95" stop-color="#b02040"/>
    </linearGradient>
    <radialGradient id="rad" gradientUnits="userSpaceOnUse" cx="22" cy="18" r="14" fx="18"
                    fy="15" fr="1">
      <stop offset="0" stop-color="#ffffff"/><stop offset="1" stop-color="#20a060"/>
    </radialGradient>
    <linearGradient id="box" x1="0" y1="0" x2="1" y2="0.3">
      <stop offset="0" stop-color="#000000"/><stop offset="1" stop-color="#ffee00"/>
    </linearGradient>
  </defs>
  <g id="turned" transform="translate(2 1) rotate(14 24 20) scale(1.05)">
    <path id="wall" d="M-60 -60 L110 -60 L110 110 L-60 110 Z" fill="url(#lin)"/>
    <path id="veil" d="M-60 -60 L110 -60 L110 110 L-60 110 Z" fill="url(#rad)"
          fill-opacity="0.5"/>
  </g>
  <g id="small" transform="translate(4 3) rotate(-9 24 20)">
    <path id="tri" d="M10 12 L34 9 L27 33 Z" fill="url(#rad)" stroke="url(#box)"
          stroke-width="3"/>
    <path id="dot" d="M36 28 L42 28 L42 34 L36 34 Z" fill="#335577"/>
  </g>
</svg>"##;

/// A skewed, non-uniformly scaled group of filled paths (one with a linear gradient), a
/// mirrored one inside it, and a stroked group under a skew.
const SKEWED: &str = r##"<svg xmlns="http://www.w3.org/2000/svg" width="56" height="44">
  <defs>
    <linearGradient id="lin" gradientUnits="userSpaceOnUse" x1="8" y1="6" x2="40" y2="36">
      <stop offset="0" stop-color="#2255aa"/><stop offset="1" stop-color="#ee8833"/>
    </linearGradient>
  </defs>
  <rect width="56" height="44" fill="#f3efe6"/>
  <g id="leaning" transform="matrix(1.1 0.17 0.35 0.8 -2 4)">
    <path id="kite" d="M8 6 C20 2 30 8 34 16 L22 34 L6 22 Z" fill="url(#lin)"/>
    <path id="tri" d="M26 4 L44 10 L32 20 Z" fill="#338855" fill-opacity="0.8"/>
    <g id="flipped" transform="matrix(-1 0 0.2 1.3 60 -8)">
      <path d="M14 22 L24 22 L20 30 Z" fill="#aa3344"/>
      <path d="M10 14 L16 12 L14 20 Z" fill="#4433aa"/>
    </g>
  </g>
  <g id="stroked" transform="skewX(15)">
    <path d="M4 36 L16 36 L12 42 Z" fill="#777777" stroke="#222222"/>
    <path d="M20 36 L28 36 L24 42 Z" fill="#555555"/>
  </g>
</svg>"##;

/// The slots of the groups' transforms (not the primitives' rotations).
fn group_transform_slots(scene: &Scene) -> Vec<usize> {
    let layout = ParamLayout::new(scene);
    (0..layout.slots.len())
        .filter(|&i| {
            let s = layout.slots[i];
            s.group == ParamGroup::Transform && layout.owners[s.owner].is_group
        })
        .collect()
}

/// The slots of the parameter groups `groups`.
fn slots_of(scene: &Scene, groups: &[ParamGroup]) -> Vec<usize> {
    let layout = ParamLayout::new(scene);
    (0..layout.slots.len())
        .filter(|&i| groups.contains(&layout.slots[i].group))
        .collect()
}

/// `which` against central differences, each group within 1e-2 (relative, absolute
/// below 1e-2 of the group's largest), and not all zero.
fn assert_slots_agree(name: &str, scene: &Scene, which: &[usize]) {
    let target = nudged_target(scene, 1.0, None);
    let (grad, _, groups) = check(
        scene,
        &target,
        Loss::Mse,
        &RenderOptions::default(),
        None,
        Some(which),
    );
    for g in &groups {
        println!("{name}: {g}");
        assert!(g.worst <= 1e-2, "{name}: {g}");
    }
    assert!(
        which.iter().all(|&i| grad[i].is_finite()) && which.iter().any(|&i| grad[i] != 0.0),
        "{name}: {:?}",
        which.iter().map(|&i| grad[i]).collect::<Vec<_>>()
    );
}

/// The groups whose transforms are parameters, as `id:slots`.
fn kept_transforms(scene: &Scene) -> Vec<String> {
    let st = Structure::of(scene);
    st.transforms
        .iter()
        .map(|t| format!("{}:{}", t.id, t.len))
        .collect()
}

#[test]
fn gradient_paints_keep_their_groups_transform() {
    let scene = Scene::from_svg_str(GRADIENTS, "gradients.svg", Sizing::Natural).unwrap();
    assert_eq!(kept_transforms(&scene), ["turned:4", "small:4"]);
    let slots = group_transform_slots(&scene);
    assert_eq!(slots.len(), 8);
    // The paints' own parameters too: geometry and stops, in gradient space.
    let paint = slots_of(&scene, &[ParamGroup::PaintGeometry, ParamGroup::StopOffset]);
    assert!(!paint.is_empty());
    assert_slots_agree("gradient paints: transforms", &scene, &slots);
    assert_slots_agree("gradient paints: paint", &scene, &paint);
}

/// Radial gradients whose circles are ellipses on the canvas (one in
/// `objectBoundingBox` units of a wide path under a turn, one under a skew, one under a
/// non-uniform scale): their groups keep their maps, drawn as baked, the maps' slots and
/// the paints' own against central differences, and through a written file the same
/// slots and pixels.
#[test]
fn radial_gradients_under_non_uniform_maps_are_parameters() {
    let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="56" height="44">
      <defs><radialGradient id="r" fx="0.35" fy="0.4"><stop offset="0" stop-color="#fff"/>
        <stop offset="1" stop-color="#225"/></radialGradient>
        <radialGradient id="u" gradientUnits="userSpaceOnUse" cx="10" cy="8" r="9" fx="7"
          fy="6"><stop offset="0" stop-color="#fe8"/><stop offset="1" stop-color="#a32"/>
        </radialGradient></defs>
      <rect width="56" height="44" fill="#eee"/>
      <g id="turned" transform="rotate(10 20 10)"><path d="M2 2 L38 2 L38 18 L2 18 Z" fill="url(#r)"/>
        <path d="M5 5 L9 5 L9 9 Z" fill="#f00"/></g>
      <g id="skewed" transform="translate(4 20) skewX(15)"><path d="M2 2 L22 2 L22 20 Z" fill="url(#u)"
        stroke="url(#u)" stroke-width="2"/></g>
      <g id="squeezed" transform="translate(30 22) scale(1.3 0.8)"><path d="M0 0 L20 0 L18 24 L2 20 Z"
        fill="url(#u)"/></g>
    </svg>"##;
    let scene = Scene::from_svg_str(svg, "radial.svg", Sizing::Natural).unwrap();
    assert_eq!(
        kept_transforms(&scene),
        ["turned:4", "skewed:6", "squeezed:6"]
    );
    let clip = "<clipPath id=\"all\"><rect x=\"-100\" y=\"-100\" width=\"300\" height=\"300\"/></clipPath>";
    let flat_svg = svg
        .replace("<defs>", &format!("<defs>{clip}"))
        .replace("<g id=", "<g clip-path=\"url(#all)\" id=");
    let flat = Scene::from_svg_str(&flat_svg, "baked.svg", Sizing::Natural).unwrap();
    assert!(ParamLayout::new(&flat).transforms.is_empty());
    let worst = worst_pixel(&scene, &flat);
    assert!(worst <= 1e-5, "as baked: {worst}");
    let (moved, text) = maps_agree_and_move(
        "radial under affine maps",
        &scene,
        16,
        &[ParamGroup::PaintGeometry, ParamGroup::StopOffset],
    );
    let back = Scene::from_svg_str(&text, "back.svg", Sizing::Natural).unwrap();
    assert_eq!(kept_transforms(&back), kept_transforms(&scene), "{text}");
    assert_reads_back(&moved, &back, &text);
}

#[test]
fn skewed_groups_of_fills_are_affine_parameters() {
    let scene = Scene::from_svg_str(SKEWED, "skewed.svg", Sizing::Natural).unwrap();
    let st = Structure::of(&scene);
    // The stroked group under a skew too (its stroke's frame takes the map).
    assert_eq!(
        kept_transforms(&scene),
        ["leaning:6", "flipped:6", "stroked:6"]
    );
    let v = scene.params();
    let at = st.transforms[0].offset + 2;
    for (got, want) in v[at..at + 4].iter().zip([1.1, 0.17, 0.35, 0.8]) {
        assert!((got - want).abs() < 1e-6, "{:?}", &v[at..at + 4]);
    }
    let slots = group_transform_slots(&scene);
    assert_eq!(slots.len(), 18);
    assert_slots_agree("affine groups", &scene, &slots);
    // The points in the groups' frames, and the linear gradient's geometry.
    let rest = slots_of(&scene, &[ParamGroup::Points, ParamGroup::PaintGeometry]);
    assert_slots_agree("affine groups: points and paint", &scene, &rest);
}

/// Written and read back: the same kinds of transform, the same slots (to `f32`) and
/// the same pixels; moved slots are written as they are.
#[test]
fn affine_transforms_and_gradient_paints_survive_a_round_trip() {
    for (name, svg) in [("skewed", SKEWED), ("gradients", GRADIENTS)] {
        let scene = Scene::from_svg_str(svg, name, Sizing::Natural).unwrap();
        let mut moved = scene.clone();
        // The outermost groups' slots (a nested group's change would move its content
        // in its parent's frame, and with it the parent's pivot: the same map, other
        // numbers).
        let mut v = scene.params();
        for t in Structure::of(&scene).transforms {
            if t.id != "flipped" {
                for x in &mut v[t.offset..t.offset + t.len] {
                    *x += 0.03;
                }
            }
        }
        moved.set_params(&v);
        let text = moved.to_svg_string();
        let back = Scene::from_svg_str(&text, "back.svg", Sizing::Natural).unwrap();
        let lens = |s: &Scene| -> Vec<usize> {
            Structure::of(s).transforms.iter().map(|t| t.len).collect()
        };
        assert_eq!(lens(&back), lens(&scene), "{name}: {text}");
        let (a, b) = (moved.params(), back.params());
        assert_eq!(a.len(), b.len(), "{name}");
        for (i, (x, y)) in a.iter().zip(&b).enumerate() {
            assert!(
                (x - y).abs() <= 2e-3 * x.abs().max(1.0),
                "{name} slot {i}: {x} vs {y}"
            );
        }
        let worst = worst_pixel(&moved, &back);
        assert!(worst < 2e-3, "{name}: pixels differ by {worst}");
        assert!(text.contains("transform=\"matrix("), "{text}");
    }
}

/// `--freeze transforms` holds the new slots, and they are what a fit moves when the
/// rest is frozen.
#[test]
fn freezing_transforms_holds_affine_slots() {
    assert_freezing_holds_maps("skewed", SKEWED, 3.0);
}

/// The same for maps over primitives (whose angles the freeze holds too): the fit
/// with the maps frozen gains less, a circle unable to follow its map's skew.
#[test]
fn freezing_transforms_holds_maps_over_primitives() {
    assert_freezing_holds_maps("prims", PRIMITIVES, 1.0);
}

/// A fit of `svg` toward its groups' maps nudged, with `--freeze transforms` and with
/// all else frozen: at least `gain` dB better in 20 steps each, the same elements read
/// back, the maps held or moved, and the other slots moved or held.
fn assert_freezing_holds_maps(name: &str, svg: &str, gain: f64) {
    use crate::common::{scratch, write};
    let dir = scratch(&format!("affine-freeze-{name}"));
    let src = write(&dir, &format!("{name}.svg"), svg);
    let scene = Scene::load(&src, Sizing::Natural).unwrap();
    let png = dir.join("target.png");
    render(&nudged_target_scene(&scene), &RenderOptions::default())
        .save_png(&png)
        .unwrap();
    let rest = "points,colors,opacities,widths,paint,stops";
    for (freeze, transforms_move) in [("transforms", false), (rest, true)] {
        let out = dir.join("fit.svg");
        // (A fit writes its best step: enough of them to improve.)
        let (initial, psnr) = fit(&src, &png, &out, &["--iters", "20", "--freeze", freeze]);
        assert!(
            psnr > initial + gain,
            "{name}, {freeze}: {initial:.2} → {psnr:.2} dB"
        );
        let fitted = Scene::load(&out, Sizing::Natural).unwrap();
        assert_eq!(kinds(&fitted), kinds(&scene), "{name}, {freeze}");
        let (a, b) = (scene.params(), fitted.params());
        let moved = |i: usize| (a[i] - b[i]).abs() > 1e-3 * a[i].abs().max(1.0);
        // The maps themselves (a file read back puts the pivot at its content's center,
        // which moving the content moves, and the translation slots with it).
        let (ma, mb) = (maps(&scene), maps(&fitted));
        assert_eq!(ma.len(), mb.len());
        let map_moved = ma
            .iter()
            .zip(&mb)
            .any(|(p, q)| p.iter().zip(q).any(|(x, y)| (x - y).abs() > 1e-3));
        assert_eq!(map_moved, transforms_move, "{freeze}: {ma:?} {mb:?}");
        // (A rectangle's rotation is in the same group.)
        let layout = ParamLayout::new(&scene);
        let others: Vec<usize> = (0..a.len())
            .filter(|&i| layout.slots[i].group != ParamGroup::Transform && moved(i))
            .collect();
        assert_eq!(!others.is_empty(), !transforms_move, "{freeze}: {others:?}");
    }
}

/// Every outline point in device pixels, a circle's center instead of its outline (whose
/// start its angle places).
fn outlines(scene: &Scene) -> Vec<[f64; 2]> {
    let mut out = Vec::new();
    scene.for_each_path(|p| match &p.primitive {
        Some(q) if matches!(q.shape, diffsvg::scene::Shape::Circle { .. }) => out.push(q.center()),
        _ => out.extend(p.points.iter().copied()),
    });
    out
}

/// `diffsvg fit SRC PNG -o OUT ARGS --json`: its initial and final PSNR, dB.
fn fit(src: &Path, png: &Path, out: &Path, args: &[&str]) -> (f64, f64) {
    use crate::common::{diffsvg, json_summary, s};
    let mut all = vec!["fit", s(src), s(png), "-o", s(out)];
    all.extend_from_slice(args);
    all.push("--json");
    let sum = json_summary(&diffsvg(&all));
    (
        sum["initial_psnr"].as_f64().unwrap(),
        sum["psnr"].as_f64().unwrap(),
    )
}

/// Every group transform's matrix, in walk order.
fn maps(scene: &Scene) -> Vec<[f64; 6]> {
    fn walk(nodes: &[diffsvg::scene::Node], out: &mut Vec<[f64; 6]>) {
        for n in nodes {
            if let diffsvg::scene::Node::Group(g) = n {
                if let Some(t) = &g.transform {
                    out.push(t.affine());
                }
                walk(&g.children, out);
            }
        }
    }
    let mut out = Vec::new();
    walk(&scene.nodes, &mut out);
    out
}

/// The scene with its group transforms moved a little: a target only they can reach.
fn nudged_target_scene(scene: &Scene) -> Scene {
    let mut t = scene.clone();
    let mut v = t.params();
    for (k, &i) in group_transform_slots(scene).iter().enumerate() {
        v[i] += if k % 2 == 0 { 0.02 } else { -0.015 };
    }
    t.set_params(&v);
    t
}

/// Single shapes with transforms of their own (usvg's group around each): a rectangle
/// turned about its corner and stroked, a circle scaled and moved, a path skewed and
/// squeezed, an ellipse in a `<g>` of its own; and one rectangle turned about its center,
/// which is its angle.
const SINGLES: &str = r##"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="48">
  <rect width="64" height="48" fill="#efe9dc"/>
  <rect id="bar" x="8" y="6" width="24" height="10" rx="2" fill="#c0392b" stroke="#2c3e50"
        stroke-width="2" transform="rotate(20 8 6)"/>
  <circle id="dot" cx="14" cy="30" r="5" fill="#27ae60" transform="translate(3 2) scale(1.3)"/>
  <path id="kite" d="M36 22 L54 24 L48 40 L34 34 Z" fill="#2980b9"
        transform="matrix(1 0.1 -0.3 0.9 6 1)"/>
  <g id="leaf" transform="rotate(-15 50 10) scale(1.1)">
    <ellipse cx="44" cy="9" rx="9" ry="4" fill="#8e44ad"/>
  </g>
  <rect id="tile" x="24" y="36" width="10" height="6" fill="#f39c12" transform="rotate(10 29 39)"/>
</svg>"##;

#[test]
fn single_shapes_keep_their_own_transforms() {
    let scene = Scene::from_svg_str(SINGLES, "singles.svg", Sizing::Natural).unwrap();
    let lens: Vec<usize> = Structure::of(&scene)
        .transforms
        .iter()
        .map(|t| t.len)
        .collect();
    // The tile's turn about its center is its own angle; a shape's own transform goes by
    // the shape's id.
    assert_eq!(lens, [4, 4, 6, 4]);
    assert_eq!(
        kept_transforms(&scene),
        ["bar:4", "dot:4", "kite:6", "leaf:4"]
    );
    let slots = group_transform_slots(&scene);
    assert_eq!(slots.len(), 18);
    assert_slots_agree("single shapes: transforms", &scene, &slots);
    let rest = slots_of(&scene, &[ParamGroup::Points, ParamGroup::StrokeWidth]);
    assert_slots_agree("single shapes: local values", &scene, &rest);
    // Written back: the transforms on the elements, read back to the same slots.
    let text = scene.to_svg_string();
    for tag in [
        "<rect id=\"bar\" ",
        "<circle id=\"dot\" ",
        "<path id=\"kite\" ",
    ] {
        assert!(
            text.contains(&format!("{tag}transform=\"matrix(")),
            "{tag}: {text}"
        );
    }
    assert!(
        text.contains("<g id=\"leaf\" transform=\"matrix("),
        "{text}"
    );
    assert!(
        text.contains("<rect id=\"tile\" transform=\"rotate("),
        "{text}"
    );
    let back = Scene::from_svg_str(&text, "back.svg", Sizing::Natural).unwrap();
    let (a, b) = (scene.params(), back.params());
    assert_eq!(a.len(), b.len(), "{text}");
    assert_eq!(
        group_transform_slots(&back),
        slots,
        "the same slots: {text}"
    );
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!(
            (x - y).abs() <= 1e-5 * x.abs().max(1.0),
            "slot {i}: {x} vs {y}"
        );
    }
}

/// The single shapes' transforms perturbed and fitted back with everything else frozen:
/// the picture to ≥ 45 dB and each shape's outline (a circle's center) to within 0.1 px
/// (a rectangle's own angle turns it about the same pivot as its transform's, so the
/// two share the turn: the maps themselves need not come back); `--freeze transforms`
/// leaves the maps where they are.
#[test]
fn single_shape_transforms_are_fitted_back() {
    use crate::common::{scratch, write};
    let dir = scratch("single-transforms-fit");
    let target = Scene::from_svg_str(SINGLES, "singles.svg", Sizing::Natural).unwrap();
    let png = dir.join("target.png");
    render(&target, &RenderOptions::default())
        .save_png(&png)
        .unwrap();
    // Each map moved: a shift, a turn, a scale or a shear.
    let mut start = target.clone();
    let mut v = start.params();
    for t in Structure::of(&target).transforms {
        let at = t.offset;
        v[at] += 1.2;
        v[at + 1] -= 0.8;
        v[at + 2] += if t.len == 4 { 0.06 } else { 0.05 };
        v[at + 3] *= 1.04;
    }
    start.set_params(&v);
    let src = write(&dir, "start.svg", &start.to_svg_string());
    let rest = "points,colors,opacities,widths,paint,stops";
    let out = dir.join("fit.svg");
    let (initial, psnr) = fit(
        &src,
        &png,
        &out,
        &["--iters", "400", "--until-psnr", "50", "--freeze", rest],
    );
    assert!(
        initial < 25.0,
        "the perturbation should hurt: {initial:.2} dB"
    );
    assert!(psnr >= 45.0, "{initial:.2} → {psnr:.2} dB");
    let fitted = Scene::load(&out, Sizing::Natural).unwrap();
    assert_eq!(maps(&fitted).len(), 4);
    let (want, got) = (outlines(&target), outlines(&fitted));
    assert_eq!(want.len(), got.len());
    let worst = want
        .iter()
        .zip(&got)
        .map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
        .fold(0.0, f64::max);
    assert!(
        worst <= 0.1,
        "{initial:.2} → {psnr:.2} dB, off by {worst} px"
    );
    // Frozen, the maps stay as they start.
    fit(
        &src,
        &png,
        &out,
        &["--iters", "10", "--freeze", "transforms"],
    );
    let held = maps(&Scene::load(&out, Sizing::Natural).unwrap());
    for (a, b) in maps(&start).iter().zip(&held) {
        assert!(
            a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-4),
            "{a:?} vs {b:?}"
        );
    }
}

/// A skewed, non-uniformly scaled group of strokes (round join, a linear-gradient
/// stroke over a fill, no fill at all) and a stroked path with a skew of its own: the pen
/// round in the group's frame, an ellipse on the canvas.
const STROKED: &str = r##"<svg xmlns="http://www.w3.org/2000/svg" width="56" height="44">
  <defs>
    <linearGradient id="lin" gradientUnits="userSpaceOnUse" x1="20" y1="4" x2="40" y2="18">
      <stop offset="0" stop-color="#113366"/><stop offset="1" stop-color="#dd5522"/>
    </linearGradient>
  </defs>
  <rect width="56" height="44" fill="#f3efe6"/>
  <g id="slanted" transform="matrix(1.1 0.15 0.4 0.75 -3 5)">
    <path id="hook" d="M6 8 C18 2 30 10 30 20 L14 30" fill="none" stroke="#224488"
          stroke-width="3" stroke-linejoin="round"/>
    <path id="box" d="M24 4 L40 6 L36 18 Z" fill="#cc7733" stroke="url(#lin)"
          stroke-width="2"/>
  </g>
  <path id="tick" d="M8 36 L20 40 L30 32" fill="none" stroke="#338855" stroke-width="2.5"
        transform="matrix(1 0 0.5 0.8 2 6)"/>
</svg>"##;

/// The same groups baked: a clip path far around the content (in the group's frame)
/// keeps a transform in the points (`movable_group`) and changes no pixel.
fn baked(svg: &str) -> String {
    svg.replace(
        "<g id=\"slanted\" ",
        "<clipPath id=\"all\"><rect x=\"-100\" y=\"-100\" width=\"300\" height=\"300\"/>\
         </clipPath><g id=\"slanted\" clip-path=\"url(#all)\" ",
    )
    .replace(
        "<path id=\"tick\" ",
        "<path id=\"tick\" clip-path=\"url(#all)\" ",
    )
}

/// `back` (`text`, written from `moved`, read back) has `moved`'s slots (within 2e-3,
/// relative above 1) and its pixels (within 2e-3).
fn assert_reads_back(moved: &Scene, back: &Scene, text: &str) {
    let (a, b) = (moved.params(), back.params());
    assert_eq!(a.len(), b.len());
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!(
            (x - y).abs() <= 2e-3 * x.abs().max(1.0),
            "slot {i}: {x} vs {y}\n{text}"
        );
    }
    let worst = worst_pixel(moved, back);
    assert!(worst < 2e-3, "pixels differ by {worst}");
}

/// `scene` draws as `flat` (its maps baked) does, and as itself through its local
/// frames and back (`set_params(params())`), within 1e-5.
fn assert_draws_as_baked(scene: &Scene, flat: &Scene) {
    let worst = worst_pixel(scene, flat);
    assert!(worst <= 1e-5, "as baked: {worst}");
    let mut again = scene.clone();
    again.set_params(&scene.params());
    let worst = worst_pixel(scene, &again);
    assert!(worst <= 1e-5, "set_params: {worst}");
}

/// The largest channel difference of two renderings.
fn worst_pixel(a: &Scene, b: &Scene) -> f32 {
    let opts = RenderOptions::default();
    let (p, q) = (render(a, &opts), render(b, &opts));
    p.data
        .iter()
        .zip(&q.data)
        .flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y).abs()))
        .fold(0.0f32, f32::max)
}

/// Strokes under a general affine map keep it as six slots: drawn as the baked file
/// draws them, every slot (the map's, the local points and widths, the paint) against
/// central differences, and through a written file the same slots and pixels.
#[test]
fn strokes_under_affine_maps_are_parameters() {
    let scene = Scene::from_svg_str(STROKED, "stroked.svg", Sizing::Natural).unwrap();
    assert_eq!(kept_transforms(&scene), ["slanted:6", "tick:6"]);
    let flat = Scene::from_svg_str(&baked(STROKED), "baked.svg", Sizing::Natural).unwrap();
    assert!(ParamLayout::new(&flat).transforms.is_empty());
    assert_draws_as_baked(&scene, &flat);
    // The local values as written: the hook's width and its first point.
    let st = Structure::of(&scene);
    let layout = ParamLayout::new(&scene);
    let v = scene.params();
    let hook = layout.paths[1];
    assert!((v[hook.stroke_width] - 3.0).abs() < 1e-6);
    assert!((v[hook.points] - 6.0).abs() < 1e-5 && (v[hook.points + 1] - 8.0).abs() < 1e-5);
    let at = st.transforms[0].offset + 2;
    for (got, want) in v[at..at + 4].iter().zip([1.1, 0.15, 0.4, 0.75]) {
        assert!((got - want).abs() < 1e-6, "{:?}", &v[at..at + 4]);
    }
    // Moved, written, read back.
    let (moved, text) = maps_agree_and_move(
        "affine strokes",
        &scene,
        12,
        &[
            ParamGroup::Points,
            ParamGroup::StrokeWidth,
            ParamGroup::PaintGeometry,
        ],
    );
    assert!(
        text.contains("<g id=\"slanted\" transform=\"matrix("),
        "{text}"
    );
    assert!(
        text.contains("<path id=\"tick\" transform=\"matrix("),
        "{text}"
    );
    let back = Scene::from_svg_str(&text, "back.svg", Sizing::Natural).unwrap();
    assert_eq!(kept_transforms(&back), ["slanted:6", "tick:6"], "{text}");
    assert_reads_back(&moved, &back, &text);
}

/// A dashed stroke under a skew keeps the map too (its dashes in the group's frame):
/// drawn as baked, and its map's slots against central differences (the dashes' cuts
/// held where they are, as for any dashed stroke: `raster::dash`).
#[test]
fn dashed_strokes_under_affine_maps_are_parameters() {
    let svg = STROKED.replace(
        "stroke-width=\"3\" stroke-linejoin=\"round\"",
        "stroke-width=\"3\" stroke-dasharray=\"6 3\" stroke-dashoffset=\"1\"",
    );
    let scene = Scene::from_svg_str(&svg, "dashed.svg", Sizing::Natural).unwrap();
    assert_eq!(kept_transforms(&scene), ["slanted:6", "tick:6"]);
    let flat = Scene::from_svg_str(&baked(&svg), "baked.svg", Sizing::Natural).unwrap();
    let worst = worst_pixel(&scene, &flat);
    assert!(worst <= 1e-5, "as baked: {worst}");
    let text = scene.to_svg_string();
    assert!(text.contains("stroke-dasharray=\"6 3\""), "{text}");
    let back = Scene::from_svg_str(&text, "back.svg", Sizing::Natural).unwrap();
    assert_eq!(kept_transforms(&back), ["slanted:6", "tick:6"], "{text}");
    assert!(worst_pixel(&scene, &back) < 2e-3);
    assert_slots_agree(
        "dashed affine strokes",
        &scene,
        &group_transform_slots(&scene),
    );
}

/// Circles, ellipses and rectangles under general affine maps: a skewed, squeezed group
/// holding a stroked circle, an ellipse turned about its center and a rounded rectangle,
/// and two shapes with skews of their own (an ellipse, a sharp rectangle).
const PRIMITIVES: &str = r##"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="48">
  <g id="leaning" transform="matrix(1.1 0.15 0.4 0.75 -3 5)">
    <circle id="dot" cx="12" cy="14" r="6" fill="#27ae60" stroke="#1c2833" stroke-width="2"/>
    <ellipse id="egg" cx="30" cy="12" rx="7" ry="4" fill="#8e44ad"
             transform="rotate(25 30 12)"/>
    <rect id="card" x="14" y="26" width="20" height="12" rx="3" ry="2" fill="#c0392b"/>
  </g>
  <ellipse id="leaf" cx="50" cy="36" rx="8" ry="5" fill="#2980b9" transform="skewX(-20)"/>
  <rect id="tile" x="44" y="4" width="12" height="8" fill="#f39c12"
        transform="matrix(1 0.25 -0.2 1.1 2 1)"/>
</svg>"##;

/// The same shapes baked into paths: a clip path far around each (in its frame) keeps
/// its transform in the points and changes no pixel.
fn primitives_baked() -> String {
    let clip = "clip-path=\"url(#all)\" ";
    PRIMITIVES
        .replace(
            "<g id=\"leaning\" ",
            &format!(
                "<clipPath id=\"all\"><rect x=\"-100\" y=\"-100\" width=\"300\" \
                 height=\"300\"/></clipPath><g id=\"leaning\" {clip}"
            ),
        )
        .replace(
            "<ellipse id=\"leaf\" ",
            &format!("<ellipse id=\"leaf\" {clip}"),
        )
        .replace(
            "<ellipse id=\"egg\" ",
            &format!("<ellipse id=\"egg\" {clip}"),
        )
        .replace("<rect id=\"tile\" ", &format!("<rect id=\"tile\" {clip}"))
}

/// The primitives' kinds in paint order (`path` for a plain path).
fn kinds(scene: &Scene) -> Vec<&'static str> {
    Structure::of(scene)
        .shapes
        .iter()
        .map(|s| s.primitive.as_ref().map_or("path", |p| p.kind))
        .collect()
}

/// Issue 30: a primitive under a general affine map (a group's, or its own) keeps its
/// own parameters in the map's frame and the map its six slots: drawn as the baked file
/// draws it, every slot against central differences, written back as the elements inside
/// the `matrix(…)` and read back to the same slots and pixels.
#[test]
fn primitives_under_affine_maps_are_parameters() {
    let scene = Scene::from_svg_str(PRIMITIVES, "prims.svg", Sizing::Natural).unwrap();
    assert_eq!(kept_transforms(&scene), ["leaning:6", "leaf:6", "tile:6"]);
    let want = ["circle", "ellipse", "rect", "ellipse", "rect"];
    assert_eq!(kinds(&scene), want);
    let flat = Scene::from_svg_str(&primitives_baked(), "baked.svg", Sizing::Natural).unwrap();
    assert!(ParamLayout::new(&flat).transforms.is_empty());
    // (The clip paths' rectangles are paths too.)
    assert!(
        kinds(&flat).iter().all(|k| *k == "path"),
        "{:?}",
        kinds(&flat)
    );
    assert_draws_as_baked(&scene, &flat);
    // The parameters as written, in the map's frame: the circle's center and radius,
    // the stroke's width, the ellipse's radii and turn, the rectangle's corner radii.
    let st = Structure::of(&scene);
    let v = scene.params();
    let at = |k: usize| st.shapes[k].primitive.as_ref().unwrap().offset;
    let near = |got: &[f64], want: &[f64]| {
        assert!(
            got.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-5),
            "{got:?} vs {want:?}"
        )
    };
    near(&v[at(0)..at(0) + 3], &[12.0, 14.0, 6.0]);
    near(&[v[st.shapes[0].stroke_width.unwrap()]], &[2.0]);
    near(
        &v[at(1)..at(1) + 5],
        &[30.0, 12.0, 7.0, 4.0, 25f64.to_radians()],
    );
    near(
        &v[at(2)..at(2) + 7],
        &[14.0, 26.0, 20.0, 12.0, 3.0, 2.0, 0.0],
    );
    near(&v[at(3)..at(3) + 5], &[50.0, 36.0, 8.0, 5.0, 0.0]);
    let t = st.transforms[0].offset + 2;
    near(&v[t..t + 4], &[1.1, 0.15, 0.4, 0.75]);
    // Every slot against central differences: the maps', the primitives' own (their
    // angles are in the transform group), the stroke width.
    // Moved, written, read back: the elements inside the maps, the same slots.
    let (moved, text) = maps_agree_and_move(
        "affine primitives",
        &scene,
        18,
        &[
            ParamGroup::Points,
            ParamGroup::Transform,
            ParamGroup::StrokeWidth,
        ],
    );
    for part in [
        "<g id=\"leaning\" transform=\"matrix(",
        "<circle id=\"dot\" cx=\"",
        "<ellipse id=\"egg\" transform=\"rotate(",
        "<rect id=\"card\" x=\"",
        "<ellipse id=\"leaf\" transform=\"matrix(",
        "<rect id=\"tile\" transform=\"matrix(",
    ] {
        assert!(text.contains(part), "{part}\n{text}");
    }
    let back = Scene::from_svg_str(&text, "back.svg", Sizing::Natural).unwrap();
    assert_eq!(
        kept_transforms(&back),
        ["leaning:6", "leaf:6", "tile:6"],
        "{text}"
    );
    assert_eq!(kinds(&back), want);
    assert_reads_back(&moved, &back, &text);
}

/// Issue 30: svg-samples/shapes/affine.svg (a circle, an ellipse and a rounded rectangle
/// under a skewed group, a skewed ellipse, stroked paths and a radial gradient under
/// general maps) perturbed as README does and fitted back: ≥ 45 dB, and the file written
/// back reads back to the same primitives and the same six-slot maps.
#[test]
fn affine_sample_is_fitted_back_as_itself() {
    use crate::common::{diffsvg, root, s, scratch};
    let dir = scratch("affine-sample-fit");
    let src = root().join("svg-samples/shapes/affine.svg");
    let scene = Scene::load(&src, Sizing::Natural).unwrap();
    assert_eq!(
        kept_transforms(&scene),
        ["slanted:6", "squeezed:6", "tilted:6", "leaf:6"]
    );
    let png = dir.join("affine.png");
    render(&scene, &RenderOptions::default())
        .save_png(&png)
        .unwrap();
    let perturbed = dir.join("perturbed.svg");
    let args = ["--seed", "5", "--points", "8"];
    let out = diffsvg(&[&["perturb", s(&src), "-o", s(&perturbed)][..], &args].concat());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out_svg = dir.join("fit.svg");
    let (initial, psnr) = fit(&perturbed, &png, &out_svg, &[]);
    assert!(
        initial < 30.0,
        "the perturbation should hurt: {initial:.2} dB"
    );
    assert!(psnr >= 45.0, "{initial:.2} → {psnr:.2} dB");
    let fitted = Scene::load(&out_svg, Sizing::Natural).unwrap();
    assert_eq!(kinds(&fitted), kinds(&scene));
    assert_eq!(kept_transforms(&fitted), kept_transforms(&scene));
}

/// Checks a scene's `maps` group-transform slots and its other slots of `groups` (the maps'
/// left out) against central differences, then moves every map slot by 0.03: the moved
/// scene and its SVG text.
fn maps_agree_and_move(
    name: &str,
    scene: &Scene,
    maps: usize,
    groups: &[ParamGroup],
) -> (Scene, String) {
    let slots = group_transform_slots(scene);
    assert_eq!(slots.len(), maps, "{name}");
    assert_slots_agree(&format!("{name}: transforms"), scene, &slots);
    let own: Vec<usize> = slots_of(scene, groups)
        .into_iter()
        .filter(|i| !slots.contains(i))
        .collect();
    assert_slots_agree(&format!("{name}: own parameters"), scene, &own);
    let mut moved = scene.clone();
    let mut w = scene.params();
    for &i in &slots {
        w[i] += 0.03;
    }
    moved.set_params(&w);
    let text = moved.to_svg_string();
    (moved, text)
}

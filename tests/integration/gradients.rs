//! Analytic gradients against central finite differences on random scenes.

use diffsvg::gradcheck::check;
use diffsvg::loss::Loss;
use diffsvg::raster::{RenderOptions, render};
use diffsvg::scene::ParamGroup;
use diffsvg::{Image, Scene, Sizing};

/// Asserts every group agrees to 1e-2 (relative, absolute below 1e-3 of the group's scale).
pub fn assert_agrees(name: &str, scene: &Scene, target: &Image, loss: Loss, bg: Option<[f32; 4]>) {
    let (grad, _, groups) = check(scene, target, loss, &RenderOptions::default(), bg, None);
    assert!(
        grad.iter().all(|g| g.is_finite()),
        "{name}: non-finite gradient"
    );
    for g in &groups {
        println!("{name}: {g}");
        assert!(g.worst <= 1e-2, "{name}: {g}");
    }
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
            // Radians: a rotation by a few hundredths moves an edge by a pixel or so.
            ParamGroup::Transform => 0.02 * amount * k,
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

#[test]
fn strokes_joins_and_caps() {
    for (join, cap) in [
        ("miter", "butt"),
        ("round", "round"),
        ("bevel", "square"),
        ("miter-clip", "butt"),
    ] {
        let s = scene(&format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="48" height="40">
            <path id="z" d="M 5 30 L 15 8 L 25 30 C 30 10 40 5 44 20" fill="none"
                  stroke="rgb(30,120,60)" stroke-width="4" stroke-opacity="0.9"
                  stroke-linejoin="{join}" stroke-linecap="{cap}" stroke-miterlimit="3"/>
            <path id="c" d="M 10 10 L 30 12 L 20 20 Z" fill="none" stroke="rgb(200,100,0)" stroke-width="2.5" stroke-opacity="0.85"
                  stroke-linejoin="{join}"/>
            </svg>"#
        ));
        let bg = Some([1.0, 1.0, 1.0, 1.0]);
        assert_agrees(
            &format!("stroke {join}/{cap}"),
            &s,
            &nudged_target(&s, 1.0, bg),
            Loss::Mse,
            bg,
        );
    }
}

#[test]
fn skewed_stroke_frame() {
    let s = scene(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="48" height="40">
        <g transform="matrix(1.3 0.2 0.4 0.7 2 3)">
        <path id="s" d="M 5 5 C 20 0 30 30 10 40" fill="none" stroke="rgb(0,0,200)" stroke-width="3" stroke-opacity="0.9"/>
        </g></svg>"#,
    );
    assert_agrees(
        "skewed stroke",
        &s,
        &nudged_target(&s, 1.0, None),
        Loss::Mse,
        None,
    );
}

#[test]
fn linear_and_radial_gradients() {
    let s = scene(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="48" height="40">
        <linearGradient id="l" x1="0.1" y1="0.2" x2="0.9" y2="0.7" spreadMethod="reflect">
          <stop offset="0.1" stop-color="rgb(250,20,20)"/>
          <stop offset="0.5" stop-color="rgb(20,200,20)" stop-opacity="0.7"/>
          <stop offset="0.8" stop-color="rgb(20,20,250)"/>
        </linearGradient>
        <radialGradient id="r" cx="30" cy="22" r="14" fx="26" fy="18" fr="2" gradientUnits="userSpaceOnUse" spreadMethod="repeat">
          <stop offset="0.2" stop-color="rgb(240,200,30)"/>
          <stop offset="0.9" stop-color="rgb(40,30,160)" stop-opacity="0.5"/>
        </radialGradient>
        <rect id="a" x="3" y="4" width="30" height="26" fill="url(#l)" fill-opacity="0.9"/>
        <ellipse id="b" cx="30" cy="22" rx="15" ry="13" fill="url(#r)" fill-opacity="0.8"/>
        </svg>"#,
    );
    let bg = Some([1.0, 1.0, 1.0, 1.0]);
    assert_agrees("gradients", &s, &nudged_target(&s, 1.0, bg), Loss::Mse, bg);
}

#[test]
fn group_layers_and_l1() {
    let s = scene(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="40">
        <rect id="under" x="2" y="2" width="30" height="20" fill="rgb(250,200,0)" fill-opacity="0.95"/>
        <g id="layer" opacity="0.6">
          <circle id="c1" cx="15" cy="18" r="10" fill="rgb(200,0,0)" fill-opacity="0.9"/>
          <circle id="c2" cx="24" cy="22" r="10" fill="rgb(0,0,200)" fill-opacity="0.7"/>
          <g id="inner" opacity="0.5"><rect id="r2" x="8" y="25" width="20" height="9" fill="green" fill-opacity="0.8"/></g>
        </g></svg>"#,
    );
    assert_agrees(
        "groups mse",
        &s,
        &nudged_target(&s, 1.0, None),
        Loss::Mse,
        None,
    );
    // L1 has a kink wherever render and target agree exactly; offset the target so that
    // no pixel does, nor comes within a difference step of it: the nudge changes a color
    // by at most 0.1, the offset is more.
    let bg = Some([0.2, 0.3, 0.4, 1.0]);
    let mut t = nudged_target(&s, 1.0, bg);
    for (k, p) in t.data.iter_mut().enumerate() {
        for c in 0..4 {
            p[c] += 0.15 + 0.05 * ((k * 7 + c) % 5) as f32 / 5.0;
        }
    }
    assert_agrees("groups l1", &s, &t, Loss::L1, bg);
}

/// A closed path of four cubics whose control points go around `c` in angular order at
/// radii in `[0.5, 1]·r`: simple in practice, so the rendering is differentiable (a pixel
/// holding a self-crossing has a kink where its clamped winding integral crosses 1).
fn star_path(r: &mut diffsvg::scene::random::Rng, c: [f64; 2], radius: f64) -> String {
    let p = |k: usize, r: &mut diffsvg::scene::random::Rng| {
        let a = (k as f64 + r.range(-0.25, 0.25)) / 12.0 * std::f64::consts::TAU;
        let d = radius * r.range(0.5, 1.0);
        format!("{:.3} {:.3}", c[0] + d * a.cos(), c[1] + d * a.sin())
    };
    let mut d = format!("M {}", p(0, r));
    for s in 0..4 {
        d += &format!(
            " C {} {} {}",
            p(3 * s + 1, r),
            p(3 * s + 2, r),
            if s == 3 { p(0, r) } else { p(3 * s + 3, r) }
        );
    }
    d + " Z"
}

/// A random scene: a filled curved path, a stroked open path with a random join and cap,
/// and a gradient-filled path inside a translucent group.
fn random_scene(seed: u64) -> Scene {
    use diffsvg::scene::random::Rng;
    let mut r = Rng::new(seed);
    let pt = |r: &mut Rng| format!("{:.3} {:.3}", r.range(2.0, 38.0), r.range(2.0, 30.0));
    let join = ["miter", "round", "bevel"][(r.next_u64() % 3) as usize];
    let cap = ["butt", "round", "square"][(r.next_u64() % 3) as usize];
    let c = |r: &mut Rng| (r.range(0.1, 0.9) * 255.0).round();
    let svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="32">
        <linearGradient id="g" x1="{}" y1="0.1" x2="{}" y2="0.9" spreadMethod="pad">
          <stop offset="0.2" stop-color="rgb({},{},{})"/><stop offset="0.8" stop-color="rgb({},{},{})" stop-opacity="0.6"/>
        </linearGradient>
        <path id="f" d="{}" fill="rgb({},{},{})" fill-opacity="{:.2}"/>
        <path id="s" d="M {} L {} Q {} {}" fill="none" stroke="rgb({},{},{})" stroke-opacity="0.85"
              stroke-width="{:.2}" stroke-linejoin="{join}" stroke-linecap="{cap}" stroke-miterlimit="3"/>
        <g id="grp" opacity="0.7"><path id="gp" d="{}" fill="url(#g)" fill-opacity="0.9"/></g>
        </svg>"#,
        r.range(0.0, 0.3),
        r.range(0.7, 1.0),
        c(&mut r),
        c(&mut r),
        c(&mut r),
        c(&mut r),
        c(&mut r),
        c(&mut r),
        star_path(&mut r, [20.0, 16.0], 12.0),
        c(&mut r),
        c(&mut r),
        c(&mut r),
        r.range(0.4, 0.9),
        pt(&mut r),
        pt(&mut r),
        pt(&mut r),
        pt(&mut r),
        c(&mut r),
        c(&mut r),
        c(&mut r),
        r.range(1.0, 4.0),
        star_path(&mut r, [22.0, 14.0], 9.0),
    );
    scene(&svg)
}

#[test]
fn random_scenes_agree_with_differences() {
    // Fixed seeds: the same scenes on every run, so a failure reproduces.
    for seed in 0..16u64 {
        let seed = seed * 7_919 + 11;
        let s = random_scene(seed);
        let bg = Some([1.0, 1.0, 1.0, 1.0]);
        assert_agrees(
            &format!("random scene {seed}"),
            &s,
            &nudged_target(&s, 1.0, bg),
            Loss::Mse,
            bg,
        );
    }
}

#[test]
fn backward_has_the_same_bits_for_any_thread_count() {
    let s = random_scene(42);
    let t = nudged_target(&s, 1.0, None);
    let run = || diffsvg::gradcheck::analytic(&s, &t, Loss::Mse, &RenderOptions::default(), None);
    let many = run();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(run);
    let three = rayon::ThreadPoolBuilder::new()
        .num_threads(3)
        .build()
        .unwrap()
        .install(run);
    assert_eq!(many.0.to_bits(), one.0.to_bits());
    assert!(
        many.1
            .iter()
            .zip(&one.1)
            .all(|(a, b)| a.to_bits() == b.to_bits())
    );
    assert!(
        many.1
            .iter()
            .zip(&three.1)
            .all(|(a, b)| a.to_bits() == b.to_bits())
    );
}

/// The fused pass (each band rendered, scored and differentiated at once) gives the bits
/// of rendering, the objective and the backward pass run one after the other, on any
/// thread count: image, loss, MSE and every gradient entry.
#[test]
fn fused_pass_has_the_bits_of_the_separate_passes() {
    use diffsvg::fit::Objective;
    use diffsvg::raster::{Prepared, backward_with_stats, render_prepared};
    let opts = RenderOptions::default();
    let mut scenes: Vec<(String, Scene)> = (0..4u64)
        .map(|k| (format!("random {k}"), random_scene(k * 31 + 5)))
        .collect();
    for p in super::common::samples() {
        let s = Scene::load(&p, Sizing::Natural).unwrap();
        scenes.push((p.display().to_string(), s));
    }
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let pixels = |i: &Image| {
        i.data
            .iter()
            .flat_map(|p| p.map(f32::to_bits))
            .collect::<Vec<_>>()
    };
    for (name, s) in &scenes {
        for (loss, bg) in [
            (Loss::Mse, None),
            (Loss::Mse, Some([1.0; 4])),
            (Loss::L1, Some([0.2, 0.4, 0.9, 0.5])),
        ] {
            let target = nudged_target(s, 1.0, bg);
            let obj = Objective::new(&target, loss, bg, 1);
            assert!(obj.is_per_pixel());
            let p = Prepared::new(s, &opts);
            let img = render_prepared(&p);
            let (l, m, d) = obj.eval_with_mse(&img);
            let (g, _) = backward_with_stats(s, &p, &d);
            for threads in [1, 3] {
                let (fi, fl, fm, fg) = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap()
                    .install(|| obj.render_and_backward(s, &p));
                let what = format!("{name}, {loss:?}, background {bg:?}, {threads} thread(s)");
                assert!(pixels(&fi) == pixels(&img), "{what}: image");
                assert_eq!(fl.to_bits(), l.to_bits(), "{what}: loss {fl} vs {l}");
                assert_eq!(fm.to_bits(), m.to_bits(), "{what}: MSE {fm} vs {m}");
                assert!(bits(&fg) == bits(&g), "{what}: gradient");
            }
        }
    }
}

/// `shape-rendering: crispEdges`: a pixel is covered wholly when its center is inside, so
/// the crisp path's points get exactly no gradient while its color and the anti-aliased
/// path beside it agree with finite differences; the written SVG keeps the attribute.
#[test]
fn crisp_edges_color_gradient_and_no_point_gradient() {
    let s = scene(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="32">
        <path id="crisp" d="M 4.3 3.7 C 20 0 36 9 33.2 27.4 L 8.6 29.1 Z" fill="rgb(200,40,30)"
              fill-opacity="0.8" shape-rendering="crispEdges"/>
        <path id="smooth" d="M 14 6 L 37 20 L 12 26 Z" fill="rgb(20,90,200)" fill-opacity="0.6"/>
        </svg>"#,
    );
    let bg = Some([1.0, 1.0, 1.0, 1.0]);
    let target = nudged_target(&s, 1.0, bg);
    let layout = diffsvg::scene::ParamLayout::new(&s);
    let crisp_point = |k: usize| {
        let slot = &layout.slots[k];
        slot.group == ParamGroup::Points && layout.owners[slot.owner].id == "crisp"
    };
    // Finite differences of the crisp points jump where a step crosses a pixel center:
    // every other parameter is compared.
    let others: Vec<usize> = (0..layout.slots.len())
        .filter(|&k| !crisp_point(k))
        .collect();
    let opts = RenderOptions::default();
    let (grad, _, groups) = check(&s, &target, Loss::Mse, &opts, bg, Some(&others));
    for g in &groups {
        println!("crisp_edges: {g}");
        assert!(g.worst <= 1e-2, "crisp_edges: {g}");
    }
    let points_of = |id: &str| -> Vec<f64> {
        layout
            .slots
            .iter()
            .zip(&grad)
            .filter(|(slot, _)| {
                slot.group == ParamGroup::Points && layout.owners[slot.owner].id == id
            })
            .map(|(_, g)| *g)
            .collect()
    };
    assert!(points_of("crisp").iter().all(|g| *g == 0.0));
    assert!(points_of("smooth").iter().any(|g| *g != 0.0));
    // Every pixel of the crisp path alone is 0 or its color: no partial coverage.
    let alone = scene(
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="32">
        <path d="M 4.3 3.7 C 20 0 36 9 33.2 27.4 L 8.6 29.1 Z" fill="#fff"
              shape-rendering="crispEdges"/></svg>"##,
    );
    let img = render(&alone, &RenderOptions::default());
    assert!(img.data.iter().all(|p| p[3] == 0.0 || p[3] == 1.0));
    assert!(img.data.iter().any(|p| p[3] == 1.0));
    assert!(
        s.to_svg_string()
            .contains(r#"shape-rendering="crispEdges""#)
    );
}

/// The scene's gradient reaches the points, colors and opacities under a filtered
/// group, the group's own opacity and the filters' parameters (blur deviation, offsets,
/// color matrix, arithmetic k), with resvg's filters and with exact ones (where
/// offsets and the blur of σ ≥ 2 move too). Offsets are fractional: at whole pixels
/// either kind has a kink.
#[test]
fn gradients_reach_the_content_under_a_filter() {
    let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="32" height="28">
        <filter id="f" x="-20%" y="-20%" width="140%" height="140%">
          <feGaussianBlur stdDeviation="1.5" result="b"/>
          <feOffset dx="2.3" dy="1.4" in="b" result="o"/>
          <feColorMatrix values="0.6 0.3 0.1 0 0.02  0.2 0.7 0.1 0 0  0.1 0.2 0.7 0 0  0 0 0 1 -0.01" in="SourceGraphic" result="s"/>
          <feComposite operator="arithmetic" k1="0.2" k2="0.6" k3="0.5" k4="0" in="s" in2="o"/>
        </filter>
        <g filter="url(#f)" opacity="0.9">
          <path d="M 6 5 C 14 2 24 6 25 20 L 8 22 Z" fill="rgb(200,60,40)" fill-opacity="0.8"/>
          <rect x="12.3" y="9.6" width="9.2" height="7.5" fill="rgb(30,120,210)" fill-opacity="0.9"/>
        </g></svg>"#;
    // (Nothing is opaque, and the matrix's alpha offset is not 0: an alpha entry of 1
    // would put an opaque pixel's alpha on the clamp at 1, and an offset of 0 a
    // transparent pixel's alpha on the clamp at 0, both kinks.)
    let scene = Scene::from_svg_str(svg, "filter.svg", Sizing::Natural).unwrap();
    let mut moved = scene.clone();
    let mut p = moved.params();
    for (k, v) in p.iter_mut().enumerate() {
        *v += 0.3 * (k as f64 * 1.3).sin();
    }
    moved.set_params(&p);
    for exact_filters in [false, true] {
        let opts = RenderOptions {
            exact_filters,
            ..RenderOptions::default()
        };
        let target = render(&moved, &opts);
        let (grad, _, groups) = check(&scene, &target, Loss::Mse, &opts, None, None);
        assert!(grad.iter().any(|g| *g != 0.0));
        assert!(groups.len() >= 4, "{groups:?}");
        for g in groups {
            assert!(g.passes(2e-2), "exact filters {exact_filters}: {g}");
        }
    }
}

/// Finite differences through the primitives added in issue 34's second part: the
/// gradient reaches the content under feConvolveMatrix, feMorphology, feTile,
/// feDisplacementMap (the moved input) and the two lightings (the alpha surface, through
/// its normals and, for point and spot lights, its height), and to the lightings' own
/// numbers (constants, color, light). feImage and feTurbulence read no content. (Lighting
/// colors are not gray: a specular result's alpha is its largest channel, a kink where
/// channels tie, and white sits on the colors' bound.)
#[test]
fn gradients_reach_the_content_under_the_resampling_and_lighting_filters() {
    let filters = [
        r#"<feConvolveMatrix order="3 2" kernelMatrix="0.1 0.3 -0.1 0.2 0.4 0.1" bias="0.05" edgeMode="duplicate"/>"#,
        // (preserveAlpha divides by alpha: a pixel turning from transparent to barely
        // covered jumps to its full straight color, a discontinuity in the points that
        // finite differences cannot cross; its adjoint is checked on pixels away from
        // alpha 0 in `raster::filter::convolve`.)
        r#"<feConvolveMatrix order="3" kernelMatrix="1 2 1 0 1 0 1 0 1" divisor="6" edgeMode="wrap"/>"#,
        r#"<feMorphology operator="dilate" radius="1.5 1"/>"#,
        r#"<feMorphology operator="erode" radius="1"/>"#,
        r#"<feOffset dx="1.3" dy="2.4" result="o"/><feTile in="o"/>"#,
        r#"<feTurbulence baseFrequency="0.2" result="t"/><feDisplacementMap in="SourceGraphic" in2="t" scale="3" xChannelSelector="R" yChannelSelector="A"/>"#,
        r#"<feDiffuseLighting surfaceScale="2" diffuseConstant="1.2" lighting-color="rgb(250,200,120)"><fePointLight x="20" y="4" z="10"/></feDiffuseLighting>"#,
        r#"<feSpecularLighting surfaceScale="3" specularConstant="0.9" specularExponent="3" lighting-color="rgb(240,210,150)"><feSpotLight x="4" y="2" z="14" pointsAtX="16" pointsAtY="16" specularExponent="1.5"/></feSpecularLighting>"#,
        r#"<feDiffuseLighting surfaceScale="1.5" lighting-color="rgb(200,230,250)"><feDistantLight azimuth="30" elevation="40"/></feDiffuseLighting>"#,
    ];
    for (i, fe) in filters.iter().enumerate() {
        let svg = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="30" height="26">
            <filter id="f" x="0" y="0" width="30" height="26" filterUnits="userSpaceOnUse">{fe}</filter>
            <g filter="url(#f)">
              <path d="M 6 5 C 14 2 24 6 25 20 L 8 22 Z" fill="rgb(200,60,40)" fill-opacity="0.8"/>
              <circle cx="15.3" cy="13.6" r="5.2" fill="rgb(30,120,210)" fill-opacity="0.7"/>
            </g></svg>"#
        );
        let scene = Scene::from_svg_str(&svg, "filter.svg", Sizing::Natural).unwrap();
        let mut moved = scene.clone();
        let mut p = moved.params();
        for (k, v) in p.iter_mut().enumerate() {
            *v += 0.3 * (k as f64 * 1.3).sin();
        }
        moved.set_params(&p);
        let opts = RenderOptions::default();
        let target = render(&moved, &opts);
        let (grad, _, groups) = check(&scene, &target, Loss::Mse, &opts, None, None);
        assert!(grad.iter().any(|g| *g != 0.0), "{i}: {fe}");
        for g in groups {
            assert!(g.passes(2e-2), "{i}: {fe}: {g}");
        }
    }
}

//! Clip paths, masks, blend modes and markers: gradients against finite differences,
//! the numerically hard cases, and SVG out → in on resvg's suite.

use diffsvg::loss::Loss;
use diffsvg::metrics::compare;
use diffsvg::raster::{RenderOptions, render, render_backward};
use diffsvg::scene::{BlendMode, ParamGroup, ParamLayout};
use diffsvg::{Image, Scene, Sizing};

use super::common::shared_data;
use super::gradients::{assert_agrees, nudged_target};

fn scene(svg: &str) -> Scene {
    Scene::from_svg_str(svg, "layers.svg", Sizing::Natural).unwrap()
}

const WHITE: Option<[f32; 4]> = Some([1.0, 1.0, 1.0, 1.0]);

#[test]
fn clip_path_gradients_reach_the_clip_and_the_content() {
    let s = scene(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="36">
        <clipPath id="c"><path id="cp" d="M 4 6 C 20 0 36 8 34 30 L 8 32 Z"/>
          <path id="cq" d="M 20 2 L 38 18 L 24 20 Z" clip-rule="evenodd"/></clipPath>
        <g clip-path="url(#c)" opacity="0.9">
          <path id="a" d="M 2 2 L 30 4 L 26 34 L 6 30 Z" fill="rgb(200,40,30)" fill-opacity="0.8"/>
          <path id="b" d="M 14 8 Q 44 18 20 34 Z" fill="rgb(20,90,200)"/>
        </g></svg>"#,
    );
    // The clip's shapes own points only: no color or opacity slots.
    let layout = ParamLayout::new(&s);
    let clip_slots = layout
        .slots
        .iter()
        .filter(|sl| layout.owners[sl.owner].id.starts_with('c'))
        .collect::<Vec<_>>();
    assert!(!clip_slots.is_empty());
    assert!(clip_slots.iter().all(|sl| sl.group == ParamGroup::Points));
    assert_agrees("clip", &s, &nudged_target(&s, 1.0, WHITE), Loss::Mse, WHITE);
}

#[test]
fn mask_gradients_luminance_alpha_and_nested() {
    for kind in ["luminance", "alpha"] {
        let s = scene(&format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="36">
            <linearGradient id="g" x1="0" x2="1"><stop offset="0.1" stop-color="white"/>
              <stop offset="0.9" stop-color="rgb(60,200,90)" stop-opacity="0.3"/></linearGradient>
            <mask id="n" mask-type="alpha"><path id="np" d="M 0 0 L 40 0 L 40 24 L 0 30 Z" fill="black" fill-opacity="0.7"/></mask>
            <mask id="m" style="mask-type:{kind}" mask="url(#n)" x="2" y="3" width="35" height="30" maskUnits="userSpaceOnUse">
              <path id="mp" d="M 3 4 C 20 0 36 8 34 30 L 8 32 Z" fill="url(#g)"/>
              <path id="mq" d="M 10 20 L 30 14 L 24 34 Z" fill="rgb(250,250,250)" fill-opacity="0.6"/>
            </mask>
            <g mask="url(#m)">
              <path id="a" d="M 2 2 L 30 4 L 26 34 L 6 30 Z" fill="rgb(200,40,30)"/>
              <path id="b" d="M 14 8 Q 44 18 20 34 Z" fill="rgb(20,90,200)" fill-opacity="0.7"/>
            </g></svg>"#
        ));
        assert_agrees(kind, &s, &nudged_target(&s, 1.0, WHITE), Loss::Mse, WHITE);
    }
}

#[test]
fn blend_mode_gradients() {
    for mode in BlendMode::ALL {
        let s = scene(&format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="32" height="28">
            <path id="under" d="M 2 2 L 28 4 L 24 26 L 4 24 Z" fill="rgb(200,120,30)" fill-opacity="0.4"/>
            <g style="mix-blend-mode:{}" opacity="0.8">
              <path id="top" d="M 10 6 C 30 2 34 20 20 26 L 8 20 Z" fill="rgb(40,150,220)" fill-opacity="0.7"/>
            </g></svg>"#,
            mode.name()
        ));
        assert_eq!(
            render(&s, &RenderOptions::default()).data.len(),
            32 * 28,
            "{mode:?}"
        );
        assert_agrees(
            mode.name(),
            &s,
            &nudged_target(&s, 1.0, WHITE),
            Loss::Mse,
            WHITE,
        );
    }
}

/// The gradient of every parameter with ∂L/∂image all ones.
fn gradient(s: &Scene) -> Vec<f64> {
    let d = Image::filled(s.width, s.height, [1.0; 4]);
    render_backward(s, &RenderOptions::default(), &d)
}

fn finite(img: &Image) -> bool {
    img.data.iter().all(|p| p.iter().all(|v| v.is_finite()))
}

#[test]
fn hard_cases_stay_finite_and_right() {
    let content = r#"<path id="a" d="M 2 2 L 30 4 L 26 30 L 6 28 Z" fill="red"/>"#;
    let cases = [
        // An empty clip path hides everything.
        (
            "empty clip",
            r#"<clipPath id="c"/>"#,
            r#"clip-path="url(#c)""#,
            Some(0.0),
        ),
        // A clip of zero area: a line.
        (
            "zero-area clip",
            r#"<clipPath id="c"><path d="M 5 5 L 25 25 Z"/></clipPath>"#,
            r#"clip-path="url(#c)""#,
            Some(0.0),
        ),
        // A fully transparent mask hides everything.
        (
            "transparent mask",
            r#"<mask id="m"><rect width="32" height="32" fill="white" fill-opacity="0"/></mask>"#,
            r#"mask="url(#m)""#,
            Some(0.0),
        ),
        (
            "empty mask",
            r#"<mask id="m"/>"#,
            r#"mask="url(#m)""#,
            Some(0.0),
        ),
        // A clip the size of the canvas changes nothing.
        (
            "whole clip",
            r#"<clipPath id="c"><rect x="-10" y="-10" width="60" height="60"/></clipPath>"#,
            r#"clip-path="url(#c)""#,
            None,
        ),
    ];
    let plain = scene(&format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="32" height="32">{content}</svg>"#
    ));
    let plain_img = render(&plain, &RenderOptions::default());
    for (name, defs, attr, alpha) in cases {
        let s = scene(&format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="32" height="32">{defs}<g {attr}>{content}</g></svg>"#
        ));
        let img = render(&s, &RenderOptions::default());
        assert!(finite(&img), "{name}");
        match alpha {
            Some(a) => assert!(img.data.iter().all(|p| p[3] == a), "{name}"),
            None => assert_eq!(compare(&img, &plain_img).max, 0.0, "{name}"),
        }
        let g = gradient(&s);
        assert!(g.iter().all(|v| v.is_finite()), "{name}: {g:?}");
        if alpha == Some(0.0) {
            // Nothing shows: no parameter of the content moves the image.
            let layout = ParamLayout::new(&s);
            for (v, sl) in g.iter().zip(&layout.slots) {
                if layout.owners[sl.owner].id == "a" {
                    assert_eq!(*v, 0.0, "{name}");
                }
            }
        }
    }
}

/// 256 clip paths nested in each other (a chain of `clip-path` on `<clipPath>`) and 256
/// nested masked groups load, render and differentiate within the layer limit; one more
/// level is refused with a clear message.
#[test]
fn deep_clips_and_masks_are_bounded() {
    let chain = |n: usize| {
        let mut defs = String::new();
        for k in 0..n {
            let next = if k + 1 < n {
                format!(r#" clip-path="url(#c{})""#, k + 1)
            } else {
                String::new()
            };
            defs.push_str(&format!(
                r#"<clipPath id="c{k}"{next}><rect x="{}" y="1" width="30" height="30"/></clipPath>"#,
                k as f64 * 0.01
            ));
        }
        format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="32" height="32">{defs}<g clip-path="url(#c0)"><rect width="32" height="32" fill="blue"/></g></svg>"#
        )
    };
    let s = Scene::from_svg_str(&chain(200), "chain.svg", Sizing::Natural).unwrap();
    let img = render(&s, &RenderOptions::default());
    assert!(finite(&img));
    assert!(img.get(16, 16)[3] > 0.99 && img.get(0, 0)[3] == 0.0);
    assert!(gradient(&s).iter().all(|v| v.is_finite()));

    let nested = |n: usize| {
        let mut open = String::new();
        let mut close = String::new();
        for k in 0..n {
            open.push_str(&format!(r#"<g mask="url(#m)" id="g{k}">"#));
            close.push_str("</g>");
        }
        format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="16" height="16"><mask id="m"><rect width="16" height="16" fill="white"/></mask>{open}<rect width="8" height="8" fill="red"/>{close}</svg>"#
        )
    };
    let s = Scene::from_svg_str(&nested(120), "nested.svg", Sizing::Natural).unwrap();
    assert!(finite(&render(&s, &RenderOptions::default())));
    assert!(gradient(&s).iter().all(|v| v.is_finite()));
    let e = Scene::from_svg_str(&nested(300), "deep.svg", Sizing::Natural).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("deep.svg") && msg.contains("nested"), "{msg}");
}

/// A marker bomb (a large marker on a path of many vertices) is refused before usvg
/// copies it; an ordinary marker renders.
#[test]
fn markers_are_bounded() {
    let marker = |elements: usize, vertices: usize| {
        let content: String = (0..elements)
            .map(|k| format!(r#"<circle cx="{}" cy="1" r="1"/>"#, k % 5))
            .collect();
        let d: String = (0..vertices)
            .map(|k| format!("L {} {} ", k % 50, (k / 50) % 50))
            .collect();
        format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="50" height="50"><marker id="m" markerWidth="4" markerHeight="4">{content}</marker><path d="M 0 0 {d}" stroke="black" marker-mid="url(#m)"/></svg>"#
        )
    };
    let s = Scene::from_svg_str(&marker(2, 10), "small.svg", Sizing::Natural).unwrap();
    assert!(s.path_count() > 10);
    let e = Scene::from_svg_str(&marker(2000, 2000), "bomb.svg", Sizing::Natural).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("bomb.svg") && msg.contains("marker"), "{msg}");
}

/// The `.svg` files directly in `dir`, sorted.
fn svg_files(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "svg"))
        .collect();
    files.sort();
    files
}

/// Writes `a` (read from `path`) as SVG, reads it back and asserts the same pixels;
/// returns the text written.
fn assert_round_trip(a: &Scene, path: &std::path::Path) -> String {
    let opts = RenderOptions::default();
    let text = a.to_svg_string();
    let b = Scene::from_svg_str(&text, "roundtrip.svg", Sizing::Natural)
        .unwrap_or_else(|e| panic!("{}: {e}\n{text}", path.display()));
    let c = compare(&render(a, &opts), &render(&b, &opts));
    assert!(
        c.max < 3.0 && c.mae < 0.02,
        "{}: round trip changed pixels by {c:?}\n{text}",
        path.display()
    );
    text
}

/// Every supported file of resvg's masking, blend, isolation, marker, paint-order and
/// pattern folders reads back from diffsvg's SVG out with the same pixels.
#[test]
fn layers_survive_a_round_trip_on_resvgs_suite() {
    let Some(data) = shared_data("layers_survive_a_round_trip_on_resvgs_suite") else {
        return;
    };
    let tests = data.join("resvg-tests/tests");
    let folders = [
        "masking/clipPath",
        "masking/clip-rule",
        "masking/mask",
        "painting/mix-blend-mode",
        "painting/isolation",
        "painting/marker",
        "painting/paint-order",
        "paint-servers/pattern",
    ];
    let mut checked = 0;
    for f in folders {
        for path in svg_files(&tests.join(f)) {
            let Ok(a) = Scene::load(&path, Sizing::Natural) else {
                continue;
            };
            assert_round_trip(&a, &path);
            checked += 1;
        }
    }
    assert!(checked > 150, "only {checked} files checked");
}

/// Every file of resvg's filters folder that diffsvg draws as resvg does reads back from
/// diffsvg's SVG out with the same pixels: the filters are written, not dropped. (A filter
/// under a rotation or skew is approximated in device pixels, and written as
/// approximated.)
#[test]
fn filters_survive_a_round_trip_on_resvgs_suite() {
    let Some(data) = shared_data("filters_survive_a_round_trip_on_resvgs_suite") else {
        return;
    };
    let root = data.join("resvg-tests/tests/filters");
    let mut dirs: Vec<_> = std::fs::read_dir(&root)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    dirs.sort();
    let opts = RenderOptions::default();
    let (mut checked, mut filtered) = (0, 0);
    for path in dirs.iter().flat_map(|d| svg_files(d)) {
        let Ok(a) = Scene::load(&path, Sizing::Natural) else {
            continue;
        };
        let same = diffsvg::reference::parity(&path, Sizing::Natural, &opts);
        if !same.is_ok_and(|p| p.passes()) {
            continue;
        }
        let text = assert_round_trip(&a, &path);
        filtered += usize::from(text.contains("<filter "));
        checked += 1;
    }
    assert!(
        checked > 200 && filtered > 150,
        "{checked} files, {filtered} with filters"
    );
}

#[test]
fn pattern_gradients_reach_the_tiles() {
    let s = scene(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="36">
        <pattern id="p" patternUnits="userSpaceOnUse" width="12" height="10">
          <path id="t" d="M 1 1 L 10 2 L 6 9 Z" fill="rgb(30,140,60)" fill-opacity="0.9"/>
        </pattern>
        <path id="a" d="M 3 3 C 20 0 38 8 36 32 L 6 33 Z" fill="url(#p)" fill-opacity="0.8"
              stroke="url(#p)" stroke-width="3"/></svg>"#,
    );
    // Several tiles, copies of the first sharing its parameters (`scene::tiling`).
    assert!(s.path_count() > 8, "{}", s.path_count());
    assert_agrees(
        "pattern",
        &s,
        &nudged_target(&s, 1.0, WHITE),
        Loss::Mse,
        WHITE,
    );
}

/// A rotated pattern holding a pattern, on a fill and a stroke: the tiles share the first
/// tile's parameters (central differences move every copy; a copy's own slots get 0), and
/// SVG out writes one `<pattern>` per pattern, read back to the same pixels.
#[test]
fn patterns_are_written_back_as_patterns() {
    let s = scene(
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="30" height="26">
        <pattern id="inner" patternUnits="userSpaceOnUse" width="4" height="4">
          <rect x="0.5" y="0.5" width="1.6" height="1.4" fill="#f0e0a0"/></pattern>
        <pattern id="outer" patternUnits="userSpaceOnUse" x="2" y="1" width="13" height="10"
                 patternTransform="rotate(-15) scale(0.9)">
          <path d="M 2 1 L 11 3 L 7 9 Z" fill="url(#inner)"/>
          <ellipse cx="4" cy="7" rx="3" ry="2" fill="#3050a0" fill-opacity="0.7"/>
        </pattern>
        <circle cx="15" cy="13" r="10" fill="url(#outer)" stroke="url(#outer)" stroke-width="3"/></svg>"##,
    );
    // Every slot of the first tiles and a spread of the rest (all of them take minutes).
    let n = ParamLayout::new(&s).len();
    let which: Vec<usize> = (0..n).filter(|&i| i < 120 || i % 37 == 0).collect();
    let (grad, num, groups) = diffsvg::gradcheck::check(
        &s,
        &nudged_target(&s, 0.5, WHITE),
        Loss::Mse,
        &RenderOptions::default(),
        WHITE,
        Some(&which),
    );
    for &i in &which {
        assert!(
            grad[i] != 0.0 || num[i].abs() < 1e-9,
            "slot {i}: 0 against {}",
            num[i]
        );
    }
    for g in &groups {
        assert!(g.worst <= 1e-2, "{g}");
    }
    // Most slots are copies': their gradient is 0.
    let zeros = grad.iter().filter(|g| **g == 0.0).count();
    assert!(zeros * 2 > grad.len(), "{zeros} of {} slots", grad.len());
    let text = assert_round_trip(&s, std::path::Path::new("patterns.svg"));
    assert_eq!(text.matches("<pattern ").count(), 4, "{text}");
}

#[test]
fn pattern_tiles_are_bounded() {
    let svg = |w: f64| {
        format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="4000" height="4000">
            <pattern id="p" patternUnits="userSpaceOnUse" width="{w}" height="{w}">
              <rect width="{}" height="{}" fill="red"/></pattern>
            <rect width="4000" height="4000" fill="url(#p)"/></svg>"#,
            w / 2.0,
            w / 2.0
        )
    };
    // A tile of 1e-6 px draws nothing, as in resvg.
    let s = Scene::from_svg_str(&svg(1e-6), "tiny.svg", Sizing::Natural).unwrap();
    assert_eq!(s.path_count(), 1, "only the clip shape is left");
    // A tile of 2 px over 4000² would be 4 million copies: refused before any is made.
    let e = Scene::from_svg_str(&svg(2.0), "many.svg", Sizing::Natural).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("many.svg") && msg.contains("tiles"), "{msg}");
    // A tile of 1e6 px is one tile.
    let s = Scene::from_svg_str(&svg(1e6), "huge.svg", Sizing::Natural).unwrap();
    assert!(finite(&render(&s, &RenderOptions::default())));
}

/// Patterns inside patterns multiply their tiles: counted over the drawing, refused past
/// the limit; and long chains of clip paths (or patterns) referring to each other are
/// refused before usvg follows them (20,000 links overflowed its stack).
#[test]
fn nested_patterns_and_reference_chains_are_bounded() {
    let mut defs = String::new();
    for k in 0..4 {
        let fill = if k < 3 {
            format!("url(#p{})", k + 1)
        } else {
            "red".to_string()
        };
        defs.push_str(&format!(
            r#"<pattern id="p{k}" patternUnits="userSpaceOnUse" width="40" height="40"><rect width="400" height="400" fill="{fill}"/></pattern>"#
        ));
    }
    let svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="400" height="400">{defs}<rect width="400" height="400" fill="url(#p0)"/></svg>"#
    );
    let e = Scene::from_svg_str(&svg, "nested.svg", Sizing::Natural).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("nested.svg") && msg.contains("tiles"), "{msg}");

    let n = 20_000;
    let defs: String = (0..n)
        .map(|k| {
            let next = if k + 1 < n {
                format!(r#" clip-path="url(#c{})""#, k + 1)
            } else {
                String::new()
            };
            format!(r#"<clipPath id="c{k}"{next}><rect width="30" height="30"/></clipPath>"#)
        })
        .collect();
    let svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="32" height="32">{defs}<g clip-path="url(#c0)"><rect width="32" height="32"/></g></svg>"#
    );
    let e = Scene::from_svg_str(&svg, "chain.svg", Sizing::Natural).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("chain.svg") && msg.contains("256 deep"),
        "{msg}"
    );
}

/// Found by the fuzzer (seed 29): a pattern of 1,000 shapes over a few hundred tiles, and
/// 20,000 copies of a path with small markers, each ran out of a gigabyte before a bound
/// applied. Both are refused now, naming the file.
#[test]
fn copies_of_patterns_and_markers_are_bounded() {
    let rects: String = (0..1000)
        .map(|_| r#"<rect x="10" y="10" width="10" height="10" fill="green"/>"#)
        .collect();
    let svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="400" height="400"><pattern id="p" patternUnits="userSpaceOnUse" width="20" height="20">{rects}</pattern><rect width="400" height="400" fill="url(#p)"/></svg>"#
    );
    let msg = Scene::from_svg_str(&svg, "shapes.svg", Sizing::Natural)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("shapes.svg") && msg.contains("shapes"),
        "{msg}"
    );

    let paths: String = (0..20_000)
        .map(|_| r#"<path d="M 1 155 C 40 125 80 185 120 155" marker-mid="url(#m)" marker-end="url(#m)" fill="none" stroke="black"/>"#)
        .collect();
    let svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200"><marker id="m" markerWidth="4" markerHeight="4"><circle cx="2" cy="2" r="2"/><rect width="1" height="1"/></marker>{paths}</svg>"#
    );
    let msg = Scene::from_svg_str(&svg, "marked.svg", Sizing::Natural)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("marked.svg") && msg.contains("markers"),
        "{msg}"
    );
}

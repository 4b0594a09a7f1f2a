//! SVG `<text>` through fonts (issue 29): glyph outlines against resvg, the missing-family
//! error in the library and on the command line, gradients on a glyph, SVG out and back.

use diffsvg::loss::Loss;
use diffsvg::metrics::compare;
use diffsvg::raster::{RenderOptions, render};
use diffsvg::reference::{PARITY_MAE, PARITY_PSNR, parity_with};
use diffsvg::scene::{Fonts, Paint};
use diffsvg::{Node, Scene, Sizing};

use super::common::{assert_fails, diffsvg, s, scratch, shared_data, write};
use super::gradients::{assert_agrees, nudged_target};

/// 24 px text with a gradient, in the default family (no `font-family`: DejaVu Sans).
const GRADIENT_TEXT: &str = r#"<svg xmlns="http://www.w3.org/2000/svg" width="220" height="40">
  <defs><linearGradient id="g" x1="0" x2="1">
    <stop offset="0" stop-color="crimson"/><stop offset="1" stop-color="navy"/>
  </linearGradient></defs>
  <text id="greeting" x="6" y="28" font-size="24" fill="url(#g)">Hello -- &lt;world&gt;</text>
</svg>"#;

fn with_family(svg: &str, family: &str) -> String {
    svg.replace("<text ", &format!("<text font-family=\"{family}\" "))
}

#[test]
fn text_in_the_bundled_font_matches_resvg() {
    let dir = scratch("text_parity");
    // At 48 px. Smaller text packs more edges per pixel, and the two rasterizers'
    // antialiasing (exact area here, tiny-skia's supersampled rows there) differ at every
    // edge: at 24 px this drawing measures MAE 0.55, PSNR 39.1 dB against resvg, just past
    // the thresholds, with the same glyph outlines on both sides.
    let big = GRADIENT_TEXT
        .replace(r#"width="220" height="40""#, r#"width="440" height="70""#)
        .replace(r#"y="28" font-size="24""#, r#"y="56" font-size="48""#);
    let mut outcomes = Vec::new();
    for (name, svg) in [
        ("default.svg", big.clone()),
        ("sans.svg", with_family(&big, "sans-serif")),
        ("serif.svg", with_family(&big, "serif")),
        ("mono.svg", with_family(&big, "monospace")),
        (
            "bold.svg",
            big.replace("<text ", "<text font-weight=\"bold\" "),
        ),
    ] {
        let f = write(&dir, name, &svg);
        let p = parity_with(
            &f,
            Sizing::Natural,
            &RenderOptions::default(),
            &Fonts::new(),
        )
        .unwrap_or_else(|e| panic!("{name}: {e}"));
        let c = p.comparison;
        println!("{name}: MAE {:.3}, PSNR {:.2} dB", c.mae, c.psnr);
        // Ink: the glyphs are drawn, not dropped.
        assert!(
            p.ours.data.iter().filter(|px| px[3] > 0.5).count() > 300,
            "{name}"
        );
        outcomes.push((name, c.mae <= PARITY_MAE && c.psnr >= PARITY_PSNR, c));
    }
    let failing: Vec<_> = outcomes.iter().filter(|o| !o.1).collect();
    assert!(failing.is_empty(), "{failing:?}");
    // The gradient reaches the glyphs as it reaches any path.
    let scene = Scene::from_svg_str(GRADIENT_TEXT, "t.svg", Sizing::Natural).unwrap();
    let Node::Path(p) = &scene.nodes[0] else {
        panic!("a path expected")
    };
    assert!(matches!(p.fill.as_ref().unwrap().paint, Paint::Gradient(_)));
    assert_eq!(p.id, "greeting");
    assert_eq!(p.text.as_deref(), Some("Hello -- <world>"));
}

#[test]
fn missing_font_family_is_an_error_naming_file_and_family() {
    let svg = with_family(GRADIENT_TEXT, "No Such Family, cursive");
    let e = Scene::from_svg_str(&svg, "missing.svg", Sizing::Natural)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("missing.svg: ") && e.contains("No Such Family") && !e.contains('\n'),
        "{e}"
    );
    // Fallback: set in DejaVu Sans, the same pixels as the default family.
    let fallback = Fonts::new().with_fallback(true);
    let fell = Scene::from_svg_str_with(&svg, "missing.svg", Sizing::Natural, &fallback).unwrap();
    let plain = Scene::from_svg_str(GRADIENT_TEXT, "t.svg", Sizing::Natural).unwrap();
    let opts = RenderOptions::default();
    assert_eq!(render(&fell, &opts).data, render(&plain, &opts).data);
}

#[test]
fn cli_refuses_a_missing_family_and_takes_font_fallback() {
    let dir = scratch("text_cli_missing");
    let input = write(
        &dir,
        "missing.svg",
        &with_family(GRADIENT_TEXT, "No Such Family"),
    );
    let out = dir.join("out.png");
    let out_svg = dir.join("out.svg");
    for (cmd, output) in [
        (vec!["render", s(&input), "-o", s(&out)], &out),
        (vec!["perturb", s(&input), "-o", s(&out_svg)], &out_svg),
    ] {
        let o = diffsvg(&cmd);
        assert_fails(&o, "missing.svg", "no such family", output);
    }
    let o = diffsvg(&["render", s(&input), "-o", s(&out), "--font-fallback"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.exists());
    // A font flag naming something that is no font: one line naming that file.
    let out2 = dir.join("out2.png");
    let o = diffsvg(&["render", s(&input), "-o", s(&out2), "--font", s(&input)]);
    assert_fails(&o, "missing.svg", "not a font file", &out2);
    let o = diffsvg(&[
        "render",
        s(&input),
        "-o",
        s(&out2),
        "--font-dir",
        s(&dir.join("no-such-folder")),
    ]);
    assert_fails(&o, "no-such-folder", "no such file", &out2);
}

#[test]
fn font_files_and_folders_are_loaded() {
    let Some(data) = shared_data("font_files_and_folders_are_loaded") else {
        return;
    };
    let fonts = data.join("resvg-tests/fonts");
    let dir = scratch("text_cli_fonts");
    let input = write(&dir, "noto.svg", &with_family(GRADIENT_TEXT, "Noto Sans"));
    let out = dir.join("out.png");
    let o = diffsvg(&["render", s(&input), "-o", s(&out)]);
    assert_fails(&o, "noto.svg", "noto sans", &out);
    for flags in [
        vec!["--font", s(&fonts.join("NotoSans-Regular.ttf"))],
        vec!["--font-dir", s(&fonts)],
    ] {
        let mut args = vec!["render", s(&input), "-o", s(&out), "--compare"];
        args.extend(flags);
        let o = diffsvg(&args);
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(stdout.contains("PSNR"), "{stdout}");
        std::fs::remove_file(&out).unwrap();
    }
    // Noto Sans is not DejaVu Sans: other glyphs than the fallback's.
    let noto = Scene::load_with(&input, Sizing::Natural, &Fonts::new().with_dir(&fonts)).unwrap();
    let fell =
        Scene::load_with(&input, Sizing::Natural, &Fonts::new().with_fallback(true)).unwrap();
    assert_ne!(noto, fell);
    // The parity preset of resvg's harness maps the generic families to its fonts.
    let cursive = write(&dir, "cursive.svg", &with_family(GRADIENT_TEXT, "cursive"));
    assert!(Scene::load(&cursive, Sizing::Natural).is_err());
    let suite = Fonts::resvg_test_suite(&fonts);
    let p = parity_with(&cursive, Sizing::Natural, &RenderOptions::default(), &suite).unwrap();
    assert!(p.passes(), "{:?}", p.comparison);
}

#[test]
fn glyph_outline_gradient_matches_finite_differences() {
    // One curvy glyph with a gradient fill on a small canvas: points, stops and opacity.
    let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="24" height="24">
      <defs><linearGradient id="g" x1="0" x2="0" y1="0" y2="1">
        <stop offset="0.2" stop-color="#c04020"/><stop offset="0.9" stop-color="#2040c0"/>
      </linearGradient></defs>
      <text id="s" x="5.3" y="19.6" font-size="20" fill="url(#g)" fill-opacity="0.8">S</text>
    </svg>"##;
    let scene = Scene::from_svg_str(svg, "s.svg", Sizing::Natural).unwrap();
    assert_eq!(scene.path_count(), 1);
    let target = nudged_target(&scene, 0.3, Some([1.0; 4]));
    assert_agrees("glyph S", &scene, &target, Loss::Mse, Some([1.0; 4]));
}

#[test]
fn text_survives_svg_out_and_back() {
    // Two spans (two paths, ids greeting-1 and -2), characters that need care in a comment.
    let svg = GRADIENT_TEXT.replace(
        "&lt;world&gt;</text>",
        "&lt;world&gt; <tspan fill=\"teal\">a--b-</tspan></text>",
    );
    let a = Scene::from_svg_str(&svg, "t.svg", Sizing::Natural).unwrap();
    let written = a.to_svg_string();
    assert!(
        written.contains("<!-- text: Hello - - <world> a- -b- -->"),
        "{written}"
    );
    let b = Scene::from_svg_str(&written, "back.svg", Sizing::Natural).unwrap();
    let ids = |s: &Scene| {
        let mut v = Vec::new();
        s.for_each_path(|p| v.push(p.id.clone()));
        v
    };
    assert_eq!(ids(&a), ids(&b));
    assert!(
        ids(&a).len() >= 2 && ids(&a)[0] == "greeting-1",
        "{:?}",
        ids(&a)
    );
    let opts = RenderOptions::default();
    let c = compare(&render(&a, &opts), &render(&b, &opts));
    assert!(c.max < 2.0 && c.mae < 0.01, "{c:?}");
    // And through a file, as the command line writes it.
    let dir = scratch("text_roundtrip");
    let f = dir.join("text.svg");
    a.save_svg(&f).unwrap();
    let c2 = compare(
        &render(&Scene::load(&f, Sizing::Natural).unwrap(), &opts),
        &render(&a, &opts),
    );
    assert!(c2.max < 2.0, "{c2:?}");
}

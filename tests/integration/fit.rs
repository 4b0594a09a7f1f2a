//! `diffsvg fit`: refinement recovers perturbed drawings, runs are reproducible, bad input
//! fails cleanly.

use std::path::Path;

use diffsvg::raster::{RenderOptions, render};
use diffsvg::scene::random::perturb;
use diffsvg::{Scene, Sizing};

use super::common::{assert_fails, diffsvg, json_summary, root, s, scratch, write};

/// Target PNG of a sample at `width` and a perturbed SVG of it (points moved by up to 8 px,
/// colors by up to 0.2); returns (svg, png).
fn perturbed_case(
    dir: &std::path::Path,
    name: &str,
    width: u32,
    seed: u64,
) -> (std::path::PathBuf, std::path::PathBuf) {
    let src = root().join("svg-samples").join(format!("{name}.svg"));
    let scene = Scene::load(&src, Sizing::Width(width)).unwrap();
    let png = dir.join(format!("{name}.png"));
    render(&scene, &RenderOptions::default())
        .save_png(&png)
        .unwrap();
    let svg = dir.join(format!("{name}.perturbed.svg"));
    perturb(&scene, 8.0, 0.2, seed).save_svg(&svg).unwrap();
    (svg, png)
}

/// Per path, how many closed subpaths end on their start point.
fn ends_at_start(scene: &Scene) -> Vec<usize> {
    let mut v = Vec::new();
    scene.for_each_path(|p| v.push(p.subpaths.iter().filter(|s| s.ends_at_start).count()));
    v
}

/// The issue's recovery goal on a few samples at 128 px wide: ≥ 40 dB within 500 steps.
#[test]
fn refinement_recovers_perturbed_samples() {
    let dir = scratch("fit-recover");
    for name in [
        "01-curves",
        "03-linear-gradient",
        "06-evenodd-star",
        "10-logo",
    ] {
        let (svg, png) = perturbed_case(&dir, name, 128, 3);
        let out_svg = dir.join(format!("{name}.fit.svg"));
        let out = diffsvg(&[
            "fit",
            s(&svg),
            s(&png),
            "-o",
            s(&out_svg),
            "--iters",
            "500",
            "--until-psnr",
            "40",
            "--json",
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let sum = json_summary(&out);
        let psnr = sum["psnr"].as_f64().unwrap();
        let initial = sum["initial_psnr"].as_f64().unwrap();
        assert!(psnr >= 40.0, "{name}: {initial:.2} → {psnr:.2} dB");
        assert!(
            initial < 25.0,
            "{name}: the perturbation should hurt ({initial:.2} dB)"
        );
        // The written SVG renders to what the summary says.
        let fitted = Scene::load(&out_svg, Sizing::Natural).unwrap();
        // Closed subpaths that end on their start still do (their closing point is the
        // start's parameter): no gap opened for the closing line to bridge.
        let source = Scene::load(
            root().join(format!("svg-samples/{name}.svg")),
            Sizing::Natural,
        )
        .unwrap();
        assert_eq!(ends_at_start(&fitted), ends_at_start(&source), "{name}");
        if name == "10-logo" {
            assert!(ends_at_start(&source).iter().sum::<usize>() > 0);
        }
        let mut target = diffsvg::Image::load(&png).unwrap();
        target.over_background([1.0; 4]);
        let mut img = render(&fitted, &RenderOptions::default()).quantized();
        img.over_background([1.0; 4]);
        let c = diffsvg::metrics::compare(&img, &target);
        assert!(
            c.psnr > 38.0,
            "{name}: SVG as written gives {:.2} dB",
            c.psnr
        );
    }
}

/// Same inputs → same output bits, and the per-iteration JSON lines and log are complete.
#[test]
fn fit_is_reproducible_and_logs() {
    let dir = scratch("fit-repro");
    let (svg, png) = perturbed_case(&dir, "05-translucent-overlap", 64, 9);
    let run = |out: &std::path::Path, log: &std::path::Path| {
        let o = diffsvg(&[
            "fit",
            s(&svg),
            s(&png),
            "-o",
            s(out),
            "--iters",
            "30",
            "--json",
            "--log",
            s(log),
            "--snapshots",
            s(&dir.join("snaps")),
            "--every",
            "10",
            "--compare",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        o
    };
    let o = run(&dir.join("a.svg"), &dir.join("a.csv"));
    run(&dir.join("b.svg"), &dir.join("b.jsonl"));
    assert_eq!(
        std::fs::read(dir.join("a.svg")).unwrap(),
        std::fs::read(dir.join("b.svg")).unwrap()
    );
    let lines = String::from_utf8_lossy(&o.stdout).lines().count();
    assert_eq!(lines, 31 + 1, "one line per evaluation and a summary");
    let csv = std::fs::read_to_string(dir.join("a.csv")).unwrap();
    assert_eq!(csv.lines().count(), 32);
    assert!(csv.starts_with("iteration,phase,loss,psnr,elapsed_ms"));
    let jsonl = std::fs::read_to_string(dir.join("b.jsonl")).unwrap();
    let last: serde_json::Value = serde_json::from_str(jsonl.lines().last().unwrap()).unwrap();
    assert_eq!(last["iteration"], 30);
    for k in ["000000", "000010", "000020", "000030"] {
        assert!(dir.join("snaps").join(format!("{k}.png")).exists());
        assert!(dir.join("snaps").join(format!("{k}.svg")).exists());
    }
    let cmp = diffsvg::Image::load(dir.join("a.compare.png")).unwrap();
    assert_eq!((cmp.width, cmp.height), (64 * 3, 64));
}

#[test]
fn fit_bad_inputs_fail_cleanly() {
    let dir = scratch("fit-bad");
    let (svg, png) = perturbed_case(&dir, "01-curves", 32, 1);
    let out = dir.join("out.svg");
    let o = diffsvg(&["fit", s(&svg), s(&dir.join("missing.png")), "-o", s(&out)]);
    assert_fails(&o, "missing.png", "no such file", &out);
    let not_image = write(&dir, "not-image.png", "hello");
    let o = diffsvg(&["fit", s(&svg), s(&not_image), "-o", s(&out)]);
    assert_fails(&o, "not-image.png", "not a readable png", &out);
    let empty = write(
        &dir,
        "empty.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="32" height="32"/>"#,
    );
    let o = diffsvg(&["fit", s(&empty), s(&png), "-o", s(&out)]);
    assert_fails(&o, "empty.svg", "nothing to optimize", &out);
    let o = diffsvg(&["fit", s(&svg), s(&png), "-o", s(&out), "--lr-points", "NaN"]);
    assert_fails(&o, "points", "learning rate", &out);
    let o = diffsvg(&[
        "fit",
        s(&svg),
        s(&png),
        "-o",
        s(&out),
        "--freeze",
        "points,colors,opacities,widths,paint,stops,transforms",
    ]);
    assert_fails(&o, "perturbed.svg", "frozen", &out);
    let o = diffsvg(&["fit", s(&svg), s(&png), "-o", s(&out), "--freeze", "wings"]);
    assert_fails(&o, "wings", "possible values: points, colors", &out);
    // Unwritable: the output's folder would have to be created inside a file.
    let blocker = write(&dir, "blocker", "");
    let inside = blocker.join("out.svg");
    let o = diffsvg(&["fit", s(&svg), s(&png), "-o", s(&inside)]);
    assert_fails(&o, "out.svg", "cannot create", &out);
    let o = diffsvg(&["fit", s(&svg), s(&png), "-o", s(&dir.join("out.png"))]);
    assert_fails(&o, "out.png", "must be a .svg", &out);
}

/// `fit --fit-background`: a drawing over a blue backdrop, fitted from the drawing alone
/// over white, recovers the backdrop's color (written as a canvas-sized `<rect>` that the
/// SVG reads back) along with the drawing; a target with transparent pixels and no opaque
/// `--background` is refused.
#[test]
fn fit_background_recovers_the_backdrop() {
    let dir = scratch("fit-background");
    let target = write(
        &dir,
        "target.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="48">
        <rect width="64" height="48" fill="rgb(40,120,200)"/>
        <circle cx="30" cy="22" r="12" fill="rgb(230,180,20)"/></svg>"#,
    );
    let init = write(
        &dir,
        "init.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="48">
        <circle cx="33" cy="24" r="10" fill="rgb(200,150,60)"/></svg>"#,
    );
    let out = dir.join("fitted.svg");
    let o = diffsvg(&[
        "fit",
        s(&init),
        s(&target),
        "-o",
        s(&out),
        "--iters",
        "300",
        "--fit-background",
        "--json",
    ]);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let summary = json_summary(&o);
    let bg: Vec<f64> = summary["background"]
        .as_array()
        .expect("background in the summary")
        .iter()
        .map(|v| v.as_f64().unwrap() * 255.0)
        .collect();
    for (got, want) in bg.iter().zip([40.0, 120.0, 200.0]) {
        assert!((got - want).abs() < 2.0, "background {bg:?}");
    }
    assert!(summary["psnr"].as_f64().unwrap() > 35.0, "{summary}");
    // The written SVG holds the backdrop and renders like the target.
    let fitted = Scene::load(&out, Sizing::Natural).unwrap();
    let want = Scene::load(&target, Sizing::Natural).unwrap();
    let (a, b) = (
        render(&fitted, &RenderOptions::default()),
        render(&want, &RenderOptions::default()),
    );
    let psnr = diffsvg::metrics::compare(&a.quantized(), &b.quantized()).psnr;
    assert!(psnr > 35.0, "written SVG against the target: {psnr} dB");
    assert!(
        std::fs::read_to_string(&out)
            .unwrap()
            .contains("id=\"background\"")
    );
    // Transparent target, transparent background: refused before any work.
    let png = dir.join("transparent.png");
    render(
        &Scene::load(&init, Sizing::Natural).unwrap(),
        &RenderOptions::default(),
    )
    .save_png(&png)
    .unwrap();
    let refused = dir.join("refused.svg");
    let o = diffsvg(&[
        "fit",
        s(&init),
        s(&png),
        "-o",
        s(&refused),
        "--fit-background",
    ]);
    assert_fails(
        &o,
        "--fit-background needs an opaque background",
        "fit",
        &refused,
    );
}

/// A fit toward a rendering made with an exactness flag: renders `truth` into `dir` with
/// `flag` (`--exact-filters`, `--exact-overlaps`), and returns a function that fits
/// `init` toward it with `args`, adding `flag` when asked, and gives the fitted SVG, the
/// standard output and the standard error.
fn fit_toward<'a>(
    dir: &'a Path,
    truth: &str,
    init: &str,
    flag: &'a str,
) -> impl Fn(&[&str], bool) -> (String, String, String) + 'a {
    let truth = write(dir, "truth.svg", truth);
    let init = write(dir, "init.svg", init);
    let target = dir.join("target.png");
    let o = diffsvg(&["render", s(&truth), "-o", s(&target), flag]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = dir.join("fitted.svg");
    move |extra: &[&str], with_flag: bool| {
        let mut args = vec!["fit", s(&init), s(&target), "-o", s(&out)];
        args.extend_from_slice(extra);
        if with_flag {
            args.push(flag);
        }
        let o = diffsvg(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (
            std::fs::read_to_string(&out).unwrap(),
            String::from_utf8_lossy(&o.stdout).into_owned(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    }
}

/// A drop shadow's offset and blur fitted from the command line: the target is rendered
/// with `render --exact-filters`, the fit starts from a small, near shadow and moves only
/// the filter, and the written SVG holds the recovered numbers. Without
/// `--exact-filters` the fit says that offsets and deviations will not move.
#[test]
fn fit_exact_filters_recovers_a_drop_shadow() {
    let dir = scratch("fit-exact-filters");
    let svg = |dx: f64, dy: f64, sd: f64| {
        format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="48">
            <filter id="s" x="-40%" y="-40%" width="180%" height="180%">
              <feDropShadow dx="{dx}" dy="{dy}" stdDeviation="{sd}" flood-opacity="0.7"/></filter>
            <g filter="url(#s)">
              <rect x="12" y="10" width="24" height="18" fill="rgb(40,110,220)"/>
              <circle cx="36" cy="28" r="9" fill="rgb(230,80,40)"/></g></svg>"#
        )
    };
    let fit = fit_toward(
        &dir,
        &svg(4.0, 5.0, 2.5),
        &svg(1.5, 1.5, 1.2),
        "--exact-filters",
    );
    let args = [
        "--iters",
        "200",
        "--freeze",
        "points,colors,opacities",
        "--lr-filter",
        "0.2",
    ];
    let number = |text: &str, attr: &str| -> f64 {
        let at = text.find(&format!(" {attr}=\"")).expect(attr) + attr.len() + 3;
        let end = text[at..].find(['"', ' ']).unwrap();
        text[at..at + end].parse().unwrap()
    };
    let (fitted, _, _) = fit(&args, true);
    for (attr, want) in [("dx", 4.0), ("dy", 5.0), ("stdDeviation", 2.5)] {
        let got = number(&fitted, attr);
        assert!(
            (got - want).abs() < 0.15,
            "{attr}: {got}, want {want}\n{fitted}"
        );
    }
    let (unmoved, _, note) = fit(&args, false);
    assert!(note.contains("--exact-filters"), "{note}");
    assert_eq!(number(&unmoved, "dx"), 1.5, "{unmoved}");
}

/// A path whose subpaths overlap, fitted from the command line toward its own rendering
/// with `render --exact-overlaps`: with `fit --exact-overlaps` the fit renders and
/// differentiates the same exact coverage and recovers the drawing; without, the clamped
/// winding integral over-covers the pixels on the coincident edges, and the fit ends
/// further off.
#[test]
fn fit_exact_overlaps_matches_an_exact_target() {
    let dir = scratch("fit-exact-overlaps");
    // The first square twice (coincident edges) and a third overlapping it; the fit
    // starts with the doubled square's left side 1.3 px off.
    let svg = |x: f64| {
        format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="32" height="24">
            <path d="M {x} 4.5 H 20.5 V 18.5 H {x} Z M 10.5 4.5 H 26.5 V 18.5 H 10.5 Z M {x} 4.5 H 20.5 V 18.5 H {x} Z"
                  fill="rgb(40,110,220)"/></svg>"#
        )
    };
    let fit = fit_toward(&dir, &svg(4.3), &svg(5.6), "--exact-overlaps");
    let psnr = |exact: bool| {
        let (_, out, _) = fit(&["--iters", "150", "--json"], exact);
        let line = out.lines().last().expect("a JSON line");
        let v: serde_json::Value = serde_json::from_str(line).expect(line);
        v["psnr"].as_f64().expect("psnr")
    };
    let (exact, clamped) = (psnr(true), psnr(false));
    // Measured: about 65.5 dB exact, 47.5 dB clamped, from 21 dB.
    assert!(exact > 55.0, "exact fit: {exact} dB");
    assert!(
        exact > clamped + 10.0,
        "exact {exact} dB, clamped {clamped} dB"
    );
}

//! `diffsvg vectorize`: builds SVGs that match pictures, in every mode; bad input fails
//! cleanly.

use diffsvg::raster::{RenderOptions, render};
use diffsvg::{Image, Scene, Sizing};

use super::common::{assert_fails, diffsvg, json_summary, root, s, scratch, shared_data};

/// PSNR over RGB of an SVG rendered over white against a picture.
fn psnr_of(svg: &std::path::Path, target: &Image) -> f64 {
    let scene = Scene::load(svg, Sizing::Natural).unwrap();
    assert_eq!((scene.width, scene.height), (target.width, target.height));
    let mut img = render(&scene, &RenderOptions::default()).quantized();
    img.over_background([1.0; 4]);
    let mut t = target.clone();
    t.over_background([1.0; 4]);
    let mse: f64 = img
        .data
        .iter()
        .zip(&t.data)
        .map(|(a, b)| (0..3).map(|c| ((a[c] - b[c]) as f64).powi(2)).sum::<f64>())
        .sum::<f64>()
        / (3 * img.data.len()) as f64;
    -10.0 * mse.log10()
}

#[test]
fn vectorizes_a_drawing_in_every_mode() {
    let dir = scratch("vectorize-modes");
    let scene = Scene::load(
        root().join("svg-samples/06-evenodd-star.svg"),
        Sizing::Width(64),
    )
    .unwrap();
    let mut target = render(&scene, &RenderOptions::default());
    target.over_background([1.0; 4]);
    let png = dir.join("star.png");
    target.save_png(&png).unwrap();
    let target = Image::load(&png).unwrap();
    let mut results = Vec::new();
    for mode in ["adaptive", "fixed", "painterly", "trace"] {
        let out = dir.join(format!("{mode}.svg"));
        let mut args = vec![
            "vectorize",
            s(&png),
            "-o",
            s(&out),
            "--paths",
            "12",
            "--iters",
            "300",
            "--json",
        ];
        if mode == "trace" {
            args.extend(["--init", "trace"]);
        } else {
            args.extend(["--mode", mode]);
        }
        let sum = json_summary(&diffsvg(&args));
        let paths = sum["paths"].as_u64().unwrap();
        assert!(paths <= 12, "{mode}: {paths} paths");
        let psnr = sum["psnr"].as_f64().unwrap();
        // The written file says the same as the summary (up to 8-bit quantization).
        let measured = psnr_of(&out, &target);
        assert!(
            (measured - psnr).abs() < 1.0,
            "{mode}: summary {psnr:.2}, file {measured:.2}"
        );
        results.push((mode, psnr));
    }
    // Same inputs and seed, same bits.
    let again = dir.join("again.svg");
    json_summary(&diffsvg(&[
        "vectorize",
        s(&png),
        "-o",
        s(&again),
        "--paths",
        "12",
        "--iters",
        "300",
        "--json",
    ]));
    assert_eq!(
        std::fs::read(&again).unwrap(),
        std::fs::read(dir.join("adaptive.svg")).unwrap()
    );
    let get = |m: &str| results.iter().find(|r| r.0 == m).unwrap().1;
    assert!(get("adaptive") > 25.0, "{results:?}");
    assert!(get("adaptive") > get("fixed"), "{results:?}");
    assert!(get("adaptive") > get("painterly"), "{results:?}");
    assert!(get("trace") > 20.0, "{results:?}");
}

/// The adaptive mode stops adding paths once the PSNR goal is met.
#[test]
fn target_psnr_uses_only_the_paths_it_needs() {
    let dir = scratch("vectorize-goal");
    let mut s1 = Scene::new(48, 48);
    let mut p = diffsvg::Path::new("sq");
    p.move_to([8.0, 8.0]);
    p.line_to([30.0, 10.0]);
    p.line_to([28.0, 36.0]);
    p.close();
    p.fill = Some(diffsvg::scene::Fill {
        paint: diffsvg::scene::Paint::Solid([0.8, 0.2, 0.1]),
        opacity: 1.0,
        rule: diffsvg::scene::FillRule::NonZero,
    });
    s1.nodes.push(diffsvg::Node::Path(p));
    let mut t = render(&s1, &RenderOptions::default());
    t.over_background([1.0; 4]);
    let png = dir.join("tri.png");
    t.save_png(&png).unwrap();
    let out = dir.join("tri.svg");
    let sum = json_summary(&diffsvg(&[
        "vectorize",
        s(&png),
        "-o",
        s(&out),
        "--target-psnr",
        "30",
        "--max-paths",
        "64",
        "--iters",
        "400",
        "--json",
    ]));
    assert!(sum["psnr"].as_f64().unwrap() >= 30.0, "{sum}");
    assert!(
        sum["paths"].as_u64().unwrap() <= 8,
        "one triangle needs few paths: {sum}"
    );
}

/// On a real photo, adaptive vectorization beats the painterly baseline at the same path
/// count and step count (small size to stay fast).
#[test]
fn adaptive_beats_painterly_on_a_photo() {
    let Some(data) = shared_data("adaptive_beats_painterly_on_a_photo") else {
        return;
    };
    let dir = scratch("vectorize-photo");
    let photo = data.join("images/astronaut.png");
    let mut mse = Vec::new();
    for mode in ["adaptive", "painterly"] {
        let out = dir.join(format!("{mode}.svg"));
        let sum = json_summary(&diffsvg(&[
            "vectorize",
            s(&photo),
            "--width",
            "64",
            "-o",
            s(&out),
            "--mode",
            mode,
            "--paths",
            "32",
            "--iters",
            "300",
            "--json",
        ]));
        mse.push(sum["mse"].as_f64().unwrap());
    }
    assert!(mse[0] < mse[1], "adaptive {} painterly {}", mse[0], mse[1]);
}

/// `--exact-overlaps` reaches vectorize's renders: with no steps the same random paths
/// come out either way, and each run's error is that of its own rendering of them, as
/// `diffsvg loss` measures it with and without the option (over RGBA, so ⁴⁄₃ of the
/// summary's RGB mean where the target and the render over it are opaque).
#[test]
fn vectorize_exact_overlaps_scores_the_exact_coverage() {
    let dir = scratch("vectorize-exact");
    let target = dir.join("star.png");
    let star = root().join("svg-samples/06-evenodd-star.svg");
    let args = [
        s(&star),
        "-o",
        s(&target),
        "--width",
        "48",
        "--background",
        "white",
    ];
    assert!(diffsvg(&[&["render"][..], &args].concat()).status.success());
    let mut mse = Vec::new();
    for flag in [None, Some("--exact-overlaps")] {
        let out = dir.join(format!("out{}.svg", flag.is_some()));
        let mut args = vec![
            "vectorize",
            s(&target),
            "-o",
            s(&out),
            "--mode",
            "fixed",
            "--paths",
            "8",
            "--seed",
            "2",
            "--iters",
            "0",
            "--background",
            "white",
            "--json",
        ];
        args.extend(flag);
        let summary = json_summary(&diffsvg(&args))["mse"].as_f64().unwrap();
        let mut args = vec!["loss", s(&out), s(&target), "--background", "white"];
        args.extend(flag);
        let loss = diffsvg(&args);
        assert!(
            loss.status.success(),
            "{}",
            String::from_utf8_lossy(&loss.stderr)
        );
        let rgba: f64 = String::from_utf8_lossy(&loss.stdout)
            .trim()
            .parse()
            .unwrap();
        assert!(
            (summary - rgba * 4.0 / 3.0).abs() < 1e-6 * summary,
            "{flag:?}: summary {summary}, loss {rgba}"
        );
        mse.push((summary, std::fs::read(&out).unwrap()));
    }
    assert_eq!(mse[0].1, mse[1].1, "the same paths either way");
    // Some of the random paths cross themselves: the two coverages differ there.
    assert!(
        (mse[0].0 - mse[1].0).abs() > 1e-5 * mse[0].0,
        "clamped {}, exact {}",
        mse[0].0,
        mse[1].0
    );
}

#[test]
fn vectorize_bad_inputs_fail_cleanly() {
    let dir = scratch("vectorize-bad");
    let out = dir.join("out.svg");
    let o = diffsvg(&["vectorize", s(&dir.join("nope.png")), "-o", s(&out)]);
    assert_fails(&o, "nope.png", "no such file", &out);
    let png = dir.join("t.png");
    Image::filled(8, 8, [1.0, 0.0, 0.0, 1.0])
        .save_png(&png)
        .unwrap();
    let o = diffsvg(&["vectorize", s(&png), "-o", s(&out), "--mode", "cubist"]);
    assert_fails(
        &o,
        "cubist",
        "possible values: adaptive, fixed, painterly",
        &out,
    );
    let o = diffsvg(&["vectorize", s(&png), "-o", s(&out), "--segments", "1"]);
    assert_fails(&o, "--segments", "between", &out);
    let o = diffsvg(&["vectorize", s(&png), "-o", s(&out), "--paths", "0"]);
    assert_fails(&o, "--paths 0", "must be between 1 and 100000", &out);
    let o = diffsvg(&["vectorize", s(&png), "-o", s(&out), "--lr-color", "inf"]);
    assert_fails(&o, "colors", "learning rate", &out);
    let o = diffsvg(&["vectorize", s(&png), "-o", s(&out), "--init", "magic"]);
    assert_fails(&o, "magic", "possible values: trace", &out);
}

/// Flags that another flag would make meaningless are refused, never silently ignored.
#[test]
fn conflicting_and_ignored_flags_are_refused() {
    let dir = scratch("vectorize-conflicts");
    let out = dir.join("out.svg");
    let png = dir.join("t.png");
    Image::filled(8, 8, [1.0, 0.0, 0.0, 1.0])
        .save_png(&png)
        .unwrap();
    let v = |extra: &[&str]| {
        let mut args = vec!["vectorize", s(&png), "-o", s(&out)];
        args.extend_from_slice(extra);
        diffsvg(&args)
    };
    let o = v(&["--init", "trace", "--mode", "fixed"]);
    assert_fails(
        &o,
        "--init trace and --mode fixed",
        "cannot be combined",
        &out,
    );
    let o = v(&["--mode", "fixed", "--segments", "6"]);
    assert_fails(&o, "--segments", "adaptive only", &out);
    let o = v(&["--init", "trace", "--segments", "6"]);
    assert_fails(&o, "--segments", "adaptive only", &out);
    let o = v(&["--seed", "7"]);
    assert_fails(&o, "--seed", "fixed and painterly only", &out);
    let o = v(&["--target-psnr", "30", "--paths", "8"]);
    assert_fails(&o, "--max-paths", "cannot be combined", &out);
    let o = v(&["--target-psnr", "30", "--until-psnr", "20"]);
    assert_fails(&o, "--until-psnr", "cannot be combined", &out);
    let o = v(&["--max-paths", "8"]);
    assert_fails(&o, "--target-psnr", "required", &out);
    // `fit` is deterministic: it has no seed to take.
    let o = diffsvg(&["fit", s(&png), s(&png), "-o", s(&out), "--seed", "3"]);
    assert_fails(&o, "--seed", "unexpected argument", &out);
}

//! Command-line regressions of issue 13: resvg's panics, single-color vectorization,
//! `--iters 0`, outputs checked before the run, batch names and bracketed paths.

use std::path::Path;
use std::process::Output;

use diffsvg::Image;

use super::common::{assert_fails, diffsvg, root, s, scratch, write};

/// The line that made tiny-skia panic inside `render --compare` and `parity`.
const LINE_1E9: &str = r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100"><line x2="1e9" y2="-1e9" stroke="black" stroke-width="1e6"/></svg>"#;

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The summary object (`"done": true`) of a `--json` run.
fn summary(o: &Output) -> serde_json::Value {
    stdout(o)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .find(|v| v["done"] == true)
        .unwrap_or_else(|| panic!("no summary in {}", stdout(o)))
}

/// A single-color PNG.
fn solid_png(dir: &Path, name: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    Image::filled(48, 32, [0.8, 0.1, 0.25, 1.0])
        .save_png(&p)
        .unwrap();
    p
}

#[test]
fn render_compare_line_1e9_fails_cleanly() {
    let dir = scratch("regress_render_compare_1e9");
    // 1e9 (1.28e9 device px at this width) is inside diffsvg's range but beyond resvg's;
    // 1e30 scales past diffsvg's own range and is refused at load.
    for (coord, why) in [("1e9", "resvg cannot render"), ("1e30", "out of range")] {
        let svg = write(&dir, "line.svg", &LINE_1E9.replace("1e9", coord));
        let out = dir.join("line.png");
        let o = diffsvg(&[
            "render",
            s(&svg),
            "-o",
            s(&out),
            "--width",
            "128",
            "--compare",
        ]);
        assert_fails(&o, "line.svg", why, &out);
        assert!(!dir.join("line.diff.png").exists());
    }
    // Without --compare diffsvg renders the line to 1e9.
    let svg = write(&dir, "line.svg", LINE_1E9);
    let out = dir.join("plain.png");
    let o = diffsvg(&["render", s(&svg), "-o", s(&out), "--width", "128"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(out.is_file());
}

#[test]
fn parity_dir_reports_resvg_failure_and_goes_on() {
    let dir = scratch("regress_parity_dir");
    write(&dir, "a-line.svg", LINE_1E9);
    write(&dir, "b-line.svg", &LINE_1E9.replace("1e9", "1e20"));
    std::fs::copy(
        root().join("svg-samples/01-curves.svg"),
        dir.join("c-curves.svg"),
    )
    .unwrap();
    let o = diffsvg(&["parity", s(&dir), "--width", "128"]);
    let (out, err) = (stdout(&o), stderr(&o));
    assert_eq!(o.status.code(), Some(0), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    for f in ["a-line.svg", "b-line.svg"] {
        assert!(
            out.lines().any(|l| l.starts_with("FAIL")
                && l.contains(f)
                && l.contains("resvg cannot render")),
            "{f} not reported as failed: {out}"
        );
    }
    // Three files: one passes, none nearer exact, none refused, two failed.
    assert!(out.contains("| **all** | 3 | 1 | 0 | 0 | 2 |"), "{out}");
}

#[test]
fn vectorize_single_color_png_and_svg_get_a_path() {
    let dir = scratch("regress_vectorize_single_color");
    let png = solid_png(&dir, "solid.png");
    let svg = write(
        &dir,
        "solid.svg",
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="30"><rect width="40" height="30" fill="#3a7"/></svg>"##,
    );
    for target in [&png, &svg] {
        let out = dir.join("out.svg");
        let o = diffsvg(&[
            "vectorize",
            s(target),
            "-o",
            s(&out),
            "--iters",
            "30",
            "--json",
        ]);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let sum = summary(&o);
        assert_eq!(sum["paths"], 1, "{sum}");
        // An exact match reports a null (infinite) PSNR.
        assert!(
            sum["psnr"].is_null() || sum["psnr"].as_f64().unwrap() > 40.0,
            "{sum}"
        );
        let text = std::fs::read_to_string(&out).unwrap();
        assert_eq!(text.matches("<path").count(), 1, "{text}");
    }
}

#[test]
fn vectorize_iters_0_takes_no_steps() {
    let dir = scratch("regress_vectorize_iters_0");
    let out = dir.join("out.svg");
    let o = diffsvg(&[
        "vectorize",
        s(&root().join("svg-samples/01-curves.svg")),
        "-o",
        s(&out),
        "--iters",
        "0",
        "--paths",
        "16",
        "--json",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let sum = summary(&o);
    assert_eq!(sum["steps"], 0, "{sum}");
    assert!(sum["paths"].as_u64().unwrap() > 0, "{sum}");
    assert!(out.is_file());
}

/// `fit --snapshots /proc/x` stopped at step 0, wrote the unoptimized SVG and exited 2.
#[test]
fn fit_snapshots_in_proc_fails_before_the_run() {
    let dir = scratch("regress_fit_snapshots_proc");
    let png = solid_png(&dir, "target.png");
    let init = root().join("svg-samples/01-curves.svg");
    let out = dir.join("out.svg");
    let o = diffsvg(&[
        "fit",
        s(&init),
        s(&png),
        "-o",
        s(&out),
        "--iters",
        "3",
        "--snapshots",
        "/proc/x",
    ]);
    assert_fails(&o, "/proc/x", "--snapshots", &out);
    assert!(
        stdout(&o).is_empty(),
        "the run must not start: {}",
        stdout(&o)
    );
    // Same for vectorize, and for a log that cannot be written.
    let o = diffsvg(&[
        "vectorize",
        s(&png),
        "-o",
        s(&out),
        "--iters",
        "3",
        "--snapshots",
        "/proc/x",
    ]);
    assert_fails(&o, "/proc/x", "--snapshots", &out);
    let o = diffsvg(&[
        "fit",
        s(&init),
        s(&png),
        "-o",
        s(&out),
        "--iters",
        "3",
        "--log",
        "/proc/x/log.csv",
    ]);
    assert_fails(&o, "/proc/x", "--log", &out);
}

/// `fit --compare` where the comparison cannot be written exited 2 after writing the SVG.
#[test]
fn fit_compare_unwritable_fails_before_the_run() {
    let dir = scratch("regress_fit_compare_unwritable");
    let png = solid_png(&dir, "target.png");
    let init = root().join("svg-samples/01-curves.svg");
    let out = dir.join("out.svg");
    // A folder where the comparison image would go.
    std::fs::create_dir(dir.join("out.compare.png")).unwrap();
    for cmd in [vec!["fit", s(&init), s(&png)], vec!["vectorize", s(&png)]] {
        let mut args = cmd.clone();
        args.extend(["-o", s(&out), "--iters", "3", "--compare"]);
        let o = diffsvg(&args);
        assert_fails(&o, "out.compare.png", "folder", &out);
        assert!(stdout(&o).is_empty(), "{}", stdout(&o));
    }
}

/// A batch job file naming `dir` for its inputs and output.
fn run_batch(dir: &Path, input: &str) -> Output {
    let jobs = write(
        dir,
        "jobs.toml",
        &format!(
            "output = \"out\"\n[[job]]\nkind = \"render\"\nname = \"r\"\ninput = '{input}'\nwidth = 16\n"
        ),
    );
    diffsvg(&["batch", s(&jobs), "--quiet"])
}

/// Non-ASCII stems collapsed to underscores, so `日本.svg` and `中国.svg` collided.
#[test]
fn batch_unicode_stems_do_not_collide() {
    let dir = scratch("regress_batch_unicode");
    let curves = root().join("svg-samples/01-curves.svg");
    for name in ["日本.svg", "中国.svg"] {
        std::fs::copy(&curves, dir.join(name)).unwrap();
    }
    let o = run_batch(&dir, "*.svg");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    for name in ["r-日本", "r-中国"] {
        let png = dir
            .join("out")
            .join(name)
            .join(format!("{}.png", &name[2..]));
        assert!(png.is_file(), "{} missing", png.display());
    }
}

/// A plain path with brackets (`a [1].svg`) was taken as a glob and failed.
#[test]
fn batch_bracketed_path_is_not_a_glob() {
    let dir = scratch("regress_batch_brackets");
    std::fs::copy(
        root().join("svg-samples/01-curves.svg"),
        dir.join("a [1].svg"),
    )
    .unwrap();
    let o = run_batch(&dir, "a [1].svg");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let csv = std::fs::read_to_string(dir.join("out/summary.csv")).unwrap();
    assert!(csv.contains(",ok,"), "{csv}");
    assert!(dir.join("out/r/a__1_.png").is_file());
    // As a pattern it still works, with the bracket escaped.
    std::fs::remove_dir_all(dir.join("out")).unwrap();
    let o = run_batch(&dir, "a [[]*.svg");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(dir.join("out/r-a__1_/a__1_.png").is_file());
}

//! The command line: outputs, and clean failures on bad input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use super::common::{root, scratch};

fn diffsvg(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_diffsvg"))
        .args(args)
        .output()
        .expect("runs diffsvg")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Asserts a clean failure: exit code 2, one line on stderr naming `needle` and `what`,
/// and no output file.
fn assert_fails(out: &Output, needle: &str, what: &str, output: &Path) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {err}");
    assert_eq!(err.trim().lines().count(), 1, "one line expected: {err}");
    assert!(err.contains(needle), "{err:?} should name {needle}");
    assert!(
        err.to_lowercase().contains(what),
        "{err:?} should say {what}"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(!output.exists(), "no output may be written on failure");
    // Nor a stray temporary file.
    let dir = output.parent().unwrap();
    let stray: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(stray.is_empty(), "temporary files left behind: {stray:?}");
}

const SQUARE: &str = r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="20">
  <rect id="r" x="10" y="5" width="20" height="10" fill="blue"/></svg>"#;

#[test]
fn render_writes_a_png_of_the_requested_size() {
    let dir = scratch("cli_render");
    let svg = write(&dir, "sq.svg", SQUARE);
    let out = dir.join("sq.png");
    let r = diffsvg(&["render", s(&svg), "-o", s(&out), "--width", "80"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let img = diffsvg::Image::load(&out).unwrap();
    assert_eq!((img.width, img.height), (80, 40));
    assert_eq!(img.get(40, 20), [0.0, 0.0, 1.0, 1.0]);
    assert_eq!(img.get(2, 2)[3], 0.0, "transparent without --background");

    let r = diffsvg(&[
        "render",
        s(&svg),
        "-o",
        s(&out),
        "--scale",
        "0.5",
        "--background",
        "white",
    ]);
    assert!(r.status.success());
    let img = diffsvg::Image::load(&out).unwrap();
    assert_eq!((img.width, img.height), (20, 10));
    assert_eq!(img.get(0, 0), [1.0; 4]);
}

#[test]
fn compare_reports_metrics_and_writes_a_difference_image() {
    let dir = scratch("cli_compare");
    let out = dir.join("curves.png");
    let sample = root().join("svg-samples/01-curves.svg");
    let r = diffsvg(&["render", s(&sample), "-o", s(&out), "--compare"]);
    let text = String::from_utf8_lossy(&r.stdout);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(text.contains("MAE") && text.contains("PSNR"), "{text}");
    assert!(dir.join("curves.diff.png").exists());
    let mae: f64 = text
        .split("MAE ")
        .nth(1)
        .unwrap()
        .split('/')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(mae <= 0.5, "{text}");
}

#[test]
fn bad_inputs_fail_cleanly() {
    let dir = scratch("cli_bad");
    let out = dir.join("out.png");
    let o = s(&out).to_string();

    let p = write(
        &dir,
        "malformed.svg",
        "<svg xmlns='http://www.w3.org/2000/svg'><rect",
    );
    assert_fails(
        &diffsvg(&["render", s(&p), "-o", &o]),
        "malformed.svg",
        "malformed",
        &out,
    );

    let p = dir.join("missing.svg");
    assert_fails(
        &diffsvg(&["render", s(&p), "-o", &o]),
        "missing.svg",
        "no such file",
        &out,
    );

    let p = write(
        &dir,
        "text.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"><text id="t">hi</text></svg>"#,
    );
    assert_fails(
        &diffsvg(&["render", s(&p), "-o", &o]),
        "text.svg",
        "unsupported: <text>",
        &out,
    );

    let p = write(
        &dir,
        "clip.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10">
        <clipPath id="c"><rect width="5" height="5"/></clipPath>
        <rect id="r" width="10" height="10" clip-path="url(#c)"/></svg>"#,
    );
    assert_fails(
        &diffsvg(&["render", s(&p), "-o", &o]),
        "clip.svg",
        "clip-path",
        &out,
    );

    let p = write(&dir, "sq.svg", SQUARE);
    assert_fails(
        &diffsvg(&["render", s(&p), "-o", &o, "--width", "0"]),
        "width",
        "at least 1",
        &out,
    );
    assert_fails(
        &diffsvg(&["render", s(&p), "-o", &o, "--width", "100000"]),
        "sq.svg",
        "exceeds the limit",
        &out,
    );
    assert_fails(
        &diffsvg(&["render", s(&p), "-o", &o, "--scale", "NaN"]),
        "scale",
        "positive",
        &out,
    );
    assert_fails(
        &diffsvg(&["render", s(&p), "-o", &o, "--background", "bluish"]),
        "bluish",
        "not a color",
        &out,
    );

    let p = write(
        &dir,
        "huge.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10">
        <path id="p" d="M 0 0 L 1e39 5 L 0 9 Z"/></svg>"#,
    );
    assert_fails(
        &diffsvg(&["render", s(&p), "-o", &o]),
        "huge.svg",
        "invalid value",
        &out,
    );

    let p = write(&dir, "sq.svg", SQUARE);
    let jpg = dir.join("out.jpg");
    assert_fails(
        &diffsvg(&["render", s(&p), "-o", s(&jpg)]),
        "out.jpg",
        ".png",
        &jpg,
    );
}

#[test]
fn a_failed_render_keeps_the_previous_output() {
    let dir = scratch("cli_keep");
    let out = dir.join("keep.png");
    std::fs::write(&out, b"previous").unwrap();
    let p = write(&dir, "bad.svg", "not svg at all");
    let r = diffsvg(&["render", s(&p), "-o", s(&out)]);
    assert_eq!(r.status.code(), Some(2));
    assert_eq!(std::fs::read(&out).unwrap(), b"previous");
}

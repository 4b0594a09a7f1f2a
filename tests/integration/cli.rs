//! The command line: outputs, and clean failures on bad input.

use super::common::{assert_fails, diffsvg, root, s, scratch, write};

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
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"><text id="t" font-family="NoSuchFamily">hi</text></svg>"#,
    );
    assert_fails(
        &diffsvg(&["render", s(&p), "-o", &o]),
        "text.svg",
        "font-family \"nosuchfamily\"",
        &out,
    );

    // Every filter primitive renders; a convolution kernel past the limit is refused.
    let kernel = vec!["1"; 65 * 65].join(" ");
    let p = write(
        &dir,
        "filter.svg",
        &format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10">
        <filter id="f"><feConvolveMatrix order="65" kernelMatrix="{kernel}"/></filter>
        <rect id="r" width="10" height="10" filter="url(#f)"/></svg>"#
        ),
    );
    assert_fails(
        &diffsvg(&["render", s(&p), "-o", &o]),
        "filter.svg",
        "feconvolvematrix",
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

#[test]
fn loss_and_grad_commands() {
    let dir = scratch("cli_grad");
    let a = write(
        &dir,
        "a.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="24" height="20">
        <path id="tri" d="M 3 3 L 20 5 C 20 12 14 17 5 17 Z" fill="rgb(200,50,30)" fill-opacity="0.8"/></svg>"#,
    );
    let b = write(
        &dir,
        "b.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="24" height="20">
        <path id="tri" d="M 4 3 L 21 6 C 20 13 14 17 5 16 Z" fill="rgb(180,70,30)" fill-opacity="0.8"/></svg>"#,
    );
    let target = dir.join("target.png");
    assert!(
        diffsvg(&["render", s(&b), "-o", s(&target), "--background", "white"])
            .status
            .success()
    );

    let r = diffsvg(&["loss", s(&a), s(&target), "--background", "white"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let loss: f64 = String::from_utf8_lossy(&r.stdout).trim().parse().unwrap();
    assert!(loss > 0.0 && loss < 1.0);

    let r = diffsvg(&[
        "grad",
        s(&a),
        s(&target),
        "--background",
        "white",
        "--json",
        "--check",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    assert_eq!(
        v["loss"].as_f64().unwrap(),
        loss,
        "grad and loss agree to the bit"
    );
    let shape = &v["shapes"][0];
    assert_eq!(shape["id"], "tri");
    // M, L, C (3 points): five points as written in the file.
    assert_eq!(shape["points"].as_array().unwrap().len(), 5);
    assert_eq!(shape["fill"].as_array().unwrap().len(), 4);
    let checks = String::from_utf8_lossy(&r.stderr);
    for line in checks.lines().filter(|l| l.starts_with("check")) {
        let worst: f64 = line
            .split("worst relative error ")
            .nth(1)
            .unwrap()
            .split(' ')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert!(worst <= 1e-2, "{line}");
    }
    assert!(checks.contains("check    points"), "{checks}");

    // A target of another size is refused unless --resize is given.
    let small = dir.join("small.png");
    assert!(
        diffsvg(&["render", s(&b), "-o", s(&small), "--width", "12"])
            .status
            .success()
    );
    let r = diffsvg(&["loss", s(&a), s(&small)]);
    assert_eq!(r.status.code(), Some(2));
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(
        err.contains("small.png") && err.contains("--resize"),
        "{err}"
    );
    assert!(
        diffsvg(&["loss", s(&a), s(&small), "--resize"])
            .status
            .success()
    );

    // Unreadable target, bad loss name.
    let bogus = write(&dir, "bogus.png", "not an image");
    let r = diffsvg(&["loss", s(&a), s(&bogus)]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("bogus.png"));
    let r = diffsvg(&["loss", s(&a), s(&target), "--loss", "huber"]);
    assert_eq!(r.status.code(), Some(2));
}

/// `diffsvg bench FILE` times that file against resvg and nothing else; `--sizes` adds the
/// random scenes.
#[test]
fn bench_times_the_given_files_only() {
    let glyph = root().join("svg-samples/glyphs/0.svg");
    let r = diffsvg(&["bench", s(&glyph), "--runs", "1", "--threads", "1"]);
    assert!(r.status.success());
    let out = String::from_utf8_lossy(&r.stdout);
    assert!(out.contains("| 0.svg |"), "{out}");
    assert!(!out.contains("random paths"), "{out}");
    // The table's header comes first, so the columns are named on the terminal too.
    assert!(
        out.starts_with("| case | resvg (ms) | diffsvg 1 thr (ms) | ratio |\n|---|"),
        "{out}"
    );
    let r = diffsvg(&[
        "bench",
        s(&glyph),
        "--runs",
        "1",
        "--threads",
        "1",
        "--sizes",
        "16",
    ]);
    assert!(r.status.success());
    assert!(String::from_utf8_lossy(&r.stdout).contains("500 random paths, 16²"));
}

/// `diffsvg bench … | head`: a reader that closes the pipe early ends the run quietly with
/// the status a shell gives a process ended by SIGPIPE, not a panic message.
#[test]
fn a_closed_stdout_ends_the_run_quietly() {
    use std::process::{Command, Stdio};
    let glyph = root().join("svg-samples/glyphs/0.svg");
    let mut child = Command::new(env!("CARGO_BIN_EXE_diffsvg"))
        .args(["bench", s(&glyph), "--runs", "1", "--sizes", "8"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("runs diffsvg");
    // Close the reading end before anything is printed.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.trim().is_empty(), "nothing on stderr: {err}");
    assert_eq!(out.status.code(), Some(141), "{err}");
}

//! Issue 13, items 1 and 3: dashing, flattening and group layers stay bounded.
//!
//! Each case runs the binary under a 1 GiB address-space limit (`ulimit -v`) with two
//! rayon threads, so that an unbounded allocation fails the test instead of the machine.

use std::path::{Path, PathBuf};
use std::process::Output;

use diffsvg::Image;

use crate::common::{assert_fails, scratch, write};

/// Address space allowed to one render, KiB (the issue's 1 GB ceiling).
const LIMIT_KIB: u64 = 1 << 20;

/// `diffsvg render IN -o OUT --width W` under [`LIMIT_KIB`].
fn render_bounded(input: &Path, output: &Path, width: u32) -> Output {
    std::process::Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -v {LIMIT_KIB}; exec \"$0\" render \"$1\" -o \"$2\" --width {width}"
        ))
        .arg(env!("CARGO_BIN_EXE_diffsvg"))
        .arg(input)
        .arg(output)
        .env("RAYON_NUM_THREADS", "2")
        .output()
        .expect("runs sh")
}

fn assert_ok(out: &Output) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "stderr: {err}");
    assert!(!err.contains("panicked"), "{err}");
}

fn svg(body: &str) -> String {
    format!("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"200\" height=\"200\">{body}</svg>")
}

/// Alpha summed along column `x`, and the number of on/off switches down it.
fn column(img: &Image, x: u32) -> (f32, usize) {
    let a: Vec<f32> = (0..img.height).map(|y| img.get(x, y)[3]).collect();
    let switches = a
        .windows(2)
        .filter(|w| (w[0] > 0.5) != (w[1] > 0.5))
        .count();
    (a.iter().sum(), switches)
}

fn run_case(dir: &Path, name: &str, body: &str) -> (Output, PathBuf) {
    let input = write(dir, &format!("{name}.svg"), &svg(body));
    let output = dir.join(format!("{name}.png"));
    (render_bounded(&input, &output, 128), output)
}

#[test]
fn dasharray_1e_5_is_bounded() {
    let dir = scratch("regress_raster_dash_1e_5");
    // In the attribute and in CSS; 1e-4 took 1.5 GB, 1e-5 aborted on 2 GiB.
    for (name, body) in [
        (
            "attr5",
            r#"<rect width="198" height="198" fill="none" stroke="black" stroke-dasharray="1e-5"/>"#,
        ),
        (
            "attr4",
            r#"<rect width="198" height="198" fill="none" stroke="black" stroke-dasharray="1e-4"/>"#,
        ),
        (
            "css",
            r#"<rect width="198" height="198" fill="none" style="stroke:black;stroke-dasharray:1e-5"/>"#,
        ),
    ] {
        let (out, png) = run_case(&dir, name, body);
        assert_ok(&out);
        // Past the dash limit the stroke is drawn solid: the left edge (a 0.64 px line
        // centered on x = 0, so 0.32 of column 0) is unbroken and at full strength, where
        // dashes at half duty would give half that.
        let img = Image::load(&png).unwrap();
        for y in 1..120 {
            let a = img.get(0, y)[3];
            assert!((a - 0.32).abs() < 0.02, "{name}: alpha {a} at row {y}");
        }
    }
}

#[test]
fn dashed_line_to_1e20_is_bounded() {
    let dir = scratch("regress_raster_dash_line");
    let (out, png) = run_case(
        &dir,
        "line",
        r#"<line x1="50" y1="0" x2="50" y2="1e20" stroke="black" stroke-width="4" stroke-dasharray="20 20"/>"#,
    );
    assert_ok(&out);
    // Only the visible part is cut, and it is still dashed: 200 px of a 40 px period,
    // scaled to 128 px, is five dashes (ten switches, give or take the ends).
    let img = Image::load(&png).unwrap();
    let (_, switches) = column(&img, 32);
    assert!((8..=10).contains(&switches), "{switches} switches");
}

#[test]
fn dashed_circle_of_radius_1e30_is_bounded() {
    let dir = scratch("regress_raster_dash_circle");
    let (out, png) = run_case(
        &dir,
        "circle",
        r#"<circle cx="100" cy="100" r="1e30" fill="none" stroke="black" stroke-dasharray="5 5"/>"#,
    );
    assert_ok(&out);
    // The circle passes nowhere near the canvas.
    let img = Image::load(&png).unwrap();
    assert!(img.data.iter().all(|p| p[3] == 0.0));
}

/// One path of `n` stroked cubics with control points spread over the canvas.
fn cubics(n: usize) -> String {
    let mut d = String::from("M0 0");
    let mut x: u64 = 12345;
    let mut next = || {
        // A small LCG: the same file on every run.
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (x >> 33) % 200
    };
    for _ in 0..n {
        let v: Vec<u64> = (0..6).map(|_| next()).collect();
        d.push_str(&format!(
            " C{} {} {} {} {} {}",
            v[0], v[1], v[2], v[3], v[4], v[5]
        ));
    }
    svg(&format!(r#"<path fill="none" stroke="black" d="{d}"/>"#))
}

#[test]
fn stroked_cubics_20k_stay_bounded() {
    let dir = scratch("regress_raster_cubics_20k");
    let input = write(&dir, "c20k.svg", &cubics(20_000));
    let output = dir.join("c20k.png");
    assert_ok(&render_bounded(&input, &output, 128));
    assert!(output.exists());
}

#[test]
fn stroked_cubics_200k_are_refused_before_flattening() {
    let dir = scratch("regress_raster_cubics_200k");
    let input = write(&dir, "c200k.svg", &cubics(200_000));
    let output = dir.join("c200k.png");
    let out = render_bounded(&input, &output, 128);
    assert_fails(&out, "c200k.svg", "line segments", &output);
}

fn nested(levels: usize) -> String {
    let mut body = String::new();
    body.push_str(&"<g opacity=\"0.99\">".repeat(levels));
    body.push_str(r#"<rect x="10" y="10" width="50" height="50" fill="red"/>"#);
    body.push_str(&"</g>".repeat(levels));
    svg(&body)
}

#[test]
fn nested_group_opacity_100_levels_is_bounded() {
    let dir = scratch("regress_raster_nested_100");
    let input = write(&dir, "n100.svg", &nested(100));
    let output = dir.join("n100.png");
    assert_ok(&render_bounded(&input, &output, 2048));
    let img = Image::load(&output).unwrap();
    // The square is 0.99^100 opaque; outside it nothing is drawn.
    let want = 0.99f32.powi(100);
    let inside = img.get(300, 300)[3];
    assert!((inside - want).abs() < 2.0 / 255.0, "{inside} vs {want}");
    assert_eq!(img.get(1000, 1000)[3], 0.0);
}

#[test]
fn nested_group_opacity_1000_levels_is_refused() {
    let dir = scratch("regress_raster_nested_1000");
    let input = write(&dir, "n1000.svg", &nested(1000));
    let output = dir.join("n1000.png");
    let out = render_bounded(&input, &output, 4096);
    assert_fails(&out, "n1000.svg", "nested", &output);
}

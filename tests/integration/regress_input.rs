//! Issue 13, input and output validation: each case the issue describes, run through the
//! binary. Cases that used to allocate gigabytes run under `ulimit -v` (1 GiB of address
//! space), so a regression aborts instead of passing slowly.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use diffsvg::{Image, Scene, Sizing};

use crate::common::{assert_fails, diffsvg, s, scratch, write};

/// Address space allowed to the binary in the memory-bound cases, in KiB.
const ULIMIT_KIB: u64 = 1 << 20;

/// Runs `diffsvg args` with its address space limited to [`ULIMIT_KIB`].
fn diffsvg_bounded(args: &[&str]) -> Output {
    let mut script = format!("ulimit -v {ULIMIT_KIB}; exec \"$0\"");
    for i in 1..=args.len() {
        script.push_str(&format!(" \"${{{i}}}\""));
    }
    Command::new("sh")
        .arg("-c")
        .arg(script)
        .arg(env!("CARGO_BIN_EXE_diffsvg"))
        .args(args)
        .output()
        .expect("runs sh")
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// A valid grayscale PNG of `w × h` white pixels, compressed row by row (an 11000² one is
/// about 120 KB, as in the issue).
fn huge_png(path: &Path, w: u32, h: u32) {
    let chunk = |out: &mut Vec<u8>, kind: &[u8], data: &[u8]| {
        out.extend_from_slice(&(data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend_from_slice(data);
        out.extend_from_slice(&body);
        out.extend_from_slice(&crc32(&body).to_be_bytes());
    };
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&w.to_be_bytes());
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]); // 8-bit grayscale
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    let mut row = vec![255u8; w as usize + 1];
    row[0] = 0; // filter: none
    for _ in 0..h {
        z.write_all(&row).unwrap();
    }
    let idat = z.finish().unwrap();
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    chunk(&mut png, b"IHDR", &ihdr);
    chunk(&mut png, b"IDAT", &idat);
    chunk(&mut png, b"IEND", &[]);
    std::fs::write(path, png).unwrap();
}

const SQUARE: &str = r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">
  <rect id="r" x="10" y="10" width="50" height="50" fill="red"/></svg>"#;

/// The square moved, as a target.
const MOVED: &str = r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">
  <rect id="r" x="20" y="15" width="50" height="50" fill="red"/></svg>"#;

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn assert_ok(o: &Output) {
    assert_eq!(o.status.code(), Some(0), "stderr: {}", stderr(o));
}

fn no_temp_files(dir: &Path) {
    let stray: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(stray.is_empty(), "temporary files left: {stray:?}");
}

// Case 4: images are decoded before their size is checked.

#[test]
fn png_11000_squared_target_fit_is_refused_from_its_header() {
    let dir = scratch("regress-input-png-11000");
    let svg = write(&dir, "a.svg", SQUARE);
    let png = dir.join("big.png");
    huge_png(&png, 11000, 11000);
    assert!(std::fs::metadata(&png).unwrap().len() < 1 << 20);
    let out = dir.join("out.svg");
    let o = diffsvg_bounded(&["fit", s(&svg), s(&png), "-o", s(&out)]);
    assert_fails(&o, "big.png", "11000x11000", &out);
    assert!(stderr(&o).contains("limit"), "{}", stderr(&o));
}

#[test]
fn png_20000_squared_target_loss_resize_is_refused_from_its_header() {
    let dir = scratch("regress-input-png-20000");
    let svg = write(&dir, "a.svg", SQUARE);
    let png = dir.join("huge.png");
    huge_png(&png, 20000, 20000);
    let o = diffsvg_bounded(&["loss", s(&svg), s(&png), "--resize"]);
    assert_fails(&o, "huge.png", "16384 pixels per side", &dir.join("none"));
}

#[test]
fn render_width_16384_is_refused_by_max_pixels() {
    let dir = scratch("regress-input-width-16384");
    let svg = write(&dir, "a.svg", SQUARE);
    let out = dir.join("a.png");
    let o = diffsvg_bounded(&["render", s(&svg), "-o", s(&out), "--width", "16384"]);
    assert_fails(&o, "a.svg", "exceeds the limit of 33554432 pixels", &out);
    // The largest canvas within the limit still renders, within the memory bound.
    let o = diffsvg_bounded(&["render", s(&svg), "-o", s(&out), "--width", "5792"]);
    assert_ok(&o);
    let img = diffsvg::Image::load(&out).unwrap();
    assert_eq!((img.width, img.height), (5792, 5792));
}

// Case 6: parallel writers of one output shared a temporary name.

/// Writes a 2-image IDX file of 28×28 digits: a vertical bar and a horizontal one.
fn two_digits(path: &Path) {
    let mut b = vec![0, 0, 8, 3];
    for d in [2u32, 28, 28] {
        b.extend_from_slice(&d.to_be_bytes());
    }
    for k in 0..2 {
        for y in 0..28 {
            for x in 0..28 {
                let ink = if k == 0 {
                    (12..16).contains(&x) && (4..24).contains(&y)
                } else {
                    (12..16).contains(&y) && (4..24).contains(&x)
                };
                b.push(if ink { 255 } else { 0 });
            }
        }
    }
    std::fs::write(path, b).unwrap();
}

#[test]
fn digits_indices_0_0_fits_each_digit_once() {
    let dir = scratch("regress-input-digits-0-0");
    let idx = dir.join("two-idx3-ubyte");
    two_digits(&idx);
    let out = dir.join("out");
    let o = diffsvg(&[
        "digits",
        "--images",
        s(&idx),
        "--indices",
        "0,0,1,0",
        "-o",
        s(&out),
        "--quiet",
        "--steps",
        "20",
        "--stage-steps",
        "10",
    ]);
    assert_ok(&o);
    assert!(stderr(&o).contains("more than once"), "{}", stderr(&o));
    let csv = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    assert_eq!(
        csv.lines().count(),
        3,
        "header and one row per digit: {csv}"
    );
    for i in 0..2 {
        Scene::load(out.join(format!("digit-{i:05}.svg")), Sizing::Natural).unwrap();
    }
    no_temp_files(&out);
}

// Case 7: range checks saw only XML attributes.

fn refuses(name: &str, svg: &str, what: &str) {
    let dir = scratch(&format!("regress-input-{name}"));
    let file = write(&dir, &format!("{name}.svg"), svg);
    let out = dir.join("out.png");
    let o = diffsvg(&["render", s(&file), "-o", s(&out), "--width", "128"]);
    assert_fails(&o, &format!("{name}.svg"), what, &out);
}

#[test]
fn style_stroke_width_1e38_is_refused() {
    refuses(
        "style-width",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">
          <path id="p" d="M10 10 L90 90" stroke="black" style="stroke-width:1e38"/></svg>"#,
        "path \"p\": stroke width 1.28e38 px is out of range",
    );
}

#[test]
fn style_rule_stroke_width_1e38_is_refused() {
    refuses(
        "style-rule",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">
          <style>.w { stroke-width: 1e38 }</style>
          <path id="q" class="w" d="M10 10 L90 90" stroke="black"/></svg>"#,
        "path \"q\": stroke width",
    );
    // Beyond f32, usvg would drop the value silently: the raw scan names the rule.
    refuses(
        "style-rule-f32",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">
          <style>.w { fill: #1e40af; stroke-width: 1e39 }</style>
          <path class="w" d="M10 10 L90 90" stroke="black"/></svg>"#,
        "1e39 out of range in property stroke-width of a <style> rule",
    );
}

#[test]
fn dasharray_1e35_is_refused() {
    refuses(
        "dash-range",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">
          <path id="d" d="M10 10 L90 90" stroke="black" stroke-dasharray="5 1e35"/></svg>"#,
        "path \"d\": stroke dash length",
    );
    refuses(
        "dash-css",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">
          <path id="d" d="M10 10 L90 90" stroke="black" style="stroke-dashoffset:-2e31"/></svg>"#,
        "path \"d\": stroke dash offset",
    );
}

#[test]
fn transformed_coordinate_out_of_range_is_refused() {
    refuses(
        "transformed",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">
          <g transform="scale(1e20)"><rect id="big" width="1e15" height="1" fill="red"/></g></svg>"#,
        "path \"big\": coordinate 1.28e35 px is out of range",
    );
}

// Case 8: diffsvg wrote SVGs it refused to read.

#[test]
fn fit_lr_points_1e308_writes_a_readable_svg() {
    let dir = scratch("regress-input-lr-points");
    let svg = write(&dir, "a.svg", SQUARE);
    let target = dir.join("t.png");
    let t = Scene::from_svg_str(MOVED, "moved.svg", Sizing::Natural).unwrap();
    diffsvg::raster::render(&t, &Default::default())
        .save_png(&target)
        .unwrap();
    let out = dir.join("out.svg");
    let snaps = dir.join("snaps");
    let o = diffsvg(&[
        "fit",
        s(&svg),
        s(&target),
        "-o",
        s(&out),
        "--lr-points",
        "1e308",
        "--iters",
        "4",
        "--snapshots",
        s(&snaps),
        "--every",
        "1",
    ]);
    assert_ok(&o);
    Scene::load(&out, Sizing::Natural).unwrap();
    // Every step's scene, huge steps included, reads back.
    let mut n = 0;
    for e in std::fs::read_dir(&snaps).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|e| e == "svg") {
            let back = Scene::load(&p, Sizing::Natural);
            assert!(back.is_ok(), "{}: {:?}", p.display(), back.err());
            n += 1;
        }
    }
    assert!(n >= 2, "snapshots written: {n}");
}

#[test]
fn perturb_points_1e300_is_refused_and_1e30_reads_back() {
    let dir = scratch("regress-input-perturb");
    let svg = write(&dir, "a.svg", SQUARE);
    let out = dir.join("p.svg");
    let o = diffsvg(&["perturb", s(&svg), "-o", s(&out), "--points", "1e300"]);
    assert_fails(&o, "--points", "out of range", &out);
    let o = diffsvg(&["perturb", s(&svg), "-o", s(&out), "--points", "1e30"]);
    assert_ok(&o);
    let back = Scene::load(&out, Sizing::Natural).unwrap();
    let far = back.params().iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(far > 1e28, "points moved far: {far}");
}

// Case 11 (parts): unbounded reads, gzip bombs, .svgz.

#[test]
fn render_dev_zero_is_bounded() {
    let dir = scratch("regress-input-dev-zero");
    let out = dir.join("z.png");
    let o = diffsvg_bounded(&["render", "/dev/zero", "-o", s(&out)]);
    assert_fails(&o, "/dev/zero", "larger than the limit of 64 mib", &out);
}

#[test]
fn digits_gzip_bomb_is_refused_before_inflating() {
    let dir = scratch("regress-input-gzip-bomb");
    let gz = |name: &str, dims: &[u32], zeros: usize| {
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
        e.write_all(&[0, 0, 8, dims.len() as u8]).unwrap();
        for d in dims {
            e.write_all(&d.to_be_bytes()).unwrap();
        }
        let chunk = vec![0u8; 1 << 20];
        for _ in 0..zeros >> 20 {
            e.write_all(&chunk).unwrap();
        }
        let p = dir.join(name);
        std::fs::write(&p, e.finish().unwrap()).unwrap();
        p
    };
    let out = dir.join("out");
    // A header promising 4e9 bytes of digits.
    let bomb = gz("bomb-idx3-ubyte.gz", &[5_000_000, 28, 28], 8 << 20);
    let o = diffsvg_bounded(&["digits", "--images", s(&bomb), "-o", s(&out)]);
    assert_fails(&o, "bomb-idx3-ubyte.gz", "above the limit", &out);
    // A modest header followed by far more data than it promises.
    let long = gz("long-idx3-ubyte.gz", &[10, 28, 28], 64 << 20);
    let o = diffsvg_bounded(&["digits", "--images", s(&long), "-o", s(&out)]);
    assert_fails(&o, "long-idx3-ubyte.gz", "promises 7840 bytes", &out);
    assert!(stderr(&o).contains("holds more"), "{}", stderr(&o));
}

#[test]
fn svgz_input_renders_like_the_plain_file() {
    let dir = scratch("regress-input-svgz");
    let svg = write(&dir, "a.svg", SQUARE);
    let svgz = dir.join("a.svgz");
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(SQUARE.as_bytes()).unwrap();
    std::fs::write(&svgz, e.finish().unwrap()).unwrap();
    let (a, b) = (dir.join("a.png"), dir.join("b.png"));
    assert_ok(&diffsvg(&[
        "render",
        s(&svg),
        "-o",
        s(&a),
        "--width",
        "128",
    ]));
    assert_ok(&diffsvg(&[
        "render",
        s(&svgz),
        "-o",
        s(&b),
        "--width",
        "128",
    ]));
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}

// ---- issue 27: reliability, round two -------------------------------------------------

/// Kind 1: a filter or `<image>` region of width 3.4e38 made usvg's geometry unwrap a
/// `None` while parsing (exit 101 with a panic trace) in `render` and `fit` alike; other
/// regions usvg computes (masks, clip paths, patterns, markers) get the same sizes.
#[test]
fn huge_regions_inside_svg_parsing_are_one_line_errors() {
    let dir = scratch("regress-27-regions");
    let cases = [
        r#"<filter id="f" width="3.4e38"><feGaussianBlur stdDeviation="2"/></filter><rect width="30" height="30" filter="url(#f)"/>"#,
        r#"<image width="3.4e38" height="10" href="data:image/png;base64,iVBORw0KGgo="/><rect width="30" height="30"/>"#,
        r#"<mask id="m" width="3.4e38" height="3.4e38"><rect width="9" height="9" fill="white"/></mask><rect width="30" height="30" mask="url(#m)"/>"#,
    ];
    // A pattern tile 3.4e38 wide is one tile now that patterns are drawn: it renders.
    let svg = write(
        &dir,
        "pattern.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64"><pattern id="p" width="3.4e38" height="3.4e38" patternUnits="userSpaceOnUse"><rect width="5" height="5"/></pattern><rect width="30" height="30" fill="url(#p)"/></svg>"#,
    );
    let png = dir.join("pattern.png");
    let o = diffsvg(&["render", s(&svg), "-o", s(&png)]);
    assert!(o.status.success() && png.exists(), "{o:?}");
    for (k, body) in cases.iter().enumerate() {
        let svg = write(
            &dir,
            &format!("r{k}.svg"),
            &format!(
                r#"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64">{body}</svg>"#
            ),
        );
        let png = dir.join(format!("r{k}.png"));
        let o = diffsvg(&["render", s(&svg), "-o", s(&png)]);
        assert_fails(&o, &format!("r{k}.svg"), "", &png);
        let fitted = dir.join(format!("r{k}.fit.svg"));
        let o = diffsvg(&["fit", s(&svg), s(&svg), "-o", s(&fitted), "--iters", "1"]);
        assert_fails(&o, &format!("r{k}.svg"), "", &fitted);
    }
    // The filter's panic itself, caught: the error says the parser failed on the file.
    let o = diffsvg(&[
        "render",
        s(&dir.join("r0.svg")),
        "-o",
        s(&dir.join("x.png")),
    ]);
    assert!(stderr(&o).contains("usvg"), "{}", stderr(&o));
}

/// Kind 2: `a48 48 0 0 0 7.1 1e38` has a modest radius, but SVG scales it up to reach
/// the far endpoint (to 5e37), and usvg spent minutes cutting that arc into cubics.
#[test]
fn arc_to_a_far_endpoint_is_refused_in_time() {
    let dir = scratch("regress-27-arc");
    for (k, d) in [
        "M10 10 a48 48 0 0 0 7.1 1e38 z",
        "M10 10 A5 5 0 1 1 3.4e38 -3.4e38",
        "M1e25 10 a1 1 0 0 0 -1e25 1e25",
    ]
    .iter()
    .enumerate()
    {
        let svg = write(
            &dir,
            &format!("a{k}.svg"),
            &format!(
                r#"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64"><path d="{d}"/></svg>"#
            ),
        );
        let png = dir.join(format!("a{k}.png"));
        let t = std::time::Instant::now();
        let o = diffsvg_bounded(&["render", s(&svg), "-o", s(&png)]);
        assert_fails(&o, &format!("a{k}.svg"), "arc radius", &png);
        assert!(t.elapsed().as_secs() < 20, "{d}: {:?}", t.elapsed());
    }
    // An arc whose endpoint is near stays drawn.
    let svg = write(
        &dir,
        "near.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64"><path d="M10 10 a48 48 0 0 0 40 40 z"/></svg>"#,
    );
    assert_ok(&diffsvg(&[
        "render",
        s(&svg),
        "-o",
        s(&dir.join("near.png")),
    ]));
}

/// Kind 3: a picture two pixels wide panicked in `vectorize` (`min > max` in the clamp of
/// a starting circle's radius). Every picture of one to three pixels in either direction
/// vectorizes, in every mode, to an SVG that reads back at the picture's size.
#[test]
fn vectorize_pictures_one_and_two_pixels_wide() {
    let dir = scratch("regress-27-tiny");
    for (w, h) in [(1, 1), (2, 2), (2, 40), (40, 2), (1, 40), (3, 3)] {
        let img = Image {
            width: w,
            height: h,
            data: (0..w * h)
                .map(|i| {
                    let v = ((i * 37) % 11) as f32 / 10.0;
                    [v, 1.0 - v, 0.5, 1.0]
                })
                .collect(),
        };
        let png = dir.join(format!("p{w}x{h}.png"));
        img.save_png(&png).unwrap();
        for mode in ["adaptive", "fixed", "painterly"] {
            let out = dir.join(format!("p{w}x{h}-{mode}.svg"));
            let o = diffsvg(&[
                "vectorize",
                s(&png),
                "-o",
                s(&out),
                "--mode",
                mode,
                "--iters",
                "4",
            ]);
            assert_ok(&o);
            let back = Scene::load(&out, Sizing::Natural).unwrap();
            assert_eq!((back.width, back.height), (w, h), "{mode} {w}x{h}");
        }
    }
}

/// Found by issue 27's fuzzer: 200,000 copies of a glyph stacked at 128² made `fit`'s
/// backward pass allocate gigabytes (the record of one band grows with the stacked
/// shapes). It is refused before the run, in one line, under the 1 GiB ceiling.
#[test]
fn fit_on_thousands_of_stacked_copies_is_refused_before_allocating() {
    let dir = scratch("regress-27-stack");
    let one = r#"<path d="M10 10H100V120H10Z"/>"#;
    let svg = write(
        &dir,
        "stack.svg",
        &format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="128" height="128">{}</svg>"#,
            one.repeat(20_000)
        ),
    );
    let out = dir.join("f.svg");
    let o = diffsvg_bounded(&["fit", s(&svg), s(&svg), "-o", s(&out), "--iters", "2"]);
    assert_fails(&o, "stack.svg", "too complex to differentiate", &out);
    let target = dir.join("t.png");
    Image::filled(128, 128, [1.0; 4]).save_png(&target).unwrap();
    let o = diffsvg_bounded(&["grad", s(&svg), s(&target)]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("too complex to differentiate"),
        "{}",
        stderr(&o)
    );
    // Rendering needs no record: it still draws.
    assert_ok(&diffsvg_bounded(&[
        "render",
        s(&svg),
        "-o",
        s(&dir.join("r.png")),
    ]));
}

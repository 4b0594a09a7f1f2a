//! `<image>` elements: parity with resvg (nearest, bilinear, bicubic; PNG, JPEG, GIF),
//! limits checked before decoding, unreadable files refused, gradients over and of an
//! image, and SVG out read back to the same pixels.

use std::path::Path;

use base64::Engine as _;
use diffsvg::gradcheck::{DEFAULT_TOLERANCE, check};
use diffsvg::loss::Loss;
use diffsvg::raster::{RenderOptions, render};
use diffsvg::reference::{PARITY_MAE, PARITY_PSNR, render_resvg};
use diffsvg::scene::{ParamGroup, ParamLayout, Structure, from_tree, parse_tree};
use diffsvg::{Image, Node, Scene, Sizing, metrics};

use super::common::{assert_fails, diffsvg, s, scratch, write};

/// A small straight-RGBA picture with varied colors and alpha (some fully transparent).
fn picture(w: u32, h: u32) -> Vec<u8> {
    (0..w * h)
        .flat_map(|k| {
            let (x, y) = (k % w, k / w);
            [
                (x * 255 / (w - 1)) as u8,
                (y * 255 / (h - 1)) as u8,
                ((x * 7 + y * 13) % 256) as u8,
                [255, 255, 180, 90, 0][(k % 5) as usize],
            ]
        })
        .collect()
}

fn png(w: u32, h: u32, rgba: &[u8]) -> Vec<u8> {
    let mut buf = Vec::new();
    let enc = image::codecs::png::PngEncoder::new(&mut buf);
    image::ImageEncoder::write_image(enc, rgba, w, h, image::ExtendedColorType::Rgba8).unwrap();
    buf
}

fn data_url(mime: &str, bytes: &[u8]) -> String {
    format!(
        "data:{mime};base64,{}",
        base64::engine::general_purpose::STANDARD.encode(bytes)
    )
}

fn svg_with(size: u32, body: &str) -> String {
    format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{size}" height="{size}">{body}</svg>"#
    )
}

/// diffsvg's and resvg's pixels of `svg`: (MAE in levels, PSNR).
fn parity_of(svg: &str, name: &str) -> (f64, f64, Scene) {
    let name = Path::new(name);
    let tree = parse_tree(svg.as_bytes(), name).unwrap();
    let scene = from_tree(&tree, name, Sizing::Natural).unwrap();
    let ours = render(&scene, &RenderOptions::default()).quantized();
    let theirs = render_resvg(&tree, name, Sizing::Natural).unwrap();
    let c = metrics::compare(&ours, &theirs);
    (c.mae, c.psnr, scene)
}

fn assert_parity(svg: &str, name: &str) -> Scene {
    let (mae, psnr, scene) = parity_of(svg, name);
    println!("{name}: MAE {mae:.4}, PSNR {psnr:.1} dB");
    assert!(
        mae <= PARITY_MAE && psnr >= PARITY_PSNR,
        "{name}: MAE {mae:.3}, PSNR {psnr:.1} dB"
    );
    scene
}

/// A 6 × 5 PNG with transparent and translucent pixels, scaled up (and down) under each
/// `image-rendering`, its rectangle on the pixel grid: resvg's pixels within the parity
/// bounds (measured: bit-exact but for bilinear, MAE below 0.001). A rotated, sheared one
/// too (MAE 0.05: its slanted edges are anti-aliased differently).
#[test]
fn png_images_match_resvg_nearest_bilinear_bicubic() {
    let url = data_url("image/png", &png(6, 5, &picture(6, 5)));
    for (rendering, q) in [
        ("optimizeSpeed", "Nearest"),
        ("smooth", "Bilinear"),
        ("optimizeQuality", "Bicubic"),
    ] {
        for (w, h) in [(48, 40), (30, 25), (4, 4), (7, 10)] {
            let svg = svg_with(
                64,
                &format!(
                    r#"<rect width="64" height="64" fill="teal"/><image x="3" y="5" width="{w}" height="{h}" preserveAspectRatio="none" style="image-rendering:{rendering}" href="{url}"/>"#
                ),
            );
            let scene = assert_parity(&svg, &format!("png-{rendering}-{w}x{h}.svg"));
            let mut found = None;
            scene.for_each_path(|p| {
                if let Some(diffsvg::scene::Paint::Image(i)) = p.fill.as_ref().map(|f| &f.paint) {
                    found = Some(format!("{:?}", i.quality));
                }
            });
            assert_eq!(found.as_deref(), Some(q));
        }
    }
    let svg = svg_with(
        64,
        &format!(
            r#"<image transform="translate(30 4) rotate(33) skewX(10)" width="36" height="30" href="{url}"/>"#
        ),
    );
    assert_parity(&svg, "png-rotated.svg");
}

/// JPEG (no alpha, decoded by the same decoder as resvg's) and GIF (its first frame)
/// images at a non-integer scale.
#[test]
fn jpeg_and_gif_images_match_resvg() {
    let rgba = picture(16, 12);
    let rgb: Vec<u8> = rgba.chunks(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
    let mut jpeg = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 90),
        &rgb,
        16,
        12,
        image::ExtendedColorType::Rgb8,
    )
    .unwrap();
    // GIF: one bit of alpha.
    let gif_rgba: Vec<u8> = rgba
        .chunks(4)
        .flat_map(|p| [p[0], p[1], p[2], if p[3] > 128 { 255 } else { 0 }])
        .collect();
    let mut gif = Vec::new();
    {
        let mut enc = image::codecs::gif::GifEncoder::new(&mut gif);
        let frame = image::Frame::new(image::RgbaImage::from_raw(16, 12, gif_rgba).unwrap());
        enc.encode_frame(frame).unwrap();
    }
    for (mime, bytes) in [("image/jpeg", jpeg), ("image/gif", gif)] {
        let url = data_url(mime, &bytes);
        for quality in ["optimizeSpeed", "optimizeQuality"] {
            let svg = svg_with(
                50,
                &format!(
                    r#"<image x="1" y="2" width="40" height="30" image-rendering="{quality}" href="{url}"/>"#
                ),
            );
            assert_parity(&svg, &format!("{mime}-{quality}.svg").replace('/', "-"));
        }
    }
}

/// A PNG whose header claims 100000 × 100000 pixels is refused from its header, at once,
/// with an error naming the SVG and the size; so is a set of images that together pass
/// the limit.
#[test]
fn image_too_large_is_refused_before_decoding() {
    // Signature, then an IHDR chunk (with its CRC) and nothing else: decoding would fail,
    // so only a check of the header can give the size error.
    let mut ihdr = b"IHDR".to_vec();
    ihdr.extend_from_slice(&100_000u32.to_be_bytes());
    ihdr.extend_from_slice(&100_000u32.to_be_bytes());
    ihdr.extend_from_slice(&[8, 6, 0, 0, 0]);
    let mut crc = flate2::Crc::new();
    crc.update(&ihdr);
    let mut bytes = b"\x89PNG\r\n\x1a\n".to_vec();
    bytes.extend_from_slice(&13u32.to_be_bytes());
    bytes.extend_from_slice(&ihdr);
    bytes.extend_from_slice(&crc.sum().to_be_bytes());
    let dir = scratch("image-too-large");
    std::fs::write(dir.join("huge.png"), &bytes).unwrap();
    let svg = write(
        &dir,
        "huge.svg",
        &svg_with(10, r#"<image width="10" height="10" href="huge.png"/>"#),
    );
    let t = std::time::Instant::now();
    let e = Scene::load(&svg, Sizing::Natural).unwrap_err().to_string();
    assert!(
        e.contains("huge.svg") && e.contains("100000x100000") && e.contains("limit"),
        "{e}"
    );
    assert!(t.elapsed().as_secs_f64() < 1.0, "{:?}", t.elapsed());
    // Two images of 4096 × 4096 are each below the limit, three together above it.
    let big = png(4096, 4096, &vec![255u8; 4096 * 4096 * 4]);
    std::fs::write(dir.join("big.png"), &big).unwrap();
    let one = r#"<image width="10" height="10" href="big.png"/>"#;
    let svg = write(&dir, "three.svg", &svg_with(10, &one.repeat(3)));
    let e = Scene::load(&svg, Sizing::Natural).unwrap_err().to_string();
    assert!(e.contains("three.svg") && e.contains("4096x4096"), "{e}");
}

/// A missing image file: `diffsvg render` exits with status 2, one line naming the SVG
/// and the image, and writes nothing; relative paths resolve against the SVG's folder
/// whatever the working folder.
#[test]
fn missing_image_file_is_refused_by_the_cli() {
    let dir = scratch("image-missing");
    let svg = write(
        &dir,
        "drawing.svg",
        &svg_with(10, r#"<image width="10" height="10" href="missing.png"/>"#),
    );
    let out_png = dir.join("out.png");
    let out = diffsvg(&["render", s(&svg), "-o", s(&out_png)]);
    assert_fails(&out, "missing.png", "cannot be read", &out_png);
    assert!(String::from_utf8_lossy(&out.stderr).contains("drawing.svg"));
    // The same file beside the SVG, loaded from elsewhere: found.
    std::fs::create_dir_all(dir.join("pics")).unwrap();
    std::fs::write(dir.join("pics/here.png"), png(2, 2, &picture(2, 2))).unwrap();
    let svg = write(
        &dir,
        "found.svg",
        &svg_with(
            10,
            r#"<image width="10" height="10" href="pics/here.png"/>"#,
        ),
    );
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_diffsvg"))
        .current_dir(std::env::temp_dir())
        .args(["render", s(&svg), "-o", s(&out_png)])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Not an image at all.
    std::fs::write(dir.join("junk.png"), b"\x01\x02 not an image").unwrap();
    let svg = write(
        &dir,
        "junk.svg",
        &svg_with(10, r#"<image width="10" height="10" href="junk.png"/>"#),
    );
    let e = Scene::load(&svg, Sizing::Natural).unwrap_err().to_string();
    assert!(e.contains("junk.svg") && e.contains("junk.png"), "{e}");
    // A PNG signature and nothing else: usvg finds no size and would drop the image.
    let svg = svg_with(
        10,
        r#"<image width="10" height="10" href="data:image/png;base64,iVBORw0KGgo="/>"#,
    );
    let e = Scene::from_svg_str(&svg, "sig.svg", Sizing::Natural)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("sig.svg") && e.contains("cannot be decoded"),
        "{e}"
    );
    // Text that says it is a PNG.
    let svg = svg_with(
        10,
        r#"<image width="10" height="10" href="data:image/png;base64,aGVsbG8="/>"#,
    );
    let e = Scene::from_svg_str(&svg, "text.svg", Sizing::Natural)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("text.svg") && e.contains("cannot be decoded"),
        "{e}"
    );
}

/// A shape drawn over an image: its points' gradient (the image is the color below it)
/// and the gradient of the image rectangle's own points and opacity, against finite
/// differences. The image's paint has no slots; its rectangle's points are frozen in
/// fits (rate 0).
#[test]
fn gradients_over_and_of_an_image_match_differences() {
    let url = data_url("image/png", &png(6, 5, &picture(6, 5)));
    let svg = svg_with(
        32,
        &format!(
            r#"<image id="pic" x="3.3" y="2.6" width="24.2" height="21.7" preserveAspectRatio="none" href="{url}"/>
               <path id="tri" d="M8.3 6.2 L25.1 11.7 L12.4 27.3 Z" fill="orange" fill-opacity="0.7"/>"#
        ),
    );
    let scene = Scene::from_svg_str(&svg, "over.svg", Sizing::Natural).unwrap();
    let layout = ParamLayout::new(&scene);
    // Image: its rectangle's points (a move and three lines: 10 control points) and its
    // opacity; no paint slot (the paint's offsets start, empty, at the opacity).
    let img = layout.paths[0];
    let fill = img.fill.unwrap();
    assert_eq!(
        (fill.base, img.fill_opacity),
        (img.fill_opacity, img.fill_opacity)
    );
    assert_eq!(layout.slots[img.fill_opacity].group, ParamGroup::Opacity);
    let structure = Structure::of(&scene);
    assert_eq!(structure.shapes[0].fill.as_ref().unwrap().kind, "image");
    assert_eq!(structure.shapes[0].id, "pic");
    // Rates: the image's points frozen, the triangle's not.
    let rates = diffsvg::fit::LearningRates::default().per_slot(&scene);
    let n_img = 2 * match &scene.nodes[0] {
        Node::Path(p) => p.points.len(),
        Node::Group(_) => unreachable!(),
    };
    assert!(
        rates[img.points..img.points + n_img]
            .iter()
            .all(|&r| r == 0.0)
    );
    assert!(rates[layout.paths[1].points] > 0.0);

    let target = Image::filled(32, 32, [0.2, 0.3, 0.9, 1.0]);
    let (_, _, groups) = check(
        &scene,
        &target,
        Loss::Mse,
        &RenderOptions::default(),
        Some([1.0, 1.0, 1.0, 1.0]),
        None,
    );
    for g in &groups {
        println!("{g}");
        assert!(g.passes(DEFAULT_TOLERANCE), "{g}");
    }
    assert!(groups.iter().any(|g| g.group == ParamGroup::Points));
}

/// SVG out writes the image as `<image>` with an embedded PNG; read back (by diffsvg and
/// by resvg) it draws the same pixels, for every filter and an opacity below 1.
#[test]
fn images_written_as_svg_read_back_to_the_same_pixels() {
    let url = data_url("image/png", &png(6, 5, &picture(6, 5)));
    let svg = svg_with(
        40,
        &format!(
            r#"<image id="a" x="1.5" y="2" width="30" height="25" preserveAspectRatio="none" href="{url}"/>
               <image id="b" transform="rotate(20 20 20)" x="10" y="10" width="18" height="15" image-rendering="optimizeSpeed" opacity="0.6" href="{url}"/>
               <image id="c" x="5" y="28" width="12" height="10" style="image-rendering:smooth" href="{url}"/>"#
        ),
    );
    let scene = Scene::from_svg_str(&svg, "in.svg", Sizing::Natural).unwrap();
    let text = scene.to_svg_string();
    assert_eq!(text.matches("<image").count(), 3, "{text}");
    assert!(text.contains("data:image/png;base64,"));
    let back = Scene::from_svg_str(&text, "out.svg", Sizing::Natural).unwrap();
    let a = render(&scene, &RenderOptions::default()).quantized();
    let b = render(&back, &RenderOptions::default()).quantized();
    let c = metrics::compare(&a, &b);
    assert!(c.max == 0.0, "read back differs: {c:?}");
    // And resvg reads what diffsvg wrote as diffsvg does.
    let name = Path::new("out.svg");
    let theirs = render_resvg(
        &parse_tree(text.as_bytes(), name).unwrap(),
        name,
        Sizing::Natural,
    )
    .unwrap();
    let c = metrics::compare(&b, &theirs);
    assert!(c.mae <= 1.0 && c.psnr >= 35.0, "{c:?}");
    // A rectangle moved off its image is refused by the writer, naming the image.
    let mut moved = scene.clone();
    let mut params = moved.params();
    params[0] += 2.0;
    moved.set_params(&params);
    let dir = scratch("image-svg-out");
    let e = moved.save_svg(dir.join("m.svg")).unwrap_err().to_string();
    assert!(e.contains("\"a\"") && e.contains("image"), "{e}");
    assert!(!dir.join("m.svg").exists());
    scene.save_svg(dir.join("ok.svg")).unwrap();
}

/// An SVG image is converted as paths (what the conversion refuses inside it, it
/// refuses, naming the image); a remote one is refused.
#[test]
fn svg_images_become_paths() {
    let inner = r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 10 10"><rect x="2" y="2" width="6" height="6" fill="navy"/></svg>"#;
    let url = data_url("image/svg+xml", inner.as_bytes());
    let svg = svg_with(
        40,
        &format!(r#"<image id="v" x="4" y="4" width="30" height="30" href="{url}"/>"#),
    );
    let scene = assert_parity(&svg, "svg-image.svg");
    assert_eq!(scene.path_count(), 1);
    let with_text =
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 10 10"><text>hi</text></svg>"#;
    let url = data_url("image/svg+xml", with_text.as_bytes());
    let svg = svg_with(
        40,
        &format!(r#"<image width="30" height="30" href="{url}"/>"#),
    );
    let e = Scene::from_svg_str(&svg, "t.svg", Sizing::Natural)
        .unwrap_err()
        .to_string();
    assert!(e.contains("t.svg") && e.contains("<text>"), "{e}");
    let svg = svg_with(
        40,
        r#"<image width="30" height="30" href="https://example.com/a.png"/>"#,
    );
    let e = Scene::from_svg_str(&svg, "t.svg", Sizing::Natural)
        .unwrap_err()
        .to_string();
    assert!(e.contains("remote"), "{e}");
}

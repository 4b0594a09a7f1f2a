//! `diffsvg digits`: IDX input, per-digit SVGs checked by rendering them again, the summary
//! and the contact sheet, and bad input.

use std::path::{Path, PathBuf};

use diffsvg::fit::digit::intensities;
use diffsvg::metrics::iou;
use diffsvg::scene::{LineCap, LineJoin, Node, Paint, Stroke};
use diffsvg::{Scene, Sizing};

use crate::common::{diffsvg, s, scratch, shared_data};

/// Writes an unsigned-byte IDX file.
fn write_idx(path: &Path, dims: &[u32], data: &[u8]) {
    let mut b = vec![0, 0, 8, dims.len() as u8];
    for d in dims {
        b.extend_from_slice(&d.to_be_bytes());
    }
    b.extend_from_slice(data);
    std::fs::write(path, b).unwrap();
}

/// Three hand-made "digits" (a 1, a 7 and a 0), drawn by diffsvg at 28×28.
fn drawn_digits() -> Vec<Vec<f32>> {
    let stroke = |build: &dyn Fn(&mut diffsvg::Path)| {
        let mut scene = Scene::new(28, 28);
        let mut p = diffsvg::Path::new("d");
        build(&mut p);
        let mut st = Stroke::new(Paint::Solid([1.0; 3]), 2.6);
        st.cap = LineCap::Round;
        st.join = LineJoin::Round;
        p.stroke = Some(st);
        scene.nodes.push(Node::Path(p));
        intensities(&scene, 28, 28)
    };
    vec![
        stroke(&|p| {
            p.move_to([15.0, 5.0]);
            p.line_to([13.0, 23.0]);
        }),
        stroke(&|p| {
            p.move_to([7.0, 6.0]);
            p.line_to([21.0, 6.0]);
            p.cubic_to([17.0, 12.0], [14.0, 17.0], [12.0, 23.0]);
        }),
        stroke(&|p| {
            p.move_to([14.0, 5.0]);
            p.cubic_to([23.0, 5.0], [23.0, 23.0], [14.0, 23.0]);
            p.cubic_to([5.0, 23.0], [5.0, 5.0], [14.0, 5.0]);
        }),
    ]
}

/// The ink of a written digit SVG rendered at `w × h`, and its strokes' segment counts.
fn reread(svg: &Path, w: u32, h: u32) -> (Vec<f32>, Vec<usize>) {
    let text = std::fs::read_to_string(svg).unwrap();
    let scene = Scene::from_svg_str(&text, svg, Sizing::Exact(w, h)).unwrap();
    let mut segments = Vec::new();
    scene.for_each_path(|p| {
        if p.stroke.is_some() {
            segments.push(p.subpaths.iter().map(|sp| sp.segments()).sum());
        }
    });
    // The SVG has its own black background, so the red channel is the ink.
    let img = diffsvg::raster::render(&scene, &Default::default());
    (img.data.iter().map(|p| p[0]).collect(), segments)
}

fn summary_rows(dir: &Path) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(dir.join("summary.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("index,label,strokes,segments,mse,iou,ms")
    );
    lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect()
}

/// Checks every digit's SVG against its image: IoU and the stroke budget.
fn check_outputs(dir: &Path, digits: &[(usize, Vec<f32>)], min_mean_iou: f64) {
    let mut total = 0.0;
    for (index, pixels) in digits {
        let svg = dir.join(format!("digit-{index:05}.svg"));
        let (ink, segments) = reread(&svg, 28, 28);
        assert!(
            (1..=2).contains(&segments.len()),
            "{}: {segments:?}",
            svg.display()
        );
        assert!(
            segments.iter().all(|&k| (1..=3).contains(&k)),
            "{segments:?}"
        );
        total += iou(&ink, pixels, 0.5);
    }
    let mean = total / digits.len() as f64;
    assert!(mean >= min_mean_iou, "mean IoU {mean}");
}

#[test]
fn digits_from_an_idx_file() {
    let dir = scratch("digits-idx");
    let digits = drawn_digits();
    let bytes: Vec<u8> = digits
        .iter()
        .flatten()
        .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    let (images, labels) = (dir.join("images.idx"), dir.join("labels.idx"));
    write_idx(&images, &[3, 28, 28], &bytes);
    write_idx(&labels, &[3], &[1, 7, 0]);
    let out = dir.join("out");
    let o = diffsvg(&[
        "digits",
        "--images",
        s(&images),
        "--labels",
        s(&labels),
        "--indices",
        "0..3",
        "-o",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = summary_rows(&out);
    assert_eq!(rows.len(), 3);
    assert_eq!(
        rows.iter().map(|r| r[1].as_str()).collect::<Vec<_>>(),
        ["1", "7", "0"]
    );
    let quantized: Vec<(usize, Vec<f32>)> = (0..3)
        .map(|i| {
            (
                i,
                bytes[i * 784..(i + 1) * 784]
                    .iter()
                    .map(|&b| b as f32 / 255.0)
                    .collect(),
            )
        })
        .collect();
    check_outputs(&out, &quantized, 0.85);
    let sheet = image::open(out.join("contact.png")).unwrap();
    // 3 pairs at 2× (56 px cells), columns = ceil(sqrt(6)) = 3, 2 px gaps.
    assert_eq!((sheet.width(), sheet.height()), (3 * 58 + 2, 2 * 58 + 2));
}

#[test]
fn digits_bad_input() {
    let dir = scratch("digits-bad");
    let out = dir.join("out");
    let png = dir.join("not-idx.png");
    std::fs::write(&png, b"\x89PNG\r\n\x1a\n....").unwrap();
    let o = diffsvg(&["digits", "--images", s(&png), "-o", s(&out)]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("not-idx.png") && err.contains("not an IDX"),
        "{err}"
    );

    let images = dir.join("images.idx");
    write_idx(&images, &[2, 28, 28], &[0; 2 * 784]);
    let labels = dir.join("labels.idx");
    write_idx(&labels, &[3], &[1, 2, 3]);
    let o = diffsvg(&[
        "digits",
        "--images",
        s(&images),
        "--labels",
        s(&labels),
        "-o",
        s(&out),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("labels.idx") && err.contains("3 labels for 2 images"),
        "{err}"
    );

    let o = diffsvg(&[
        "digits",
        "--images",
        s(&images),
        "--indices",
        "0..5",
        "-o",
        s(&out),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--indices 0..5") && err.contains("last index, 1"),
        "{err}"
    );
    assert!(!out.join("summary.csv").exists());
}

/// The first MNIST test digits: mean IoU ≥ 0.8 with at most 2 strokes of 3 segments,
/// measured on the written SVGs.
#[test]
fn digits_on_mnist() {
    let Some(data) = shared_data("digits_on_mnist") else {
        return;
    };
    let images: PathBuf = data.join("mnist/t10k-images-idx3-ubyte.gz");
    let dir = scratch("digits-mnist");
    let o = diffsvg(&[
        "digits",
        "--images",
        s(&images),
        "--indices",
        "0..40",
        "-o",
        s(&dir),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let set = diffsvg::mnist::read_images(&images).unwrap();
    let digits: Vec<(usize, Vec<f32>)> = (0..40).map(|i| (i, set.get(i))).collect();
    check_outputs(&dir, &digits, 0.8);
    assert_eq!(summary_rows(&dir).len(), 40);
}

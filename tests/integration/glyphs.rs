//! `diffsvg glyphs`: closed cubic outlines fitted to rendered font digits reach the IoU
//! goal (checked here from the written SVGs, not from the report); bad input fails
//! cleanly.

use std::path::Path;

use diffsvg::raster::{RenderOptions, render};
use diffsvg::{Image, Scene, Sizing};

use super::common::{assert_fails, diffsvg, root, s, scratch, write};

/// Ink coverage (1 − mean RGB over white) of an SVG rendered 128 px wide.
fn ink_at_128(svg: &Path) -> Vec<f32> {
    let scene = Scene::load(svg, Sizing::Width(128)).unwrap();
    assert_eq!((scene.width, scene.height), (128, 128), "{}", svg.display());
    let mut img = render(&scene, &RenderOptions::default());
    img.over_background([1.0; 4]);
    img.data
        .iter()
        .map(|p| 1.0 - (p[0] + p[1] + p[2]) / 3.0)
        .collect()
}

/// IoU of the pixels inked at least half in both.
fn iou(a: &[f32], b: &[f32]) -> f64 {
    let (mut inter, mut union) = (0, 0);
    for (&x, &y) in a.iter().zip(b) {
        inter += (x >= 0.5 && y >= 0.5) as usize;
        union += (x >= 0.5 || y >= 0.5) as usize;
    }
    inter as f64 / union as f64
}

/// The font's own segment counts written beside the glyphs by `make_glyphs`.
fn font_segments(digit: &str) -> String {
    let csv = std::fs::read_to_string(root().join("svg-samples/glyphs/segments.csv")).unwrap();
    csv.lines()
        .find_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[0] == digit).then(|| f[2].to_string())
        })
        .unwrap_or_else(|| panic!("segments.csv lists no {digit}"))
}

#[test]
fn digits_reach_the_iou_goal() {
    let dir = scratch("glyphs");
    let glyphs = root().join("svg-samples/glyphs");
    // 0 has a hole, 1 has none.
    let inputs = [glyphs.join("0.svg"), glyphs.join("1.svg")];
    let out = diffsvg(&["glyphs", s(&inputs[0]), s(&inputs[1]), "-o", s(&dir)]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("2 of 2 reached"), "{stdout}");
    let csv = std::fs::read_to_string(dir.join("glyphs.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    for (input, digit, contours) in [(&inputs[0], "0", 2), (&inputs[1], "1", 1)] {
        let fitted = dir.join(format!("{digit}.svg"));
        let score = iou(&ink_at_128(&fitted), &ink_at_128(input));
        assert!(score >= 0.99, "{digit}: IoU {score}");
        // One black path of closed cubics, one subpath per contour, over a background.
        let scene = Scene::load(&fitted, Sizing::Natural).unwrap();
        assert_eq!(scene.path_count(), 2, "{digit}: background and glyph");
        let mut subpaths = Vec::new();
        scene.for_each_path(|p| subpaths.push(p.subpaths.clone()));
        let glyph = &subpaths[1];
        assert_eq!(glyph.len(), contours, "{digit}");
        assert!(glyph.iter().all(|sp| sp.closed));
        let segments: usize = glyph.iter().map(|sp| sp.segments()).sum();
        let row: Vec<&str> = csv
            .lines()
            .find(|l| l.split(',').next() == Some(digit))
            .unwrap_or_else(|| panic!("glyphs.csv lists no {digit}:\n{csv}"))
            .split(',')
            .collect();
        assert_eq!(row[col("segments")], segments.to_string(), "{digit}");
        assert_eq!(row[col("contours")], contours.to_string(), "{digit}");
        assert_eq!(row[col("font_segments")], font_segments(digit), "{digit}");
        assert_eq!(row[col("reached")], "true");
        // Fewer cubics than the font has segments, for these two.
        assert!(
            segments < font_segments(digit).parse::<usize>().unwrap(),
            "{digit}: {segments}"
        );
    }
    let sheet = Image::load(dir.join("contact.png")).unwrap();
    assert_eq!((sheet.width, sheet.height), (2 * 132 + 4, 2 * 132 + 4));
}

#[test]
fn a_malformed_glyph_fails_naming_the_file() {
    let dir = scratch("glyphs-bad");
    let bad = write(
        &dir,
        "broken.svg",
        "<svg xmlns='http://www.w3.org/2000/svg'><path",
    );
    let good = root().join("svg-samples/glyphs/7.svg");
    let out_dir = dir.join("out");
    let out = diffsvg(&["glyphs", s(&good), s(&bad), "-o", s(&out_dir)]);
    assert_fails(
        &out,
        "broken.svg",
        "malformed svg",
        &out_dir.join("glyphs.csv"),
    );
    // Inputs are all read before any fitting: nothing was written for the good one.
    assert!(!out_dir.join("7.svg").exists());
    let missing = dir.join("missing");
    let out = diffsvg(&["glyphs", s(&missing), "-o", s(&out_dir)]);
    assert_fails(&out, "missing", "no such file", &out_dir.join("glyphs.csv"));
}

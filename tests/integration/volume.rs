//! `diffsvg recon voxel` and `diffsvg view` end to end: a tiny NeRF-synthetic scene of two
//! shaded spheres (ray-traced here, exactly, through the library's cameras) is
//! reconstructed and viewed from held-out cameras and an orbit; and every kind of bad input
//! (scene, flags, model file) fails with a clean message and leaves no file behind.

use std::path::{Path, PathBuf};
use std::process::Output;

use diffsvg::glam::Vec3;
use diffsvg::volume::Ray;
use diffsvg::volume::camera::Camera;
use serde_json::{Value, json};

use super::common::{diffsvg, s, scratch, shared_data, skip};

// ---------------------------------------------------------------------------------------
// A tiny synthetic scene

/// An opaque, Lambert-shaded sphere.
struct Sphere {
    center: Vec3,
    radius: f32,
    albedo: [f32; 3],
}

const SPHERES: [Sphere; 2] = [
    Sphere {
        center: Vec3::new(-0.3, -0.1, 0.0),
        radius: 0.5,
        albedo: [0.9, 0.2, 0.1],
    },
    Sphere {
        center: Vec3::new(0.45, 0.3, 0.25),
        radius: 0.35,
        albedo: [0.1, 0.35, 0.95],
    },
];

/// Horizontal field of view of every camera, radians.
const FOV: f32 = 0.8;
/// Distance of the cameras from the origin, world units.
const DIST: f32 = 3.0;

/// The shaded color of the nearest sphere hit by `r`, if any.
fn trace(r: &Ray) -> Option<[f32; 3]> {
    let light = Vec3::new(0.3, -0.5, 0.8).normalize();
    let mut best: Option<(f32, &Sphere)> = None;
    for sp in &SPHERES {
        let oc = r.origin - sp.center;
        let b = oc.dot(r.dir);
        let disc = b * b - (oc.length_squared() - sp.radius * sp.radius);
        if disc < 0.0 {
            continue;
        }
        let t = -b - disc.sqrt();
        if t > 0.0 && best.is_none_or(|(bt, _)| t < bt) {
            best = Some((t, sp));
        }
    }
    best.map(|(t, sp)| {
        let n = (r.at(t) - sp.center).normalize();
        let shade = 0.35 + 0.65 * n.dot(light).max(0.0);
        sp.albedo.map(|a| a * shade)
    })
}

/// Camera `i` of `n` looking at the origin from distance [`DIST`], +Z up (as in Blender):
/// a golden-angle spiral from 20° below the horizon to 65° above it, turned by `phase`.
fn camera(i: usize, n: usize, phase: f32, size: u32) -> Camera {
    let golden = std::f32::consts::PI * (3.0 - 5.0f32.sqrt());
    let z = -0.35 + 1.25 * (i as f32 + 0.5) / n as f32;
    let r = (1.0 - z * z).sqrt();
    let a = golden * i as f32 + phase;
    let eye = Vec3::new(r * a.cos(), r * a.sin(), z) * DIST;
    Camera::look_at(eye, Vec3::ZERO, Vec3::Z, FOV, size, size).unwrap()
}

/// The camera's photo as straight RGBA: per pixel, 4×4 sub-samples; alpha is the covered
/// fraction and the color the mean of the covered samples, so that compositing over white
/// gives the anti-aliased picture on a white background.
fn photo(cam: &Camera) -> image::RgbaImage {
    const SS: u32 = 4;
    image::RgbaImage::from_fn(cam.width, cam.height, |x, y| {
        let (mut sum, mut hits) = ([0.0f32; 3], 0);
        for k in 0..SS * SS {
            let u = x as f32 + ((k % SS) as f32 + 0.5) / SS as f32;
            let v = y as f32 + ((k / SS) as f32 + 0.5) / SS as f32;
            if let Some(c) = trace(&cam.ray(u, v)) {
                (0..3).for_each(|i| sum[i] += c[i]);
                hits += 1;
            }
        }
        let byte = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        if hits == 0 {
            image::Rgba([0, 0, 0, 0])
        } else {
            let c = sum.map(|v| byte(v / hits as f32));
            image::Rgba([c[0], c[1], c[2], byte(hits as f32 / (SS * SS) as f32)])
        }
    })
}

/// A camera-to-world pose as the row-major 4×4 `transform_matrix` of a transforms file.
fn rows(cam: &Camera) -> Value {
    let (m, t) = (cam.c2w.matrix3, cam.c2w.translation);
    let row = |r: usize| json!([m.x_axis[r], m.y_axis[r], m.z_axis[r], t[r]]);
    json!([row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]])
}

/// Writes a NeRF-synthetic folder: `n_train` and `n_test` views of `size²` pixels
/// (`train/r_i.png`, `test/r_i.png`, `file_path` without the extension as in the real
/// datasets), test cameras between the training ones.
pub(super) fn write_scene(dir: &Path, n_train: usize, n_test: usize, size: u32) {
    for (split, n, phase) in [("train", n_train, 0.0), ("test", n_test, 1.3)] {
        std::fs::create_dir_all(dir.join(split)).unwrap();
        let frames: Vec<Value> = (0..n)
            .map(|i| {
                let cam = camera(i, n, phase, size);
                photo(&cam)
                    .save(dir.join(format!("{split}/r_{i}.png")))
                    .unwrap();
                json!({"file_path": format!("./{split}/r_{i}"), "rotation": 0.1,
                       "transform_matrix": rows(&cam)})
            })
            .collect();
        write_json(
            &dir.join(format!("transforms_{split}.json")),
            &json!({"camera_angle_x": FOV, "frames": frames}),
        );
    }
}

pub(super) fn write_json(path: &Path, v: &Value) {
    std::fs::write(path, serde_json::to_vec_pretty(v).unwrap()).unwrap();
}

pub(super) fn read_json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

pub(super) fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

pub(super) fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The last line of stdout as JSON.
pub(super) fn summary(o: &Output) -> Value {
    let out = stdout(o);
    let last = out.trim().lines().last().unwrap_or_default();
    serde_json::from_str(last).unwrap_or_else(|e| panic!("{e}: not JSON: {out}"))
}

/// The mean PSNR of an all-white picture (an empty model) over the test photos of `dir`.
pub(super) fn empty_model_psnr(dir: &Path) -> f64 {
    let ds = diffsvg::volume::dataset::Dataset::load(dir, 1).unwrap();
    let sum: f64 = ds
        .test
        .iter()
        .map(|v| diffsvg::volume::metrics::psnr(&vec![[1.0; 3]; v.rgb.len()], &v.rgb))
        .sum();
    sum / ds.test.len() as f64
}

// ---------------------------------------------------------------------------------------
// End to end

/// Training views, test views, image size and iterations of the end-to-end test.
const TRAIN: usize = 40;
const TEST: usize = 5;
const SIZE: u32 = 32;
const ITERS: &str = "300";
/// The held-out PSNR a working pipeline must reach. Measured: 36.8 dB (SH degree 1; 33–37
/// dB over seeds, SH degrees 0–2 and test camera sets); an empty model scores 9.6 dB,
/// photos off by one pixel 29.3 dB, and 20 training views instead of 40 (too few: the grid
/// overfits) 24–32 dB.
const MIN_TEST_PSNR: f64 = 30.0;

#[test]
fn recon_voxel_then_view_reproduce_a_synthetic_scene() {
    let dir = scratch("volume_e2e");
    let scene = dir.join("scene");
    write_scene(&scene, TRAIN, TEST, SIZE);
    let model = dir.join("out/model.vox");

    let t0 = std::time::Instant::now();
    let r = diffsvg(&[
        "recon",
        "voxel",
        "--scene",
        s(&scene),
        "-o",
        s(&model),
        "--res",
        "32",
        "--iters",
        ITERS,
        "--batch",
        "2048",
        "--degree",
        "1",
        "--json",
    ]);
    let recon_s = t0.elapsed().as_secs_f64();
    assert!(r.status.success(), "{}", stderr(&r));
    assert!(!stderr(&r).contains("panicked"), "{}", stderr(&r));
    let sum = summary(&r);
    println!("recon voxel ({recon_s:.1} s): {sum}");
    assert_eq!(sum["done"], json!(true));
    assert_eq!(sum["stopped"], json!(false));
    assert_eq!(sum["iterations"], json!(300));
    assert_eq!(sum["res"], json!(32));
    let test_psnr = sum["test_psnr"].as_f64().expect("test_psnr is a number");
    let empty = empty_model_psnr(&scene);
    println!("held-out PSNR {test_psnr:.2} dB (an empty model: {empty:.2} dB)");
    assert!(
        test_psnr >= MIN_TEST_PSNR,
        "held-out PSNR {test_psnr:.2} dB < {MIN_TEST_PSNR} dB"
    );
    assert!(
        empty < 15.0,
        "the photos show the spheres: {empty} dB for white"
    );
    // Progress lines before the summary.
    let progress = stdout(&r).lines().count() - 1;
    assert!(progress >= 300 / 50, "{}", stdout(&r));

    // The model loads and is a 32³ grid; the log's last row is the final iteration with
    // the same test PSNR.
    assert!(model.is_file());
    let grid = diffsvg::volume::voxel::load(&model).unwrap();
    assert_eq!((grid.res(), grid.degree()), (32, 1));
    let log = std::fs::read_to_string(dir.join("out/model.log.csv")).unwrap();
    let mut lines = log.lines();
    assert_eq!(
        lines.next(),
        Some("iteration,seconds,res,allocated,batch_psnr,test_psnr")
    );
    let last: Vec<&str> = lines.last().expect("a final row").split(',').collect();
    assert_eq!(last.len(), 6, "{log}");
    assert_eq!((last[0], last[2]), (ITERS, "32"), "{log}");
    let logged: f64 = last[5].parse().unwrap();
    assert!((logged - test_psnr).abs() < 1e-3, "{log}");
    let leftovers: Vec<_> = std::fs::read_dir(dir.join("out"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != "model.vox" && n != "model.log.csv")
        .collect();
    assert!(leftovers.is_empty(), "stray files: {leftovers:?}");

    // View the test split and an orbit.
    let views = dir.join("views");
    let t0 = std::time::Instant::now();
    let r = diffsvg(&[
        "view",
        s(&model),
        "--scene",
        s(&scene),
        "-o",
        s(&views),
        "--orbit",
        "4",
        "--json",
    ]);
    let view_s = t0.elapsed().as_secs_f64();
    assert!(r.status.success(), "{}", stderr(&r));
    let sum = summary(&r);
    println!("view ({view_s:.1} s): {sum}");
    assert_eq!(sum["views"], json!(TEST));
    assert_eq!(sum["orbit"], json!(4));

    let csv = std::fs::read_to_string(views.join("metrics.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(rows[0], ["view", "psnr", "ssim", "ms"], "{csv}");
    assert_eq!(rows.len(), 1 + TEST + 1, "{csv}");
    let mut sum_psnr = 0.0;
    for (i, row) in rows[1..=TEST].iter().enumerate() {
        assert_eq!(row[0], format!("test/r_{i}"), "{csv}");
        let p: f64 = row[1].parse().unwrap();
        let q: f64 = row[2].parse().unwrap();
        assert!(p >= MIN_TEST_PSNR - 3.0 && q > 0.5 && q <= 1.0, "{csv}");
        sum_psnr += p;
        // rendering | photo
        let pair = image::open(views.join(format!("r_{i}.png"))).unwrap();
        assert!(pair.width() >= 2 * SIZE && pair.height() >= SIZE);
    }
    let mean = rows[TEST + 1].clone();
    assert_eq!(mean[0], "mean", "{csv}");
    let mean_psnr: f64 = mean[1].parse().unwrap();
    assert!((mean_psnr - sum_psnr / TEST as f64).abs() < 2e-3, "{csv}");
    assert!(
        (mean_psnr - test_psnr).abs() <= 0.1,
        "view {mean_psnr} vs recon {test_psnr}"
    );
    assert!((sum["psnr"].as_f64().unwrap() - mean_psnr).abs() < 1e-3);

    // Orbit frames see the spheres (colored pixels, not only background).
    for i in 0..4 {
        let f = image::open(views.join(format!("orbit-{i:03}.png")))
            .unwrap()
            .to_rgb8();
        assert_eq!(f.dimensions(), (SIZE, SIZE));
        let colored = f
            .pixels()
            .filter(|p| p.0.iter().max().unwrap() - p.0.iter().min().unwrap() > 80)
            .count();
        assert!(colored >= 20, "orbit frame {i}: {colored} colored pixels");
    }
    assert!(!views.join("orbit-004.png").exists());
    let gif = std::fs::File::open(views.join("orbit.gif")).unwrap();
    let frames = image::AnimationDecoder::into_frames(
        image::codecs::gif::GifDecoder::new(std::io::BufReader::new(gif)).unwrap(),
    )
    .count();
    assert_eq!(frames, 4);
    assert!(image::open(views.join("orbit.png")).is_ok());
    println!("recon {recon_s:.1} s, view {view_s:.1} s");
}

// ---------------------------------------------------------------------------------------
// Bad input

/// A small valid scene (2 train and 1 test views of 8×8) in `dir/name`.
pub(super) fn small_scene(dir: &Path, name: &str) -> PathBuf {
    let scene = dir.join(name);
    write_scene(&scene, 2, 1, 8);
    scene
}

/// Asserts a clean failure: exit status 2, no panic, stderr naming every needle, and no
/// file at all in `out_dir` (no model, log or temporary file).
pub(super) fn assert_clean_failure(o: &Output, needles: &[&str], out_dir: &Path) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(2), "stderr: {err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.starts_with("error: "), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "one line expected: {err}");
    for n in needles {
        assert!(err.contains(n), "{err:?} should contain {n:?}");
    }
    if out_dir.exists() {
        let files: Vec<_> = std::fs::read_dir(out_dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert!(files.is_empty(), "files left behind: {files:?} ({err})");
    }
}

/// `recon voxel` of `scene` with extra flags (and a tiny grid and run unless given),
/// writing into `out/model.vox`.
fn recon(scene: &Path, out: &Path, extra: &[&str]) -> Output {
    let model = out.join("model.vox");
    let mut args = vec!["recon", "voxel", "--scene", s(scene), "-o", s(&model)];
    args.extend_from_slice(extra);
    // Small defaults for the flags not given.
    for (flag, value) in [("--res", "8"), ("--iters", "2"), ("--batch", "16")] {
        if !extra.contains(&flag) {
            args.extend([flag, value]);
        }
    }
    diffsvg(&args)
}

#[test]
fn recon_voxel_scores_the_test_views_aligned_when_asked() {
    let dir = scratch("volume_align_test_poses");
    let scene = small_scene(&dir, "scene");
    let plain = summary(&recon(&scene, &dir.join("a"), &["--json"]));
    assert_eq!(plain["test_psnr_aligned"], json!(null), "{plain}");
    let r = recon(&scene, &dir.join("b"), &["--json", "--align-test-poses"]);
    assert!(r.status.success(), "{}", stderr(&r));
    let sum = summary(&r);
    let (held, aligned) = (
        sum["test_psnr"].as_f64().unwrap(),
        sum["test_psnr_aligned"]
            .as_f64()
            .expect("a number with the flag"),
    );
    let turn = sum["test_pose_turn"].as_f64().unwrap();
    // The same model as without the flag; its test camera aligned to it only gains.
    assert_eq!(sum["test_psnr"], plain["test_psnr"], "{sum}");
    assert!(aligned >= held - 0.05, "{held} dB → {aligned} dB");
    assert!(turn.is_finite() && turn >= 0.0, "{sum}");
    // The summary line says it.
    let r = recon(&scene, &dir.join("c"), &["--align-test-poses"]);
    assert!(
        stdout(&r).contains("with the test cameras aligned"),
        "{}",
        stdout(&r)
    );
}

#[test]
fn recon_rejects_bad_scenes_cleanly() {
    let dir = scratch("volume_bad_scenes");
    let out = dir.join("out");

    // The small scene itself is fine.
    let good = small_scene(&dir, "good");
    let r = recon(&good, &dir.join("good-out"), &[]);
    assert!(r.status.success(), "{}", stderr(&r));
    assert!(dir.join("good-out/model.vox").is_file());

    // Missing scene folder.
    let missing = dir.join("no-such-scene");
    assert_clean_failure(
        &recon(&missing, &out, &[]),
        &["no-such-scene", "does not exist"],
        &out,
    );

    // A folder without transforms files.
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    assert_clean_failure(
        &recon(&empty, &out, &[]),
        &["empty", "transforms_train.json", "transforms.json"],
        &out,
    );

    // Malformed JSON.
    let scene = small_scene(&dir, "malformed");
    std::fs::write(scene.join("transforms_train.json"), "{\"frames\": [").unwrap();
    assert_clean_failure(
        &recon(&scene, &out, &[]),
        &["transforms_train.json", "malformed JSON"],
        &out,
    );

    // A frame whose image is missing (NeRF-synthetic needs them all).
    let scene = small_scene(&dir, "missing-image");
    std::fs::remove_file(scene.join("train/r_1.png")).unwrap();
    assert_clean_failure(
        &recon(&scene, &out, &[]),
        &["train/r_1", "transforms_train.json", "does not exist"],
        &out,
    );

    // An unreadable image.
    let scene = small_scene(&dir, "garbage-image");
    std::fs::write(scene.join("test/r_0.png"), b"not a png").unwrap();
    assert_clean_failure(
        &recon(&scene, &out, &[]),
        &["test/r_0.png", "not a readable"],
        &out,
    );

    // Images of mixed sizes.
    let scene = small_scene(&dir, "mixed-sizes");
    image::RgbaImage::new(10, 8)
        .save(scene.join("train/r_1.png"))
        .unwrap();
    assert_clean_failure(
        &recon(&scene, &out, &[]),
        &["train/r_1.png", "10×8", "8×8", "same size"],
        &out,
    );

    // Degenerate poses: an all-zero rotation, a reflection, an entry beyond f64 (JSON has
    // no NaN or infinity; `1e999` replaces the marker 12345.5), a non-numeric entry.
    let cases: [(&str, Value, &[&str]); 4] = [
        (
            "zero-rotation",
            json!([[0, 0, 0, 1], [0, 0, 0, 2], [0, 0, 0, 3], [0, 0, 0, 1]]),
            &["frame 1 (./train/r_1)", "degenerate pose", "orthonormal"],
        ),
        (
            "reflection",
            json!([[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]]),
            &["frame 1 (./train/r_1)", "reflection"],
        ),
        (
            "overflow",
            json!([[1, 0, 0, 0], [0, 1, 0, 12345.5], [0, 0, 1, 3], [0, 0, 0, 1]]),
            &["transforms_train.json", "malformed JSON", "out of range"],
        ),
        (
            "string",
            json!([[1, 0, 0, 0], [0, 1, 0, "NaN"], [0, 0, 1, 3], [0, 0, 0, 1]]),
            &["frame 1 (./train/r_1)", "transform_matrix must be 4×4"],
        ),
    ];
    for (name, matrix, needles) in cases {
        let scene = small_scene(&dir, name);
        let path = scene.join("transforms_train.json");
        let mut j = read_json(&path);
        j["frames"][1]["transform_matrix"] = matrix;
        let text = serde_json::to_string_pretty(&j).unwrap();
        std::fs::write(&path, text.replace("12345.5", "1e999")).unwrap();
        let r = recon(&scene, &out, &[]);
        println!("{name}: {}", stderr(&r).trim());
        assert_clean_failure(&r, needles, &out);
    }
}

#[test]
fn recon_rejects_bad_flags_cleanly() {
    let dir = scratch("volume_bad_flags");
    let scene = small_scene(&dir, "scene");
    let out = dir.join("out");
    for (flags, needles) in [
        (&["--res", "0"][..], &["--res 0", "between 8"][..]),
        (&["--res", "4096"], &["--res 4096", "between 8"]),
        (&["--degree", "4"], &["--degree 4", "0 to 3"]),
        (&["--downscale", "0"], &["--downscale", "at least 1"]),
        (&["--iters", "0"], &["--iters", "at least 1"]),
        (&["--bound=-1"], &["--bound -1", "positive"]),
        (&["--downscale", "9"], &["downscale 9", "8×8"]),
    ] {
        let r = recon(&scene, &out, flags);
        println!("{flags:?}: {}", stderr(&r).trim());
        assert_clean_failure(&r, needles, &out);
    }
    // Not a .vox output.
    let r = diffsvg(&[
        "recon",
        "voxel",
        "--scene",
        s(&scene),
        "-o",
        s(&out.join("model.png")),
    ]);
    assert_clean_failure(&r, &["model.png", ".vox"], &out);
}

#[test]
fn view_rejects_bad_models_and_flags_cleanly() {
    use diffsvg::volume::voxel::{Grid, save};
    let dir = scratch("volume_bad_view");
    let scene = small_scene(&dir, "scene");
    let out = dir.join("views");
    let view = |model: &Path, extra: &[&str]| {
        let mut args = vec!["view", s(model), "--scene", s(&scene), "-o", s(&out)];
        args.extend_from_slice(extra);
        diffsvg(&args)
    };

    // A valid model renders.
    let model = dir.join("good.vox");
    save(
        &Grid::dense(Vec3::splat(-1.0), Vec3::splat(1.0), 8, 1, 0.5),
        &model,
    )
    .unwrap();
    let r = view(&model, &[]);
    assert!(r.status.success(), "{}", stderr(&r));
    assert!(out.join("metrics.csv").is_file() && out.join("r_0.png").is_file());
    std::fs::remove_dir_all(&out).unwrap();

    // A missing model.
    let missing = dir.join("missing.vox");
    assert_clean_failure(&view(&missing, &[]), &["missing.vox"], &out);
    assert!(!out.exists());

    // Corrupt models: garbage, the right header with garbage after it, a valid file cut
    // short, a future version.
    let bytes = std::fs::read(&model).unwrap();
    let mut future = bytes.clone();
    future[8..12].copy_from_slice(&7u32.to_le_bytes());
    let mut header_only = b"DSVOXGRD".to_vec();
    header_only.extend_from_slice(&1u32.to_le_bytes());
    header_only.extend_from_slice(b"garbage");
    let cases: [(&str, Vec<u8>, &[&str]); 5] = [
        ("garbage.vox", b"hello, world".to_vec(), &["DSVOXGRD"]),
        ("empty.vox", Vec::new(), &["DSVOXGRD"]),
        ("header.vox", header_only, &["truncated"]),
        (
            "cut.vox",
            bytes[..bytes.len() - 10].to_vec(),
            &["size", "expected"],
        ),
        ("future.vox", future, &["version 7"]),
    ];
    for (name, data, needles) in cases {
        let p = dir.join(name);
        std::fs::write(&p, data).unwrap();
        let r = view(&p, &["--orbit", "2"]);
        println!("{name}: {}", stderr(&r).trim());
        let mut all = vec![name];
        all.extend_from_slice(needles);
        assert_clean_failure(&r, &all, &out);
        assert!(!out.exists());
    }

    // Bad flags.
    assert_clean_failure(
        &view(&model, &["--split", "bogus"]),
        &["'bogus' for '--split", "possible values: test, train"],
        &out,
    );
    assert_clean_failure(
        &diffsvg(&["view", s(&model), "-o", s(&out)]),
        &["nothing to render"],
        &out,
    );
    // A scene that does not load.
    let r = diffsvg(&[
        "view",
        s(&model),
        "--scene",
        s(&dir.join("no-such-scene")),
        "-o",
        s(&out),
    ]);
    assert_clean_failure(&r, &["no-such-scene", "does not exist"], &out);
}

/// `view --step` below the renderer's minimum of 0.01 voxels (or NaN) is refused like
/// `recon voxel --step 0`, and so are `--downscale 0` and an orbit looking straight down
/// its up vector.
#[test]
fn view_rejects_bad_render_flags_cleanly() {
    use diffsvg::volume::voxel::{Grid, save};
    let dir = scratch("volume_bad_step");
    let model = dir.join("model.vox");
    save(
        &Grid::dense(Vec3::splat(-1.0), Vec3::splat(1.0), 8, 1, 0.5),
        &model,
    )
    .unwrap();
    let out = dir.join("views");
    // (flag, value, what the message must name); the last looks straight down the up
    // vector and is refused before anything is written.
    let cases = [
        ("--step", "0", vec!["step", "0"]),
        ("--step", "0.001", vec!["step", "0.001"]),
        ("--step", "NaN", vec!["step", "NaN"]),
        ("--downscale", "0", vec!["--downscale"]),
        ("--elevation", "90", vec!["orbit", "parallel"]),
    ];
    for (flag, value, needles) in cases {
        let args = [
            "view",
            s(&model),
            "--orbit",
            "2",
            "-o",
            s(&out),
            flag,
            value,
        ];
        assert_clean_failure(&diffsvg(&args), &needles, &out);
    }
}

/// `bench voxel` runs on its own synthetic scene and reports both grids; the sparse one
/// holds less (speeds are printed, never asserted).
#[test]
fn bench_voxel_reports_sparse_and_dense_grids() {
    let r = diffsvg(&[
        "bench",
        "voxel",
        "--res",
        "16",
        "--size",
        "16",
        "--views",
        "2",
        "--iters",
        "2",
        "--runs",
        "1",
        "--threads",
        "1",
    ]);
    assert!(r.status.success(), "{}", stderr(&r));
    let out = stdout(&r);
    let row = |name: &str| -> Vec<String> {
        let line = out
            .lines()
            .find(|l| l.starts_with(&format!("| {name} |")))
            .unwrap_or_else(|| panic!("no {name} row in {out}"));
        line.split('|').map(|c| c.trim().to_string()).collect()
    };
    let (sparse, dense) = (row("sparse"), row("dense"));
    let allocated = |r: &[String]| r[3].parse::<usize>().unwrap();
    assert_eq!(allocated(&dense), 17 * 17 * 17);
    assert!(allocated(&sparse) < allocated(&dense), "{out}");
    for r in [&sparse, &dense] {
        for c in &r[5..7] {
            let v: f64 = c.parse().unwrap();
            assert!(v.is_finite() && v > 0.0, "{out}");
        }
    }
    assert!(out.contains("sparse/dense speed"), "{out}");
}

/// `bench splat` on gsplat's garden fixture: one workload of 3 views at 648×420, each with
/// Gaussians in view and positive forward and backward times (never compared with
/// anything).
#[test]
fn bench_splat_times_the_garden_views() {
    let Some(data) = shared_data("bench_splat_times_the_garden_views") else {
        return;
    };
    let garden = data.join("scenes/gsplat_test_garden/test_garden.npz");
    if !garden.is_file() {
        skip(
            "bench_splat_times_the_garden_views",
            &format!("{} not found", garden.display()),
        );
        return;
    }
    let r = diffsvg(&[
        "bench",
        "splat",
        "--garden",
        s(&garden),
        "--runs",
        "1",
        "--threads",
        "1",
        "--json",
    ]);
    assert!(r.status.success(), "{}", stderr(&r));
    let out = stdout(&r);
    let j: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
    assert_eq!(j["runs"], 1);
    let workloads = j["workloads"].as_array().unwrap();
    assert_eq!(workloads.len(), 1, "{out}");
    let w = &workloads[0];
    assert_eq!(w["name"], "garden");
    let n = w["gaussians"].as_u64().unwrap();
    assert!(n > 100_000, "{out}");
    let views = w["views"].as_array().unwrap();
    assert_eq!(views.len(), 3, "{out}");
    for v in views {
        assert_eq!(
            (v["width"].as_u64(), v["height"].as_u64()),
            (Some(648), Some(420))
        );
        let visible = v["visible"].as_u64().unwrap();
        assert!(visible > 0 && visible <= n, "{out}");
        let timings = v["timings"].as_array().unwrap();
        assert_eq!(timings.len(), 1, "{out}");
        assert_eq!(timings[0]["threads"], 1);
        for key in ["forward_ms", "backward_ms"] {
            let ms = timings[0][key].as_f64().unwrap();
            assert!(ms.is_finite() && ms > 0.0, "{key}: {out}");
        }
    }
}

/// `bench splat --model` on a tiny hand-made model: 3 orbit views of 200×200 without
/// `--scene`, the scene's test view with it; every view sees Gaussians and has positive
/// times at each thread count.
#[test]
fn bench_splat_times_a_model() {
    use diffsvg::volume::splat::{Gaussians, save};
    let dir = scratch("bench-splat-model");
    // 27 Gaussians of SH degree 1 on a grid inside the synthetic scene's spheres.
    let mut g = Gaussians::new(1);
    for i in 0..27 {
        let p = [i % 3, i / 3 % 3, i / 9].map(|c| (c as f32 - 1.0) * 0.3);
        let sh: Vec<f32> = (0..12).map(|k| ((i + k) % 5) as f32 * 0.1 - 0.2).collect();
        g.push(p, [-2.5, -2.0, -3.0], [1.0, 0.1, -0.2, 0.3], 1.0, &sh);
    }
    let model = dir.join("tiny.ply");
    save(&g, &model).unwrap();
    let scene = small_scene(&dir, "scene");
    let run = |extra: &[&str]| {
        let mut args = vec!["bench", "splat", "--no-garden", "--model", s(&model)];
        args.extend_from_slice(&["--runs", "2", "--threads", "1,2", "--json"]);
        args.extend_from_slice(extra);
        let r = diffsvg(&args);
        assert!(r.status.success(), "{}", stderr(&r));
        let out = stdout(&r);
        let j: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
        let workloads = j["workloads"].as_array().unwrap();
        assert_eq!(workloads.len(), 1, "{out}");
        let w = &workloads[0];
        assert_eq!(w["name"], s(&model), "{out}");
        assert_eq!(
            (w["gaussians"].as_u64(), w["sh_degree"].as_u64()),
            (Some(27), Some(1))
        );
        let views = w["views"].as_array().unwrap().clone();
        for v in &views {
            let visible = v["visible"].as_u64().unwrap();
            assert!(visible > 0 && visible <= 27, "{out}");
            let timings = v["timings"].as_array().unwrap();
            let threads: Vec<_> = timings.iter().map(|t| t["threads"].as_u64()).collect();
            assert_eq!(threads, [Some(1), Some(2)], "{out}");
            for t in timings {
                for key in ["forward_ms", "backward_ms"] {
                    let ms = t[key].as_f64().unwrap();
                    assert!(ms.is_finite() && ms > 0.0, "{key}: {out}");
                }
            }
        }
        views
    };
    let orbit = run(&[]);
    assert_eq!(orbit.len(), 3);
    for (i, v) in orbit.iter().enumerate() {
        assert_eq!(v["name"], format!("orbit {i}"));
        assert_eq!(
            (v["width"].as_u64(), v["height"].as_u64()),
            (Some(200), Some(200))
        );
    }
    let test = run(&["--scene", s(&scene)]);
    assert_eq!(test.len(), 1);
    assert_eq!(
        (test[0]["width"].as_u64(), test[0]["height"].as_u64()),
        (Some(8), Some(8))
    );
    // The table has both columns.
    let r = diffsvg(&[
        "bench",
        "splat",
        "--no-garden",
        "--model",
        s(&model),
        "--runs",
        "1",
    ]);
    assert!(r.status.success(), "{}", stderr(&r));
    let out = stdout(&r);
    assert!(out.contains("| forward (ms) | backward (ms) |"), "{out}");
    assert_eq!(
        out.lines().filter(|l| l.contains("orbit")).count(),
        6,
        "{out}"
    );
}

/// Without the garden file (and no `--model`), `bench splat` fails with one line naming it.
#[test]
fn bench_splat_names_a_missing_garden() {
    let dir = scratch("bench-splat-missing");
    let missing = dir.join("no-such-garden.npz");
    let r = diffsvg(&["bench", "splat", "--garden", s(&missing), "--runs", "1"]);
    let err = stderr(&r);
    assert_eq!(r.status.code(), Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("no-such-garden.npz") && err.contains("not found"),
        "{err}"
    );
    assert!(stdout(&r).is_empty());
}

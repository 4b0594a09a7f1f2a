//! Regression tests for issue 13's 3D input cases (item 11 and what the fuzzer found):
//! absurd cameras and boxes, paths that leave the scene folder, unbounded reads, scene
//! size limits. Each is refused with one line naming the file (or flag) and the field,
//! exit status 2, and no model written.

use std::path::{Path, PathBuf};
use std::process::Output;

use serde_json::{Value, json};

use super::common::{assert_fails, diffsvg, s, scratch};

/// Row-major camera-to-world matrix of a camera on a circle of radius 4 at angle `a`,
/// looking at the origin (OpenGL axes: +Y up, looking down −Z).
fn pose(a: f64) -> Value {
    let eye = [4.0 * a.cos(), 4.0 * a.sin(), 1.0];
    let n = |v: [f64; 3]| {
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / l, v[1] / l, v[2] / l]
    };
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let f = n([-eye[0], -eye[1], -eye[2]]);
    let r = n(cross(f, [0.0, 0.0, 1.0]));
    let u = cross(r, f);
    json!([
        [r[0], u[0], -f[0], eye[0]],
        [r[1], u[1], -f[1], eye[1]],
        [r[2], u[2], -f[2], eye[2]],
        [0, 0, 0, 1]
    ])
}

fn png(path: &Path, w: u32, h: u32) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::RgbImage::from_fn(w, h, |x, y| {
        image::Rgb([(x * 30) as u8, (y * 30) as u8, 90])
    })
    .save(path)
    .unwrap();
}

/// A NeRF-synthetic folder `dir/scene` (2 train views, 1 test view, 8×8) whose
/// transforms files get `extra` merged into their top level.
fn scene(dir: &Path, extra: Value) -> PathBuf {
    let sc = dir.join("scene");
    for (split, n, off) in [("train", 2, 0.0), ("test", 1, 2.0)] {
        let frames: Vec<Value> = (0..n)
            .map(|i| {
                png(&sc.join(format!("{split}/r_{i}.png")), 8, 8);
                json!({"file_path": format!("./{split}/r_{i}"),
                       "transform_matrix": pose(0.7 * (i as f64 + off))})
            })
            .collect();
        let mut top = json!({"camera_angle_x": 0.69, "frames": frames});
        for (k, v) in extra.as_object().unwrap() {
            top[k] = v.clone();
        }
        write_json(&sc.join(format!("transforms_{split}.json")), &top);
    }
    sc
}

fn write_json(path: &Path, v: &Value) {
    std::fs::write(path, serde_json::to_vec(v).unwrap()).unwrap();
}

/// `recon voxel` on `scene`, writing `dir/out/m.vox`, with `extra` flags.
fn recon(scene: &Path, model: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "recon",
        "voxel",
        "--scene",
        s(scene),
        "-o",
        s(model),
        "--iters",
        "2",
        "--res",
        "8",
        "--batch",
        "64",
        "--quiet",
    ];
    args.extend_from_slice(extra);
    diffsvg(&args)
}

#[test]
fn camera_angle_x_1e_minus_30_is_refused() {
    let dir = scratch("regress_volume_angle");
    // A good model first, for `view`.
    let good = scene(&dir.join("good"), json!({}));
    let model = dir.join("good/m.vox");
    let o = recon(&good, &model, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let sc = scene(&dir, json!({"camera_angle_x": 1e-30}));
    let out = dir.join("out/m.vox");
    let o = recon(&sc, &out, &[]);
    // (serde_json reads 1e-30 as 9.999999999999999e-31.)
    assert_fails(&o, "transforms_train.json", "camera_angle_x = ", &out);
    assert!(String::from_utf8_lossy(&o.stderr).contains("e-31 must be between"));
    // `view` reads the scene through the same loader.
    let views = dir.join("views");
    let o = diffsvg(&["view", s(&model), "--scene", s(&sc), "-o", s(&views)]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("camera_angle_x = "), "{err}");
    assert!(!views.exists(), "view wrote into {}", views.display());
    // A focal length of 10³⁰ px given directly is refused too, naming its key.
    let sc = scene(&dir, json!({"fl_x": 1e30}));
    let o = recon(&sc, &out, &[]);
    assert_fails(&o, "transforms_train.json", "fl_x = 1", &out);
}

#[test]
fn k1_1e30_is_refused() {
    let dir = scratch("regress_volume_k1");
    let out = dir.join("out/m.vox");
    let sc = scene(&dir, json!({"k1": 1e30}));
    let o = recon(&sc, &out, &[]);
    assert_fails(&o, "transforms_train.json", "k1 = ", &out);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("outside [-10, 10]"), "{err}");
    // Within the bounds but folding over inside a wide image: no ray for some pixels.
    let sc = scene(&dir, json!({"k1": -1.0, "camera_angle_x": 2.5}));
    let o = recon(&sc, &out, &[]);
    assert_fails(&o, "transforms_train.json", "folds over", &out);
    // Ordinary lens distortion still loads (the fox dataset's coefficients).
    let sc = scene(
        &dir,
        json!({"k1": 0.0578421, "k2": -0.0805099, "p1": -0.000980296, "p2": 0.00015575}),
    );
    let o = recon(&sc, &out, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn bound_1e30_is_refused() {
    let dir = scratch("regress_volume_bound");
    let sc = scene(&dir, json!({}));
    let out = dir.join("out/m.vox");
    for b in ["--bound=1e30", "--bound=1e-30", "--bound=3.4e38"] {
        let o = recon(&sc, &out, &[b]);
        assert_fails(&o, "--bound", "median distance", &out);
    }
    // A sensible box still works.
    let o = recon(&sc, &out, &["--bound=1.5"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Found by the fuzzer: `--bound 1e-30` collapsed the box in f32 and panicked in
/// `Grid::dense` (exit 101).
#[test]
fn bound_1e_minus_30_does_not_panic() {
    let dir = scratch("regress_volume_bound_tiny");
    let sc = scene(&dir, json!({}));
    let out = dir.join("out/m.vox");
    let o = recon(&sc, &out, &["--bound=1e-30"]);
    assert_fails(&o, "--bound", "between", &out);
}

#[test]
fn file_path_of_etc_passwd_is_refused() {
    let dir = scratch("regress_volume_passwd");
    let sc = scene(&dir, json!({}));
    let out = dir.join("out/m.vox");
    let json_path = sc.join("transforms_train.json");
    let mut t: Value = serde_json::from_slice(&std::fs::read(&json_path).unwrap()).unwrap();
    for evil in [
        "../../../../etc/passwd",
        "/etc/passwd",
        "train/../../scene-elsewhere/r_0",
    ] {
        t["frames"][1]["file_path"] = json!(evil);
        write_json(&json_path, &t);
        let o = recon(&sc, &out, &[]);
        assert_fails(
            &o,
            "transforms_train.json",
            "outside the dataset folder",
            &out,
        );
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("frame 1"), "{err}");
    }
    // A symbolic link inside the folder that leads out of it is refused as well.
    png(&dir.join("outside.png"), 8, 8);
    std::fs::remove_file(sc.join("train/r_1.png")).unwrap();
    std::os::unix::fs::symlink(dir.join("outside.png"), sc.join("train/r_1.png")).unwrap();
    t["frames"][1]["file_path"] = json!("./train/r_1");
    write_json(&json_path, &t);
    let o = recon(&sc, &out, &[]);
    assert_fails(
        &o,
        "transforms_train.json",
        "outside the dataset folder",
        &out,
    );
}

#[test]
fn transforms_json_of_dev_zero_is_bounded() {
    let dir = scratch("regress_volume_dev_zero");
    let out = dir.join("out/m.vox");
    // instant-ngp's transforms.json, and NeRF-synthetic's train file, as /dev/zero.
    for name in ["transforms.json", "transforms_train.json"] {
        let sc = dir.join(format!("scene-{name}"));
        std::fs::create_dir_all(&sc).unwrap();
        std::os::unix::fs::symlink("/dev/zero", sc.join(name)).unwrap();
        let o = recon(&sc, &out, &[]);
        assert_fails(&o, "scene", "transforms", &out);
    }
    // A regular transforms file past the 64 MiB limit is refused before it is read (a
    // sparse file: no disk used).
    let sc = dir.join("scene-big");
    std::fs::create_dir_all(&sc).unwrap();
    let f = std::fs::File::create(sc.join("transforms.json")).unwrap();
    f.set_len((64 << 20) + 1).unwrap();
    let o = recon(&sc, &out, &[]);
    assert_fails(&o, "transforms.json", "more than the limit", &out);
}

#[test]
fn ten_thousand_and_one_frames_are_refused() {
    let dir = scratch("regress_volume_frames");
    let sc = dir.join("scene");
    png(&sc.join("images/a.png"), 8, 8);
    let frames: Vec<Value> = (0..10_001)
        .map(|i| json!({"file_path": "images/a.png", "transform_matrix": pose(i as f64)}))
        .collect();
    write_json(
        &sc.join("transforms.json"),
        &json!({"fl_x": 10, "frames": frames}),
    );
    let out = dir.join("out/m.vox");
    let o = recon(&sc, &out, &[]);
    assert_fails(&o, "transforms.json", "10001 frames", &out);
}

/// Sets a PNG's header size to `w × h` (with a valid CRC), leaving its data as it was.
fn claim_size(path: &Path, w: u32, h: u32) {
    let mut b = std::fs::read(path).unwrap();
    assert_eq!(&b[12..16], b"IHDR");
    b[16..20].copy_from_slice(&w.to_be_bytes());
    b[20..24].copy_from_slice(&h.to_be_bytes());
    let mut c = 0xffff_ffffu32;
    for &x in &b[12..29] {
        c ^= x as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xedb8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    b[29..33].copy_from_slice(&(!c).to_be_bytes());
    std::fs::write(path, b).unwrap();
}

#[test]
fn image_header_20000x20000_is_refused_before_decoding() {
    let dir = scratch("regress_volume_huge_image");
    let sc = scene(&dir, json!({}));
    claim_size(&sc.join("train/r_1.png"), 20000, 20000);
    let out = dir.join("out/m.vox");
    // Under 1 GiB of address space: decoding first would need 1.2 GB for the pixels.
    let o = std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 1048576 && exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_diffsvg"))
        .args([
            "recon",
            "voxel",
            "--scene",
            s(&sc),
            "-o",
            s(&out),
            "--iters",
            "2",
            "--res",
            "8",
            "--quiet",
        ])
        .env("MALLOC_ARENA_MAX", "2")
        .output()
        .unwrap();
    assert_fails(&o, "r_1.png", "20000×20000", &out);
}

#[test]
fn dataset_over_the_pixel_budget_is_refused_before_decoding() {
    // Three views whose headers say 4096×4096 (each within the image limit): 5·10⁷
    // pixels together, over the dataset budget; --downscale 2 brings them under it.
    let dir = scratch("regress_volume_budget");
    let sc = scene(&dir, json!({}));
    for p in ["train/r_0.png", "train/r_1.png", "test/r_0.png"] {
        claim_size(&sc.join(p), 4096, 4096);
    }
    let out = dir.join("out/m.vox");
    let o = recon(&sc, &out, &[]);
    assert_fails(&o, "scene", "--downscale", &out);
    // At --downscale 2 the budget holds and the (fake) images fail to decode instead.
    let o = recon(&sc, &out, &["--downscale", "2"]);
    assert_fails(&o, "r_0.png", "not a readable", &out);
}

//! `diffsvg recon splat` and `diffsvg view` of a Gaussian-splatting model end to end: a
//! short run on the synthetic two-sphere scene of [`super::volume`] writes a PLY that
//! loads, saves back bit for bit and renders; a PLY packed by hand in the standard 3DGS
//! layout (degree 0 and degree 3) loads and renders the expected picture; and bad scenes,
//! models and flags fail with one line, exit code 2 and no file left behind.

use std::path::Path;
use std::process::Output;

use diffsvg::glam::{Affine3A, Vec3};
use diffsvg::volume::camera::Camera;
use diffsvg::volume::dataset::Dataset;
use diffsvg::volume::metrics::psnr;
use diffsvg::volume::splat::{self, Gaussians, RenderSettings};
use serde_json::json;

use super::common::{diffsvg, s, scratch};
use super::volume::{
    assert_clean_failure, empty_model_psnr, read_json, small_scene, stderr, stdout, summary,
    write_json, write_scene,
};

/// `recon splat` of `scene` into `out/model.ply` with extra flags (and a tiny run unless
/// given).
fn recon_splat(scene: &Path, out: &Path, extra: &[&str]) -> Output {
    let model = out.join("model.ply");
    let mut args = vec!["recon", "splat", "--scene", s(scene), "-o", s(&model)];
    args.extend_from_slice(extra);
    for (flag, value) in [("--iters", "2"), ("--initial", "50")] {
        if !extra.contains(&flag) {
            args.extend([flag, value]);
        }
    }
    args.push("--quiet");
    diffsvg(&args)
}

/// The names of the files in `dir`, sorted.
fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

// ---------------------------------------------------------------------------------------
// End to end

/// A NeRF-synthetic folder converted to COLMAP (the `to_colmap` example's [`convert`],
/// no points) trains with its `test.txt` as `--test-list` exactly as the folder itself:
/// the same test views, the same sequence of training views, the same random start.
///
/// [`convert`]: diffsvg::volume::colmap::convert
#[test]
fn converted_folder_with_its_test_list_trains_as_the_original() {
    let dir = scratch("splat_cli_converted");
    let scene = dir.join("scene");
    write_scene(&scene, 12, 3, 16);
    let colmap = dir.join("colmap");
    let opts = diffsvg::volume::colmap::Convert {
        points: 0,
        ..Default::default()
    };
    diffsvg::volume::colmap::convert(&scene, &colmap, &opts).unwrap();
    let list = colmap.join(diffsvg::volume::colmap::TEST_LIST);
    let flags = ["--iters", "30", "--initial", "300", "--seed", "4", "--json"];
    let run = |scene: &Path, out: &str, extra: &[&str]| {
        let extra: Vec<&str> = flags.iter().chain(extra).copied().collect();
        let r = recon_splat(scene, &dir.join(out), &extra);
        assert!(r.status.success(), "{}", stderr(&r));
        summary(&r)
    };
    let a = run(&scene, "a", &[]);
    let b = run(&colmap, "b", &["--test-list", s(&list)]);
    let c = run(&colmap, "c", &[]);
    let psnr = |v: &serde_json::Value| v["test_psnr"].as_f64().unwrap();
    println!(
        "test PSNR: {} original, {} converted with test.txt, {} every 8th",
        psnr(&a),
        psnr(&b),
        psnr(&c)
    );
    assert!((psnr(&a) - psnr(&b)).abs() < 1e-3, "{a} vs {b}");
    assert_eq!(a["gaussians"], b["gaussians"]);
    // Without the list the test views are others (every 8th by name).
    assert!((psnr(&a) - psnr(&c)).abs() > 1e-3, "{a} vs {c}");
}

#[test]
fn recon_splat_writes_a_ply_that_round_trips_renders_and_views() {
    let dir = scratch("splat_cli_e2e");
    let scene = dir.join("scene");
    write_scene(&scene, 12, 3, 32);
    let out = dir.join("out");
    let model = out.join("model.ply");

    let t0 = std::time::Instant::now();
    let r = recon_splat(
        &scene,
        &out,
        &[
            "--iters",
            "150",
            "--initial",
            "1500",
            "--max-gaussians",
            "4000",
            "--json",
        ],
    );
    let recon_s = t0.elapsed().as_secs_f64();
    assert!(r.status.success(), "{}", stderr(&r));
    assert!(!stderr(&r).contains("panicked"), "{}", stderr(&r));
    let sum = summary(&r);
    println!("recon splat ({recon_s:.1} s): {sum}");
    assert_eq!(sum["done"], json!(true));
    assert_eq!(sum["stopped"], json!(false));
    assert_eq!(sum["iterations"], json!(150));
    let gaussians = sum["gaussians"].as_u64().expect("gaussians is a number") as usize;
    assert!((1..=4000).contains(&gaussians), "{sum}");
    let test_psnr = sum["test_psnr"].as_f64().expect("test_psnr is a number");
    // Only the model and its log; no temporary file.
    assert_eq!(files_in(&out), ["model.log.csv", "model.ply"]);

    // The PLY loads back (default degree 3: 45 f_rest properties) and `save` of what was
    // loaded writes the very same bytes.
    let g = splat::load(&model).unwrap();
    assert_eq!(g.len(), gaussians);
    assert_eq!(g.sh_degree, 3);
    assert_eq!(g.validate(), Ok(()));
    let bytes = std::fs::read(&model).unwrap();
    let header_end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header = std::str::from_utf8(&bytes[..header_end]).unwrap();
    assert!(
        header.starts_with("ply\nformat binary_little_endian 1.0\n"),
        "{header}"
    );
    assert!(header.contains(&format!("element vertex {gaussians}\n")));
    assert!(header.contains("property float f_rest_44\nproperty float opacity\n"));
    assert_eq!(bytes.len() - header_end, gaussians * 62 * 4);
    let copy = dir.join("copy/model.ply");
    splat::save(&g, &copy).unwrap();
    assert!(
        std::fs::read(&copy).unwrap() == bytes,
        "save(load(file)) is not the same bytes"
    );

    // It renders the test views with finite pixels, at the PSNR `recon` reported.
    let ds = Dataset::load(&scene, 1).unwrap();
    let settings = RenderSettings {
        background: [1.0; 3],
        ..RenderSettings::default()
    };
    let mut own = Vec::new();
    for v in &ds.test {
        let img = splat::render(&g, &v.camera, &settings).unwrap();
        assert_eq!((img.width, img.height), (32, 32));
        assert!(
            img.rgb.iter().flatten().all(|c| c.is_finite()),
            "{}",
            v.name
        );
        own.push(psnr(&img.rgb, &v.rgb).min(99.0));
    }
    let own_mean = own.iter().sum::<f64>() / own.len() as f64;
    assert!(
        (own_mean - test_psnr).abs() < 1e-6,
        "{own_mean} vs {test_psnr}"
    );
    // Better than an empty (all-white) model by a clear margin.
    let empty = empty_model_psnr(&scene);
    println!("held-out PSNR {test_psnr:.2} dB (an empty model: {empty:.2} dB)");
    assert!(
        test_psnr > empty + 5.0,
        "{test_psnr} dB vs {empty} dB empty"
    );

    // `view --scene` renders the held-out views and reports the same PSNR.
    let views = dir.join("views");
    let r = diffsvg(&[
        "view",
        s(&model),
        "--scene",
        s(&scene),
        "-o",
        s(&views),
        "--json",
    ]);
    assert!(r.status.success(), "{}", stderr(&r));
    let sum = summary(&r);
    println!("view: {sum}");
    assert_eq!(sum["views"], json!(3));
    let view_psnr = sum["psnr"].as_f64().unwrap();
    assert!(
        (view_psnr - test_psnr).abs() < 1e-6,
        "{view_psnr} vs {test_psnr}"
    );
    let csv = std::fs::read_to_string(views.join("metrics.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(rows[0], ["view", "psnr", "ssim", "ms"], "{csv}");
    assert_eq!(rows.len(), 1 + 3 + 1, "{csv}");
    for (i, row) in rows[1..=3].iter().enumerate() {
        assert_eq!(row[0], format!("test/r_{i}"), "{csv}");
        let p: f64 = row[1].parse().unwrap();
        assert!((p - own[i]).abs() < 1e-3, "{csv}: {}", own[i]);
        let pair = image::open(views.join(format!("r_{i}.png"))).unwrap();
        assert_eq!((pair.width() >= 64, pair.height()), (true, 32));
    }
    assert_eq!(rows[4][0], "mean", "{csv}");
    // And the plain (non-JSON) report names the PSNR too.
    let r = diffsvg(&["view", s(&model), "--scene", s(&scene), "-o", s(&views)]);
    assert!(r.status.success(), "{}", stderr(&r));
    assert!(
        stdout(&r).contains(&format!("mean PSNR {test_psnr:.2} dB")),
        "{}",
        stdout(&r)
    );
    println!("recon splat {recon_s:.1} s");
}

// ---------------------------------------------------------------------------------------
// A PLY packed by hand

/// `C0` and `C1` of the real SH basis.
const C0: f32 = 0.282_094_8;
const C1: f32 = 0.488_602_5;

/// Where the two Gaussians sit: 4 units in front of [`camera`], 0.55 to either side,
/// projecting to the centers of pixels (10, 12) and (21, 12).
const LEFT: [f32; 3] = [-0.55, -0.05, -4.0];
const RIGHT: [f32; 3] = [0.55, -0.05, -4.0];
/// Background of the hand-made renders.
const BG: [f32; 3] = [0.2, 0.2, 0.2];

/// A 32 × 24 camera at the origin looking down −Z (+Y up), fx = fy = 40.
fn camera() -> Camera {
    Camera::new(32, 24, 40.0, 40.0, 16.0, 12.0, Affine3A::IDENTITY).unwrap()
}

/// The standard property names of a 3DGS PLY with `rest` f_rest properties.
fn standard_names(rest: usize) -> Vec<String> {
    let mut v: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .map(String::from)
    .to_vec();
    v.extend((0..rest).map(|j| format!("f_rest_{j}")));
    v.extend(["opacity", "scale_0", "scale_1", "scale_2"].map(String::from));
    v.extend((0..4).map(|j| format!("rot_{j}")));
    v
}

/// A binary little-endian PLY: the header for `names`, then `records` packed by hand.
fn pack(names: &[String], records: &[Vec<f32>]) -> Vec<u8> {
    let mut h = format!(
        "ply\nformat binary_little_endian 1.0\ncomment packed by hand\nelement vertex {}\n",
        records.len()
    );
    for n in names {
        h += &format!("property float {n}\n");
    }
    h += "end_header\n";
    let mut b = h.into_bytes();
    for r in records {
        assert_eq!(r.len(), names.len());
        for v in r {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    b
}

/// One record in the standard order: σ = 0.1 world units (1 px at depth 4), opacity
/// sigmoid(6), identity rotation, the given DC and f_rest.
fn record(mean: [f32; 3], dc: [f32; 3], rest: &[f32]) -> Vec<f32> {
    let mut r = mean.to_vec();
    r.extend([0.0; 3]); // normals
    r.extend(dc);
    r.extend_from_slice(rest);
    r.push(6.0);
    r.extend([0.1f32.ln(); 3]);
    r.extend([1.0, 0.0, 0.0, 0.0]);
    r
}

/// SH DC of linear color `c`.
fn dc(c: [f32; 3]) -> [f32; 3] {
    c.map(|v| (v - 0.5) / C0)
}

/// Two Gaussians, degree 0: red on the left, green on the right.
fn degree0_ply() -> Vec<u8> {
    pack(
        &standard_names(0),
        &[
            record(LEFT, dc([1.0, 0.0, 0.0]), &[]),
            record(RIGHT, dc([0.0, 1.0, 0.0]), &[]),
        ],
    )
}

/// Two Gaussians, degree 3: red on the left (f_rest all 0); on the right, a DC of black
/// and one higher coefficient, blue's `z` term (`C1·z`, coefficient 2 of blue, which the
/// channel-grouped layout stores as f_rest_{2·15 + 1}), that makes it blue seen from the
/// camera.
fn degree3_ply() -> Vec<u8> {
    let dir = Vec3::from_array(RIGHT).normalize();
    let mut rest = [0.0f32; 45];
    rest[31] = 1.0 / (C1 * dir.z);
    pack(
        &standard_names(45),
        &[
            record(LEFT, dc([1.0, 0.0, 0.0]), &[0.0; 45]),
            record(RIGHT, dc([0.0; 3]), &rest),
        ],
    )
}

/// Asserts pixel `(x, y)` of `rgb` (32 wide) is `want` within `tol`.
fn assert_pixel(rgb: &[[f32; 3]], x: usize, y: usize, want: [f32; 3], tol: f32) {
    let got = rgb[y * 32 + x];
    assert!(
        got.iter().zip(want).all(|(g, w)| (g - w).abs() <= tol),
        "pixel ({x}, {y}) is {got:?}, expected {want:?}"
    );
}

/// Renders `g` and checks the picture: `left` and `right` colors at the projected
/// centers (peak opacity clamped at 0.99 over the background), the background exactly
/// between them and in the corners.
fn check_picture(g: &Gaussians, left: [f32; 3], right: [f32; 3]) {
    let out = splat::render(
        g,
        &camera(),
        &RenderSettings {
            background: BG,
            ..RenderSettings::default()
        },
    )
    .unwrap();
    assert_eq!((out.width, out.height), (32, 24));
    let over = |c: [f32; 3]| [0, 1, 2].map(|i| 0.99 * c[i] + 0.01 * BG[i]);
    assert_pixel(&out.rgb, 10, 12, over(left), 2e-3);
    assert_pixel(&out.rgb, 21, 12, over(right), 2e-3);
    // One pixel off the center: partly covered, still mostly the Gaussian's color.
    for (x, y) in [(9, 12), (11, 12), (10, 11), (10, 13)] {
        let p = out.rgb[y * 32 + x];
        assert!(p[0] > 0.4 && p[0] < 0.9 && p[1] < 0.2, "({x}, {y}): {p:?}");
    }
    // 5 px and more from both centers: exactly the background.
    for (x, y) in [
        (0, 0),
        (31, 0),
        (0, 23),
        (31, 23),
        (15, 12),
        (16, 12),
        (10, 5),
        (21, 19),
    ] {
        assert_eq!(out.rgb[y * 32 + x], BG, "({x}, {y})");
        assert_eq!(out.transmittance[y * 32 + x], 1.0, "({x}, {y})");
    }
    assert!(out.rgb.iter().flatten().all(|v| v.is_finite()));
}

#[test]
fn hand_packed_ply_loads_and_renders_the_expected_picture() {
    let dir = scratch("splat_cli_hand");

    // Degree 0: no f_rest.
    let p0 = dir.join("two-d0.ply");
    std::fs::write(&p0, degree0_ply()).unwrap();
    let g = splat::load(&p0).unwrap();
    assert_eq!((g.len(), g.sh_degree), (2, 0));
    assert_eq!(g.means, vec![LEFT, RIGHT]);
    assert_eq!(g.logit_opacities, vec![6.0, 6.0]);
    assert_eq!(g.rotations, vec![[1.0, 0.0, 0.0, 0.0]; 2]);
    assert_eq!(g.log_scales, vec![[0.1f32.ln(); 3]; 2]);
    let mut sh = dc([1.0, 0.0, 0.0]).to_vec();
    sh.extend(dc([0.0, 1.0, 0.0]));
    assert_eq!(g.sh, sh);
    check_picture(&g, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);

    // Degree 3: the f_rest block grouped by channel.
    let p3 = dir.join("two-d3.ply");
    std::fs::write(&p3, degree3_ply()).unwrap();
    let g = splat::load(&p3).unwrap();
    assert_eq!((g.len(), g.sh_degree), (2, 3));
    assert_eq!(g.sh.len(), 2 * 48);
    // Channel-major in memory (16 coefficients per channel): every higher coefficient is
    // 0 but coefficient 2 of Gaussian 1's blue, which the file held as f_rest_31.
    let z_term = 1.0 / (C1 * Vec3::from_array(RIGHT).normalize().z);
    for i in 0..2 {
        let want_dc = if i == 0 {
            dc([1.0, 0.0, 0.0])
        } else {
            dc([0.0; 3])
        };
        for c in 0..3 {
            let ch = &g.sh[48 * i + 16 * c..48 * i + 16 * (c + 1)];
            assert_eq!(ch[0], want_dc[c], "Gaussian {i}, channel {c}");
            for (k, &v) in ch.iter().enumerate().skip(1) {
                let want = if (i, c, k) == (1, 2, 2) { z_term } else { 0.0 };
                assert_eq!(v, want, "Gaussian {i}, channel {c}, coefficient {k}");
            }
        }
    }
    check_picture(&g, [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]);

    // `view` of the hand-made model runs (an orbit around it) and writes frames.
    let views = dir.join("views");
    let r = diffsvg(&["view", s(&p3), "--orbit", "2", "-o", s(&views), "--json"]);
    assert!(r.status.success(), "{}", stderr(&r));
    assert_eq!(summary(&r)["orbit"], json!(2));
    assert!(views.join("orbit-000.png").is_file() && views.join("orbit.gif").is_file());

    // The same with CRLF header lines, which the PLY reader accepts: `view` takes it for a
    // Gaussian model too (it used to look for "ply\n" only and report a bad voxel grid).
    let bytes = degree3_ply();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header = std::str::from_utf8(&bytes[..end])
        .unwrap()
        .replace('\n', "\r\n");
    let mut crlf = header.into_bytes();
    crlf.extend_from_slice(&bytes[end..]);
    let pc = dir.join("two-d3-crlf.ply");
    std::fs::write(&pc, crlf).unwrap();
    assert_eq!(splat::load(&pc).unwrap(), g);
    let views = dir.join("views-crlf");
    let r = diffsvg(&["view", s(&pc), "--orbit", "2", "-o", s(&views), "--json"]);
    assert!(r.status.success(), "{}", stderr(&r));
    assert_eq!(summary(&r)["orbit"], json!(2));
}

// ---------------------------------------------------------------------------------------
// Bad input

#[test]
fn recon_splat_rejects_bad_scenes_and_flags_cleanly() {
    let dir = scratch("splat_cli_bad_recon");
    let out = dir.join("out");

    // The small scene itself is fine.
    let good = small_scene(&dir, "good");
    let r = recon_splat(&good, &dir.join("good-out"), &[]);
    assert!(r.status.success(), "{}", stderr(&r));
    assert!(dir.join("good-out/model.ply").is_file());

    // No images at all: a NeRF-synthetic folder whose listed photos are all missing.
    let scene = small_scene(&dir, "no-images");
    for split in ["train", "test"] {
        std::fs::remove_dir_all(scene.join(split)).unwrap();
    }
    let r = recon_splat(&scene, &out, &[]);
    println!("no images: {}", stderr(&r).trim());
    assert_clean_failure(
        &r,
        &["train/r_0", "transforms_train.json", "does not exist"],
        &out,
    );

    // An instant-ngp folder listing frames none of which has its image.
    let ngp = dir.join("ngp-no-images");
    std::fs::create_dir_all(&ngp).unwrap();
    let pose = json!([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]]);
    let frames: Vec<_> = (0..3)
        .map(|i| json!({"file_path": format!("images/{i}.png"), "transform_matrix": pose}))
        .collect();
    write_json(
        &ngp.join("transforms.json"),
        &json!({"fl_x": 10, "frames": frames}),
    );
    let r = recon_splat(&ngp, &out, &[]);
    println!("ngp, no images: {}", stderr(&r).trim());
    assert_clean_failure(&r, &["none of the 3 frames", "images/0.png"], &out);

    // A transforms file with no frames, and a folder with no transforms file.
    let scene = small_scene(&dir, "no-frames");
    write_json(
        &scene.join("transforms_train.json"),
        &json!({"camera_angle_x": 0.8, "frames": []}),
    );
    let r = recon_splat(&scene, &out, &[]);
    assert_clean_failure(&r, &["transforms_train.json", "\"frames\" is empty"], &out);
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let r = recon_splat(&empty, &out, &[]);
    assert_clean_failure(
        &r,
        &["empty", "transforms_train.json", "transforms.json"],
        &out,
    );

    // NaN (or an infinity) in a pose, as Python's json.dump writes it: bare words that
    // are not JSON.
    for word in ["NaN", "Infinity", "-Infinity"] {
        let scene = small_scene(&dir, &format!("pose-{word}"));
        let path = scene.join("transforms_train.json");
        let mut j = read_json(&path);
        j["frames"][1]["transform_matrix"][1][3] = json!(12345.5);
        let text = serde_json::to_string_pretty(&j).unwrap();
        std::fs::write(&path, text.replace("12345.5", word)).unwrap();
        let r = recon_splat(&scene, &out, &[]);
        println!("{word} in a pose: {}", stderr(&r).trim());
        assert_clean_failure(
            &r,
            &[
                "transforms_train.json",
                "malformed JSON",
                "line ",
                "NaN and Infinity",
            ],
            &out,
        );
    }
    // A pose entry that is finite in the file but not as f32.
    let scene = small_scene(&dir, "huge-pose");
    let path = scene.join("transforms_train.json");
    let mut j = read_json(&path);
    j["frames"][1]["transform_matrix"][1][3] = json!(1e300);
    write_json(&path, &j);
    let r = recon_splat(&scene, &out, &[]);
    println!("1e300 in a pose: {}", stderr(&r).trim());
    assert_clean_failure(
        &r,
        &[
            "transforms_train.json",
            "frame 1 (./train/r_1)",
            "non-finite",
        ],
        &out,
    );

    // A --bound far outside the cameras' scale: refused by name, as by `recon voxel`
    // (the initial Gaussians' sizes were infinite or zero, and training failed with
    // "log scale is inf").
    for bound in ["1e30", "1e-30"] {
        let r = recon_splat(&good, &out, &["--bound", bound]);
        println!("--bound {bound}: {}", stderr(&r).trim());
        assert_clean_failure(&r, &[&format!("--bound {bound}"), "must be between"], &out);
    }

    // --test-list: refused for NeRF-synthetic folders (their split is their own); a
    // name that is no photo of the folder is one line naming the list and the line.
    let list = dir.join("held.txt");
    std::fs::write(&list, "test/r_0.png\n").unwrap();
    let r = recon_splat(&good, &out, &["--test-list", s(&list)]);
    assert_clean_failure(
        &r,
        &["--test-list", "held.txt", "transforms_test.json"],
        &out,
    );
    let colmap = dir.join("colmap");
    diffsvg::volume::colmap::convert(&good, &colmap, &Default::default()).unwrap();
    std::fs::write(&list, "test/r_0.png\ntest/r_9.png\n").unwrap();
    let r = recon_splat(&colmap, &out, &["--test-list", s(&list)]);
    println!("--test-list, unknown name: {}", stderr(&r).trim());
    assert_clean_failure(&r, &["held.txt", "line 2", "test/r_9.png"], &out);

    // --max-gaussians 0 (and above the limit).
    let r = recon_splat(&good, &out, &["--max-gaussians", "0"]);
    assert_clean_failure(&r, &["--max-gaussians 0"], &out);
    let r = recon_splat(&good, &out, &["--max-gaussians", "999999999999"]);
    assert_clean_failure(&r, &["--max-gaussians 999999999999"], &out);
}

#[test]
fn view_rejects_bad_splat_models_cleanly() {
    let dir = scratch("splat_cli_bad_view");
    let scene = small_scene(&dir, "scene");
    let out = dir.join("views");
    let view = |model: &Path| diffsvg(&["view", s(model), "--scene", s(&scene), "-o", s(&out)]);

    // The hand-made model views fine.
    let good = degree0_ply();
    let p = dir.join("good.ply");
    std::fs::write(&p, &good).unwrap();
    let r = view(&p);
    assert!(r.status.success(), "{}", stderr(&r));
    assert!(out.join("metrics.csv").is_file());
    std::fs::remove_dir_all(&out).unwrap();

    // Cut short, with a missing property, with a NaN value.
    let without_opacity = {
        let names: Vec<String> = standard_names(0)
            .into_iter()
            .filter(|n| n != "opacity")
            .collect();
        let recs: Vec<Vec<f32>> = [LEFT, RIGHT]
            .map(|m| {
                let mut r = record(m, dc([1.0, 0.0, 0.0]), &[]);
                r.remove(9); // opacity
                r
            })
            .to_vec();
        pack(&names, &recs)
    };
    let mut with_nan = good.clone();
    let at = good.len() - 17 * 4 + 7 * 4; // vertex 1, f_dc_1
    with_nan[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let cases: [(&str, Vec<u8>, &[&str]); 5] = [
        (
            "truncated.ply",
            good[..good.len() - 5].to_vec(),
            &["truncated"],
        ),
        (
            "header-only.ply",
            good[..good.len() - 2 * 17 * 4].to_vec(),
            &["truncated"],
        ),
        (
            "no-opacity.ply",
            without_opacity,
            &["property opacity missing"],
        ),
        ("nan.ply", with_nan, &["vertex 1", "f_dc_1", "NaN"]),
        ("cut-header.ply", good[..40].to_vec(), &["end_header"]),
    ];
    for (name, data, needles) in cases {
        let p = dir.join(name);
        std::fs::write(&p, data).unwrap();
        let r = view(&p);
        println!("{name}: {}", stderr(&r).trim());
        let mut all = vec![name];
        all.extend_from_slice(needles);
        assert_clean_failure(&r, &all, &out);
        assert!(!out.exists(), "{name}: the output folder was created");
    }
}

// ---------------------------------------------------------------------------------------
// The features of issue 31 end to end

/// `recon splat --antialias --exposure --mcmc` writing an SPZ: the file is gzip, loads
/// as an antialiased model within the budget, and `view --depth` reads it and writes the
/// depth images with their scales; a cut SPZ fails with one line naming it.
#[test]
fn recon_splat_features_write_spz_and_view_depth() {
    let dir = scratch("splat_cli_features");
    let scene = dir.join("scene");
    write_scene(&scene, 12, 3, 32);
    let model = dir.join("out/model.spz");
    let r = diffsvg(&[
        "recon",
        "splat",
        "--scene",
        s(&scene),
        "-o",
        s(&model),
        "--iters",
        "60",
        "--initial",
        "200",
        "--max-gaussians",
        "300",
        "--antialias",
        "--exposure",
        "--mcmc",
        "--json",
        "--quiet",
    ]);
    assert!(r.status.success(), "{}", stderr(&r));
    let sum = summary(&r);
    let n = sum["gaussians"].as_u64().unwrap() as usize;
    assert!((1..=300).contains(&n), "{sum}");
    let bytes = std::fs::read(&model).unwrap();
    assert!(bytes.starts_with(&[0x1f, 0x8b]), "an SPZ is a gzip stream");
    let g = splat::load_spz(&model).unwrap();
    assert!(g.antialiased);
    assert_eq!(g.len(), n);

    let views = dir.join("views");
    let r = diffsvg(&[
        "view",
        s(&model),
        "--scene",
        s(&scene),
        "-o",
        s(&views),
        "--depth",
        "--json",
    ]);
    assert!(r.status.success(), "{}", stderr(&r));
    let test_psnr = sum["test_psnr"].as_f64().unwrap();
    let view_psnr = summary(&r)["psnr"].as_f64().unwrap();
    // The SPZ's quantization moves the PSNR a little, not much.
    assert!(
        (view_psnr - test_psnr).abs() < 1.0,
        "{view_psnr} vs {test_psnr}"
    );
    let csv = std::fs::read_to_string(views.join("depth.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows[0], "file,units_per_level,max_depth");
    assert_eq!(rows.len(), 1 + 3 * 2, "{csv}");
    for kind in ["expected", "median"] {
        let png = image::open(views.join(format!("r_0.depth-{kind}.png"))).unwrap();
        assert_eq!((png.width(), png.height()), (32, 32));
        assert!(matches!(png, image::DynamicImage::ImageLuma16(_)));
        let npy = std::fs::read(views.join(format!("r_0.depth-{kind}.npy"))).unwrap();
        assert!(npy.starts_with(b"\x93NUMPY"));
    }
    let row: Vec<&str> = rows[1].split(',').collect();
    let max: f32 = row[2].parse().unwrap();
    assert!(max > 0.5 && max < 20.0, "{csv}");

    // A cut SPZ is one line naming it, and nothing is written.
    let cut = dir.join("cut.spz");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let out = dir.join("cut-views");
    let r = diffsvg(&["view", s(&cut), "--scene", s(&scene), "-o", s(&out)]);
    assert_clean_failure(&r, &["cut.spz"], &out);
}

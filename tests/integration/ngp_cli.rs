//! `diffsvg recon ngp` and `diffsvg view` of its model end to end on the tiny synthetic
//! scene of the voxel tests, and bad flags and model files failing cleanly.

use serde_json::json;

use super::common::{diffsvg, s, scratch};
use super::volume::{
    assert_clean_failure, empty_model_psnr, small_scene, stderr, summary, write_scene,
};

/// A small model and run: 8 levels up to 64 cells, 2¹² entries, 96 samples per diagonal.
const SMALL: [&str; 12] = [
    "--levels",
    "8",
    "--log2-table",
    "12",
    "--max-res",
    "64",
    "--steps",
    "96",
    "--samples",
    "8192",
    "--width",
    "32",
];

#[test]
fn recon_ngp_then_view_reproduce_a_synthetic_scene() {
    let dir = scratch("ngp_e2e");
    let scene = dir.join("scene");
    write_scene(&scene, 24, 3, 24);
    let model = dir.join("out/model.ngp");
    let mut args = vec![
        "recon",
        "ngp",
        "--scene",
        s(&scene),
        "-o",
        s(&model),
        "--iters",
        "120",
        "--json",
    ];
    args.extend(SMALL);
    let r = diffsvg(&args);
    assert!(r.status.success(), "{}", stderr(&r));
    let sum = summary(&r);
    println!("recon ngp: {sum}");
    assert_eq!(sum["done"], json!(true));
    assert_eq!(sum["iterations"], json!(120));
    let test_psnr = sum["test_psnr"].as_f64().expect("a test PSNR");
    let empty = empty_model_psnr(&scene);
    assert!(
        test_psnr > empty + 8.0,
        "held-out {test_psnr:.2} dB, an empty model {empty:.2} dB"
    );
    let m = diffsvg::volume::field::load(&model).unwrap();
    assert_eq!(m.shape().hash.levels, 8);
    assert_eq!(
        sum["bytes"].as_u64(),
        Some(std::fs::metadata(&model).unwrap().len())
    );
    assert!(dir.join("out/model.log.csv").is_file());

    view_agrees_and_a_cut_model_fails(&dir, &scene, &model, test_psnr, "ngp");
}

/// `view` reads the kind from the header and scores the same test views as `recon`
/// (`test_psnr`); the model cut short fails with one line naming it, nothing written.
fn view_agrees_and_a_cut_model_fails(
    dir: &std::path::Path,
    scene: &std::path::Path,
    model: &std::path::Path,
    test_psnr: f64,
    ext: &str,
) {
    let views = dir.join("views");
    let r = diffsvg(&[
        "view",
        s(model),
        "--scene",
        s(scene),
        "-o",
        s(&views),
        "--json",
    ]);
    assert!(r.status.success(), "{}", stderr(&r));
    let v = summary(&r);
    assert_eq!(v["views"], json!(3));
    let p = v["psnr"].as_f64().unwrap();
    assert!((p - test_psnr).abs() < 0.5, "view {p} vs recon {test_psnr}");
    let bytes = std::fs::read(model).unwrap();
    let name = format!("cut.{ext}");
    let cut = dir.join(&name);
    std::fs::write(&cut, &bytes[..bytes.len() - 3]).unwrap();
    let out = dir.join("cut-views");
    let r = diffsvg(&["view", s(&cut), "--scene", s(scene), "-o", s(&out)]);
    assert_clean_failure(&r, &[&name, "header implies"], &out);
}

#[test]
fn recon_ngp_refuses_bad_flags_before_reading() {
    refuses_bad_flags(
        "ngp",
        &[
            ("--levels", "0", "--levels"),
            ("--log2-table", "30", "--log2-table"),
            ("--width", "4", "--width"),
            ("--batch", "0", "--batch"),
            ("--steps", "2", "--steps"),
            ("--lr", "nan", "--lr"),
            ("--seconds=-1", "", "--seconds"),
        ],
    );
}

/// `recon KIND` with each `(flag, value, needle)`: exit 2, one line containing the
/// needle, no file written. Returns the scene and the output folder.
fn refuses_bad_flags(
    kind: &str,
    cases: &[(&str, &str, &str)],
) -> (std::path::PathBuf, std::path::PathBuf) {
    let dir = scratch(&format!("{kind}_bad_flags"));
    let scene = small_scene(&dir, "scene");
    let out = dir.join("out");
    let model = out.join(format!("m.{kind}"));
    for &(flag, value, needle) in cases {
        let mut args = vec!["recon", kind, "--scene", s(&scene), "-o", s(&model), flag];
        if !value.is_empty() {
            args.push(value);
        }
        let r = diffsvg(&args);
        assert_clean_failure(&r, &[needle], &out);
    }
    (scene, out)
}

/// `recon nerf` then `view` on the same scene: a small NeRF field (6 octaves, 32 wide).
#[test]
fn recon_nerf_then_view_reproduce_a_synthetic_scene() {
    let dir = scratch("nerf_e2e");
    let scene = dir.join("scene");
    write_scene(&scene, 24, 3, 24);
    let model = dir.join("out/model.nerf");
    let r = diffsvg(&[
        "recon",
        "nerf",
        "--scene",
        s(&scene),
        "-o",
        s(&model),
        "--iters",
        "150",
        "--frequencies",
        "6",
        "--width",
        "32",
        "--density-layers",
        "2",
        "--steps",
        "96",
        "--samples",
        "8192",
        "--lr",
        "5e-3",
        "--json",
    ]);
    assert!(r.status.success(), "{}", stderr(&r));
    let sum = summary(&r);
    println!("recon nerf: {sum}");
    assert_eq!(sum["iterations"], json!(150));
    let test_psnr = sum["test_psnr"].as_f64().expect("a test PSNR");
    let empty = empty_model_psnr(&scene);
    assert!(
        test_psnr > empty + 5.0,
        "held-out {test_psnr:.2} dB, an empty model {empty:.2} dB"
    );
    assert_eq!(&std::fs::read(&model).unwrap()[..8], b"DSNERFLD");
    let m = diffsvg::volume::field::load(&model).unwrap();
    assert_eq!(m.shape().kind(), diffsvg::volume::field::FieldKind::Nerf);
    assert_eq!(m.shape().frequencies, 6);
    assert_eq!(m.shape().density_layers, 2);
    view_agrees_and_a_cut_model_fails(&dir, &scene, &model, test_psnr, "nerf");
}

#[test]
fn recon_nerf_refuses_bad_flags_before_reading() {
    let (scene, out) = refuses_bad_flags(
        "nerf",
        &[
            ("--frequencies", "0", "--frequencies"),
            ("--frequencies", "17", "--frequencies"),
            ("--density-layers", "5", "--density-layers"),
            ("--color-layers", "0", "--color-layers"),
            ("--width", "4", "--width"),
            ("--steps", "2", "--steps"),
            ("--lr", "nan", "--lr"),
            ("--levels", "4", "--levels"),
        ],
    );
    // The model's extension must be the kind's.
    let r = diffsvg(&[
        "recon",
        "nerf",
        "--scene",
        s(&scene),
        "-o",
        s(&out.join("m.ngp")),
    ]);
    assert_clean_failure(&r, &["m.ngp"], &out);
}

/// `diffsvg ladder` with tiny budgets on the synthetic scene: four rows with finite
/// scores, the table, the JSON and the chart; bad flags fail with one line, no file.
#[test]
fn ladder_trains_every_representation_and_writes_the_table() {
    let dir = scratch("ladder");
    let scene = dir.join("scene");
    write_scene(&scene, 24, 3, 24);
    let out = dir.join("out");
    let r = diffsvg(&[
        "ladder",
        "--scene",
        s(&scene),
        "--seconds",
        "1.5",
        "--voxel-res",
        "32",
        "--voxel-iters",
        "100",
        "--splat-iters",
        "100",
        "-o",
        s(&out),
        "--json",
    ]);
    assert!(r.status.success(), "{}", stderr(&r));
    let t: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    let rows = t["rows"].as_array().unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r["model"].as_str().unwrap()).collect();
    assert_eq!(names, ["voxel", "splat", "ngp", "nerf"]);
    for row in rows {
        let p = row["test_psnr"].as_f64().unwrap();
        assert!(p.is_finite() && p > 5.0, "{row}");
        let ssim = row["ssim"].as_f64().unwrap();
        assert!(ssim > 0.0 && ssim <= 1.0, "{row}");
        assert!(row["train_seconds"].as_f64().unwrap() < 15.0, "{row}");
        assert!(row["render_seconds_per_view"].as_f64().unwrap() > 0.0);
        assert_eq!(row["views"], json!(3));
        let file = std::path::PathBuf::from(row["file"].as_str().unwrap());
        assert_eq!(
            row["model_bytes"].as_u64(),
            Some(std::fs::metadata(&file).unwrap().len())
        );
    }
    for f in ["ladder.md", "ladder.json", "ladder.png", "ladder.svg"] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let md = std::fs::read_to_string(out.join("ladder.md")).unwrap();
    assert_eq!(md.lines().filter(|l| l.starts_with("| ")).count(), 5);

    let bad = dir.join("bad");
    let list = dir.join("test.txt");
    std::fs::write(&list, "test/r_0.png\n").unwrap();
    for args in [
        vec!["--seconds", "0"],
        vec!["--seconds", "1", "--rungs", "voxel,mesh"],
        vec!["--seconds", "1", "--downscale", "0"],
        // A NeRF-synthetic folder has its own test views: a list is refused.
        vec!["--seconds", "1", "--test-list", s(&list)],
    ] {
        let mut a = vec!["ladder", "--scene", s(&scene), "-o", s(&bad)];
        a.extend(args);
        let r = diffsvg(&a);
        assert_clean_failure(&r, &[], &bad);
    }
}

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

    // `view` reads the kind from the header and scores the same test views.
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
    let v = summary(&r);
    assert_eq!(v["views"], json!(3));
    let p = v["psnr"].as_f64().unwrap();
    assert!((p - test_psnr).abs() < 0.5, "view {p} vs recon {test_psnr}");

    // A truncated model: one line naming the file, nothing written.
    let bytes = std::fs::read(&model).unwrap();
    let cut = dir.join("cut.ngp");
    std::fs::write(&cut, &bytes[..bytes.len() - 3]).unwrap();
    let out = dir.join("cut-views");
    let r = diffsvg(&["view", s(&cut), "--scene", s(&scene), "-o", s(&out)]);
    assert_clean_failure(&r, &["cut.ngp", "header implies"], &out);
}

#[test]
fn recon_ngp_refuses_bad_flags_before_reading() {
    let dir = scratch("ngp_bad_flags");
    let scene = small_scene(&dir, "scene");
    let out = dir.join("out");
    for (flag, value, needle) in [
        ("--levels", "0", "--levels"),
        ("--log2-table", "30", "--log2-table"),
        ("--width", "4", "--width"),
        ("--batch", "0", "--batch"),
        ("--steps", "2", "--steps"),
        ("--lr", "nan", "--lr"),
        ("--seconds=-1", "", "--seconds"),
    ] {
        let model = out.join("m.ngp");
        let mut args = vec!["recon", "ngp", "--scene", s(&scene), "-o", s(&model), flag];
        if !value.is_empty() {
            args.push(value);
        }
        let r = diffsvg(&args);
        assert_clean_failure(&r, &[needle], &out);
    }
}

//! `grad --check`: no false alarms at clamped parameters, and a failing check exits 1.

use crate::common::{diffsvg, root, s, scratch};

/// A perturbed copy of `01-curves.svg` (its opacities stay at 1) and the original's
/// rendering as the target.
fn perturbed_curves(name: &str) -> (std::path::PathBuf, std::path::PathBuf) {
    let dir = scratch(name);
    let original = root().join("svg-samples/01-curves.svg");
    let moved = dir.join("moved.svg");
    let target = dir.join("target.png");
    let r = diffsvg(&["perturb", s(&original), "-o", s(&moved), "--seed", "3"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let r = diffsvg(&["render", s(&original), "-o", s(&target), "--width", "64"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    (moved, target)
}

#[test]
fn grad_check_at_opacity_one_is_no_false_alarm() {
    let (moved, target) = perturbed_curves("gradcheck-ok");
    let r = diffsvg(&["grad", s(&moved), s(&target), "--width", "64", "--check"]);
    let out = String::from_utf8_lossy(&r.stdout);
    assert!(
        r.status.success(),
        "{out}{}",
        String::from_utf8_lossy(&r.stderr)
    );
    assert!(
        out.contains("opacities") && !out.contains("FAILED"),
        "{out}"
    );
}

#[test]
fn grad_check_with_a_flipped_sign_exits_1() {
    let (moved, target) = perturbed_curves("gradcheck-flip");
    let r = diffsvg(&[
        "grad",
        s(&moved),
        s(&target),
        "--width",
        "64",
        "--check",
        "--corrupt",
        "0",
    ]);
    let out = String::from_utf8_lossy(&r.stdout);
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(1), "{out}{err}");
    assert!(
        out.contains("FAILED") && err.contains("moved.svg"),
        "{out}{err}"
    );
}

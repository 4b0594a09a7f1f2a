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

/// `grad --check --exact-overlaps`: the exact coverage's gradient, where the two squares of
/// one path overlap, agrees with central differences of the exact renders; it is not the
/// clamped coverage's gradient, and `loss` takes the option too.
#[test]
fn grad_check_of_the_exact_coverage_passes() {
    let dir = scratch("gradcheck-exact");
    let svg = dir.join("overlap.svg");
    std::fs::write(
        &svg,
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="16" height="16">
  <path d="M 2.3 2.2 L 9.6 2.2 L 9.6 9.4 L 2.3 9.4 Z M 5.1 3.5 L 13.2 3.5 L 13.2 12.6 L 5.1 12.6 Z"
        fill="#3366cc" fill-opacity="0.8"/></svg>"##,
    )
    .unwrap();
    let target = root().join("svg-samples/01-curves.svg");
    let png = dir.join("target.png");
    let r = diffsvg(&["render", s(&target), "-o", s(&png), "--width", "16"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let run = |args: &[&str]| {
        let mut all = vec![args[0], s(&svg), s(&png)];
        all.extend_from_slice(&args[1..]);
        let r = diffsvg(&all);
        let out = String::from_utf8_lossy(&r.stdout).into_owned();
        assert!(
            r.status.success(),
            "{out}{}",
            String::from_utf8_lossy(&r.stderr)
        );
        out
    };
    let checked = run(&["grad", "--check", "--exact-overlaps"]);
    assert!(!checked.contains("FAILED"), "{checked}");
    assert_ne!(
        run(&["grad", "--json", "--exact-overlaps"]),
        run(&["grad", "--json"])
    );
    assert_ne!(run(&["loss", "--exact-overlaps"]), run(&["loss"]));
}

//! Helpers shared by the integration tests.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The crate root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Whether `DIFFSVG_REQUIRE_DATA=1` is set: then a test that needs `../shared/data` fails
/// instead of skipping when the data is missing (`.ci/run` sets it; CI has the data).
pub fn data_required() -> bool {
    std::env::var_os("DIFFSVG_REQUIRE_DATA").is_some_and(|v| v == "1")
}

/// Skips a test that needs data which is not there: prints the reason, or panics when
/// [`data_required`].
pub fn skip(test: &str, reason: &str) {
    if data_required() {
        panic!("{test}: {reason}, and DIFFSVG_REQUIRE_DATA=1 forbids skipping");
    }
    println!("SKIPPED {test}: {reason} (set DIFFSVG_DATA)");
}

/// `../shared/data` beside the checkout (or `$DIFFSVG_DATA`), when present. Prints why a
/// test is skipped when it is not; with `DIFFSVG_REQUIRE_DATA=1` a missing folder fails
/// the test instead.
pub fn shared_data(test: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("DIFFSVG_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("../shared/data"));
    if dir.is_dir() {
        Some(dir)
    } else {
        skip(test, &format!("{} not found", dir.display()));
        None
    }
}

/// The bundled samples, sorted.
pub fn samples() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join("svg-samples"))
        .expect("svg-samples/ exists")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "svg"))
        .collect();
    v.sort();
    v
}

/// A fresh empty folder under the target directory.
pub fn scratch(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs the `diffsvg` binary.
pub fn diffsvg(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_diffsvg"))
        .args(args)
        .output()
        .expect("runs diffsvg")
}

/// A path as `&str`.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Writes a text file into `dir`.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Asserts a clean failure: exit code 2, one line on stderr naming `needle` and `what`,
/// and no output file.
pub fn assert_fails(out: &Output, needle: &str, what: &str, output: &Path) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {err}");
    assert_eq!(err.trim().lines().count(), 1, "one line expected: {err}");
    assert!(err.contains(needle), "{err:?} should name {needle}");
    assert!(
        err.to_lowercase().contains(what),
        "{err:?} should say {what}"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(!output.exists(), "no output may be written on failure");
    // Nor a stray temporary file.
    let dir = output.parent().unwrap();
    let stray: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(stray.is_empty(), "temporary files left behind: {stray:?}");
}

/// The JSON summary a `--json` run prints last, once the run succeeded (its stderr
/// shown otherwise).
pub fn json_summary(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.lines().last().unwrap_or_default())
        .unwrap_or_else(|e| panic!("{e}: {text}"))
}

//! Helpers shared by the integration tests.

use std::path::PathBuf;

/// The crate root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `../shared/data` beside the checkout (or `$DIFFSVG_DATA`), when present. Prints why a
/// test is skipped when it is not.
pub fn shared_data(test: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("DIFFSVG_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("../shared/data"));
    if dir.is_dir() {
        Some(dir)
    } else {
        println!(
            "SKIPPED {test}: {} not found (set DIFFSVG_DATA)",
            dir.display()
        );
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

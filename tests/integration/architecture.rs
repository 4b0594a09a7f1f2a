//! The module rules of docs/architecture.md, checked on the source: which library module
//! may use which, and that no library file uses a command-line crate.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use super::common::root;

/// The library's top-level modules.
const MODULES: [&str; 18] = [
    "error",
    "limits",
    "guard",
    "choice",
    "rng",
    "image_io",
    "metrics",
    "loss",
    "mnist",
    "scene",
    "raster",
    "optim",
    "fit",
    "gradcheck",
    "reference",
    "volume",
    "mesh",
    "lib",
];

/// The library modules each top-level module must not name through `crate::`: the rules of
/// docs/architecture.md, with no exceptions. Every module may use `error`, `limits`,
/// `guard`, `choice` and `rng`.
fn forbidden(module: &str) -> &'static [&'static str] {
    // Modules that sit above everything else but the command line.
    const TOP: [&str; 5] = ["fit", "gradcheck", "reference", "volume", "mesh"];
    match module {
        "error" | "limits" | "guard" | "choice" | "rng" => &[
            "image_io",
            "metrics",
            "loss",
            "mnist",
            "scene",
            "raster",
            "optim",
            "fit",
            "gradcheck",
            "reference",
            "volume",
            "mesh",
        ],
        "image_io" | "metrics" | "loss" | "mnist" => &[
            "scene",
            "raster",
            "optim",
            "fit",
            "gradcheck",
            "reference",
            "volume",
            "mesh",
        ],
        // The generic optimizer: slices of numbers only.
        "optim" => &[
            "scene",
            "raster",
            "fit",
            "volume",
            "loss",
            "gradcheck",
            "reference",
            "mesh",
        ],
        "scene" => &[
            "raster",
            "fit",
            "optim",
            "gradcheck",
            "reference",
            "volume",
            "mesh",
        ],
        "raster" => &["fit", "optim", "volume", "gradcheck", "reference", "mesh"],
        "volume" => &[
            "scene",
            "raster",
            "fit",
            "gradcheck",
            "reference",
            "loss",
            "mesh",
        ],
        "fit" => &["volume", "gradcheck", "reference", "mesh"],
        // Meshes use raster, volume's cameras and datasets, optim, loss and metrics.
        "mesh" => &["fit", "gradcheck", "reference", "scene"],
        "gradcheck" | "reference" => &TOP,
        m => panic!("module {m} is not in docs/architecture.md's table: add it there and here"),
    }
}

/// Every `.rs` file under `dir`.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The identifiers that follow `crate::` in `text`, outside comments.
fn crate_paths(text: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    for line in text.lines() {
        let code = line.split("//").next().unwrap_or("");
        let mut rest = code;
        while let Some(i) = rest.find("crate::") {
            rest = &rest[i + "crate::".len()..];
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() {
                found.insert(name);
            }
        }
    }
    found
}

/// The library's files with their top-level module (`lib`, `scene`, `volume`, …).
fn library_files() -> Vec<(String, PathBuf, String)> {
    let src = root().join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    files
        .into_iter()
        .filter_map(|p| {
            let rel = p
                .strip_prefix(&src)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            if rel == "main.rs" || rel.starts_with("cli/") {
                return None;
            }
            let top = rel
                .split('/')
                .next()
                .unwrap()
                .trim_end_matches(".rs")
                .to_string();
            let text = std::fs::read_to_string(&p).unwrap();
            Some((top, p, text))
        })
        .collect()
}

#[test]
fn library_modules_use_only_what_the_architecture_allows() {
    let mut broken = Vec::new();
    for (top, path, text) in library_files() {
        assert!(
            MODULES.contains(&top.as_str()),
            "{}: module {top} unknown",
            path.display()
        );
        if top == "lib" {
            continue;
        }
        let rel = path.to_string_lossy();
        for name in crate_paths(&text) {
            if forbidden(&top).contains(&name.as_str()) {
                broken.push(format!("{rel}: {top} uses crate::{name}"));
            }
        }
    }
    assert!(
        broken.is_empty(),
        "see docs/architecture.md:\n{}",
        broken.join("\n")
    );
}

/// The fence is not empty: a file of each rule's module that named a forbidden module
/// would be caught (the check above is not vacuous).
#[test]
fn the_fence_catches_a_forbidden_edge() {
    let found = crate_paths("use crate::raster::prepare;\n// crate::fit in a comment\n");
    assert_eq!(found.into_iter().collect::<Vec<_>>(), ["raster"]);
    assert!(forbidden("optim").contains(&"scene") && forbidden("scene").contains(&"raster"));
    assert!(forbidden("volume").contains(&"raster") && forbidden("fit").contains(&"volume"));
}

#[test]
fn library_uses_no_command_line_crate() {
    const CLI_CRATES: [&str; 8] = [
        "clap",
        "indicatif",
        "ctrlc",
        "toml",
        "glob",
        "anyhow",
        "plotters",
        "sha2",
    ];
    let mut broken = Vec::new();
    for (_, path, text) in library_files() {
        for line in text.lines() {
            let code = line.split("//").next().unwrap_or("");
            for c in CLI_CRATES {
                if code.contains(&format!("{c}::")) || code.contains(&format!("use {c}")) {
                    broken.push(format!("{}: {}", path.display(), line.trim()));
                }
            }
        }
    }
    assert!(broken.is_empty(), "{}", broken.join("\n"));
    // And the library compiles without them: the `cli` feature carries them all.
    let manifest = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    for c in CLI_CRATES {
        let line = manifest
            .lines()
            .find(|l| l.starts_with(&format!("{c} =")))
            .unwrap_or_else(|| panic!("{c} is not a dependency"));
        assert!(
            line.contains("optional = true"),
            "{c} must be optional: {line}"
        );
    }
}

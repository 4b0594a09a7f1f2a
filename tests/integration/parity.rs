//! Forward parity with resvg on the bundled samples and on resvg's own test suite.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use diffsvg::Sizing;
use diffsvg::raster::RenderOptions;
use diffsvg::reference::{PARITY_MAE, PARITY_PSNR, closer_to_exact, parity_with};
use diffsvg::scene::Fonts;
use rayon::prelude::*;

use super::common::{root, samples, shared_data};

/// Set to regenerate `tests/parity-skip.tsv` from a run: every refusal is written with
/// diffsvg's own reason, and the `differs` entries that still differ (and are not nearer
/// the exact rendering than resvg) keep theirs. A file that renders but misses the
/// thresholds without a `differs` entry, and is not nearer exact, still fails: its reason
/// must be written by hand.
const WRITE_SKIP: &str = "DIFFSVG_WRITE_PARITY_SKIP";

fn check_all(
    files: &[(PathBuf, String, Sizing)],
    skip: &HashMap<String, (String, String)>,
    fonts: &Fonts,
) {
    type Row = (String, Result<diffsvg::metrics::Comparison, String>, bool);
    let results: Vec<Row> = files
        .par_iter()
        .map(|(f, key, sizing)| {
            let r = parity_with(f, *sizing, &RenderOptions::default(), fonts)
                .map(|p| p.comparison)
                .map_err(|e| e.to_string());
            // A file that differs from resvg still passes where diffsvg is the nearer of
            // the two to the exact rendering (resvg's with 16 × 16 samples per pixel).
            let nearer = r.as_ref().is_ok_and(|c| !passes(c))
                && closer_to_exact(f, *sizing, fonts)
                    .ok()
                    .flatten()
                    .is_some_and(|[ours, theirs]| ours <= theirs);
            (key.clone(), r, nearer)
        })
        .collect();
    let (mut pass, mut refused, mut differs, mut nearer_exact) = (0, 0, 0, 0);
    let mut failures = Vec::new();
    let regenerate = std::env::var_os(WRITE_SKIP).is_some() && !skip.is_empty();
    let mut rewritten = Vec::new();
    for (key, r, nearer) in &results {
        if *nearer {
            nearer_exact += 1;
            println!("nearer the exact rendering than resvg: {key}");
            if let Some((kind, _)) = skip.get(key) {
                failures.push(format!(
                    "{key}: skip list says {kind}, but it is nearer the exact rendering than \
                     resvg (rewrite the list with {WRITE_SKIP}=1)"
                ));
            }
            continue;
        }
        if regenerate {
            match (r, skip.get(key)) {
                (Err(e), _) => {
                    let why = e.split_once(".svg: ").map_or(e.as_str(), |(_, w)| w);
                    rewritten.push(format!("{key}\trefused\t{why}"));
                    refused += 1;
                    continue;
                }
                (Ok(c), Some((kind, why))) if kind == "differs" && !passes(c) => {
                    rewritten.push(format!("{key}\tdiffers\t{why}"));
                }
                _ => {}
            }
        }
        match (r, skip.get(key)) {
            (Ok(c), None) => {
                if passes(c) {
                    pass += 1;
                } else {
                    failures.push(format!("{key}: MAE {:.3}, PSNR {:.1} dB", c.mae, c.psnr));
                }
            }
            (Err(e), None) => failures.push(format!("{key}: unexpected error: {e}")),
            (Err(e), Some((kind, _))) if kind == "refused" => {
                // Refused files must fail cleanly, naming the file.
                assert!(
                    e.contains(".svg"),
                    "{key}: error does not name the file: {e}"
                );
                refused += 1;
            }
            (Ok(c), Some((kind, why))) if kind == "differs" => {
                differs += 1;
                println!(
                    "known difference {key}: MAE {:.3}, PSNR {:.1} dB ({why})",
                    c.mae, c.psnr
                );
            }
            (r, Some((kind, _))) => failures.push(format!(
                "{key}: skip list says {kind}, got {:?}",
                r.as_ref().map(|c| c.mae)
            )),
        }
    }
    println!(
        "parity: {} files, {pass} pass, {nearer_exact} nearer the exact rendering than resvg, \
         {refused} refused (unsupported or invalid), {differs} known differences",
        results.len()
    );
    if regenerate {
        let path = root().join("tests/parity-skip.tsv");
        let old = std::fs::read_to_string(&path).unwrap();
        let header: String = old
            .lines()
            .take_while(|l| l.starts_with('#'))
            .map(|l| format!("{l}\n"))
            .collect();
        rewritten.sort();
        std::fs::write(&path, header + &rewritten.join("\n") + "\n").unwrap();
        println!(
            "{WRITE_SKIP}: wrote {} entries to {}",
            rewritten.len(),
            path.display()
        );
    }
    assert!(
        failures.is_empty(),
        "{} files fail parity:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// Whether a comparison with resvg meets the parity thresholds.
fn passes(c: &diffsvg::metrics::Comparison) -> bool {
    c.mae <= PARITY_MAE && c.psnr >= PARITY_PSNR
}

fn skip_list() -> HashMap<String, (String, String)> {
    let text = std::fs::read_to_string(root().join("tests/parity-skip.tsv")).unwrap();
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let mut f = l.splitn(3, '\t');
            let path = f.next().unwrap().to_string();
            let kind = f.next().expect("kind column").to_string();
            let why = f.next().expect("reason column").to_string();
            assert!(
                kind == "refused" || kind == "differs",
                "bad kind in skip list: {l}"
            );
            assert!(
                !why.trim().is_empty(),
                "skip list entry without a reason: {l}"
            );
            (path, (kind, why))
        })
        .collect()
}

#[test]
fn samples_match_resvg() {
    let files: Vec<_> = samples()
        .into_iter()
        .map(|p| {
            let key = p.file_name().unwrap().to_string_lossy().into_owned();
            (p, key, Sizing::Natural)
        })
        .collect();
    assert!(files.len() >= 12, "expected a dozen samples");
    check_all(&files, &HashMap::new(), &Fonts::default());
}

fn svgs(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            svgs(&p, out);
        } else if p.extension().is_some_and(|e| e == "svg") {
            out.push(p);
        }
    }
}

#[test]
fn resvg_test_suite_matches_resvg() {
    let Some(data) = shared_data("resvg_test_suite_matches_resvg") else {
        return;
    };
    let base = data.join("resvg-tests");
    let mut files = Vec::new();
    // The suite's drawings are 200 units rendered 300 px wide; `extra/` at natural size.
    for (sub, sizing) in [("tests", Sizing::Width(300)), ("extra", Sizing::Natural)] {
        let mut v = Vec::new();
        svgs(&base.join(sub), &mut v);
        v.sort();
        for p in v {
            let key = p
                .strip_prefix(&base)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            files.push((p, key, sizing));
        }
    }
    assert!(
        files.len() > 500,
        "resvg-tests looks incomplete: {} files",
        files.len()
    );
    // `<text>` with resvg's harness fonts, as `diffsvg parity --resvg-fonts` sets them.
    let fonts = Fonts::resvg_test_suite(base.join("fonts"));
    check_all(&files, &skip_list(), &fonts);
}

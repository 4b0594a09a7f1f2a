//! The in-tree fuzzer's bounded run: a fixed seed, a fixed number of mutated inputs
//! through every command (see `tests/fuzz/engine.rs` for the mutations and the oracle),
//! no panic, abort or signal, exit codes as documented, no output left on failure, peak
//! memory under 1 GiB. Long campaigns: `cargo run --release --example fuzz -- --minutes N`.
//!
//! `DIFFSVG_FUZZ_CASES` and `DIFFSVG_FUZZ_SEED` change the count and the seed.

#[path = "../fuzz/engine.rs"]
mod engine;

use std::time::Duration;

use super::common::{root, scratch};
use engine::{Config, Fuzzer, campaign, distinct};

/// The CI run's seed and size: about 200 cases, well under a minute in release.
const SEED: u64 = 13;
const CASES: u64 = 200;

fn env_u64(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

#[test]
fn fuzz_cases_keep_the_cli_contract() {
    let work = scratch("fuzz");
    let repro = scratch("fuzz-repro");
    let mut cfg = Config::new(
        env!("CARGO_BIN_EXE_diffsvg").into(),
        work,
        root(),
        env_u64("DIFFSVG_FUZZ_SEED", SEED),
    );
    // The time limit only catches hangs here (the machine may be busy); campaigns use
    // the 10 s of the issue.
    cfg.timeout = Duration::from_secs(60);
    cfg.repro_dir = Some(repro.clone());
    let mut fz = Fuzzer::new(cfg).unwrap();
    let n = env_u64("DIFFSVG_FUZZ_CASES", CASES);
    let (run, failures) = campaign(&mut fz, 0, n, None, |_, _| {});
    assert_eq!(run, n);
    for f in &failures {
        println!(
            "case {}: {}\n  {}\n  {}\n  reproducer: {:?}",
            f.case, f.key, f.command, f.detail, f.saved
        );
    }
    let kinds = distinct(&failures);
    assert!(
        failures.is_empty(),
        "{} of {run} fuzz cases failed, {} distinct: {:?} (reproducers in {})",
        failures.len(),
        kinds.len(),
        kinds.keys().collect::<Vec<_>>(),
        repro.display()
    );
}

/// The generator is a pure function of (seed, case number), so a failure reproduces.
#[test]
fn fuzz_cases_are_deterministic() {
    let cfg = Config::new(
        env!("CARGO_BIN_EXE_diffsvg").into(),
        scratch("fuzz-det"),
        root(),
        7,
    );
    let fz = Fuzzer::new(cfg).unwrap();
    for i in [0, 1, 17, 99] {
        let (a, b) = (fz.generate(i), fz.generate(i));
        assert_eq!(a.args, b.args);
        assert_eq!(a.files, b.files);
    }
    assert_ne!(fz.generate(0).files, fz.generate(1).files);
}

/// Issue 27's directed cases: filter, image, mask, clip, pattern and marker regions and
/// far arc endpoints at sizes near `f32::MAX`, through `render` and `fit`, and pictures of
/// one to three pixels a side through `vectorize` in every mode. Before the issue's
/// fixes these panicked (exit 101) or ran past the time limit.
#[test]
fn fuzz_directed_cases_keep_the_cli_contract() {
    let cfg = Config::new(
        env!("CARGO_BIN_EXE_diffsvg").into(),
        scratch("fuzz-directed"),
        root(),
        SEED,
    );
    let mut cfg = cfg;
    // Hangs only (the machine may be busy): the far arc ran for minutes.
    cfg.timeout = Duration::from_secs(60);
    let mut fz = Fuzzer::new(cfg).unwrap();
    let n = fz.directed().len();
    assert!(n >= 100, "directed cases: {n}");
    let failures = fz.run_directed();
    for f in &failures {
        println!(
            "case {}: {}\n  {}\n  {}",
            f.case, f.key, f.command, f.detail
        );
    }
    assert!(
        failures.is_empty(),
        "{} of {n} directed cases failed: {:?}",
        failures.len(),
        distinct(&failures).keys().collect::<Vec<_>>()
    );
    // Every command and outcome the cases meant to reach was reached.
    for cmd in ["render", "fit", "vectorize"] {
        let [runs, ok, _, _] = fz.stats[cmd];
        assert!(runs > 0 && ok > 0, "{cmd}: {runs} cases, {ok} exit 0");
    }
}

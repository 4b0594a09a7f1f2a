//! Long fuzzing campaigns with the in-tree mutation fuzzer (`tests/fuzz/engine.rs`).
//!
//! ```sh
//! cargo build --release
//! cargo run --release --example fuzz -- --minutes 30 [--seed S] [--out DIR] \
//!     [--bin target/release/diffsvg] [--first N] [--cases N] [--mem-mib 1024] \
//!     [--timeout 10] [--no-data]
//! ```
//!
//! Runs cases `first, first + 1, …` of the seed until the time or the count is reached,
//! each a mutated input through one command of the release binary (which it does not
//! build: `cargo build --release` first). Seeds: `svg-samples/` and, unless `--no-data`,
//! `../shared/data/resvg-tests` (or `$DIFFSVG_DATA/resvg-tests`) when present. Prints
//! progress, then the cases run, the failures and the distinct failure kinds; each
//! failure's inputs and a `cmd.sh` (the command, under the same `ulimit -v`) are saved in
//! `DIR/<kind>-seed<S>-case<N>/` (at most 3 per kind). Exit status 1 when anything failed.

#[path = "../tests/fuzz/engine.rs"]
mod engine;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use engine::{Config, Fuzzer, campaign, distinct};

fn main() {
    let mut minutes = 1.0f64;
    let mut seed = 1u64;
    let mut out = PathBuf::from("fuzz-findings");
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut bin = std::env::current_exe()
        .ok()
        .and_then(|p| Some(p.parent()?.parent()?.join("diffsvg")))
        .unwrap_or_else(|| root.join("target/release/diffsvg"));
    let mut first = 0u64;
    let mut cases = u64::MAX;
    let mut mem_mib = 1024u64;
    let mut timeout = 10u64;
    let mut data = true;
    let mut args = std::env::args().skip(1);
    let usage = "usage: fuzz [--minutes N] [--seed S] [--out DIR] [--bin PATH] [--first N] \
                 [--cases N] [--mem-mib M] [--timeout SECS] [--no-data]";
    while let Some(a) = args.next() {
        let mut val = || {
            args.next().unwrap_or_else(|| {
                eprintln!("error: {a} needs a value\n{usage}");
                std::process::exit(2)
            })
        };
        fn num<T: std::str::FromStr>(flag: &str, v: String) -> T {
            v.parse().unwrap_or_else(|_| {
                eprintln!("error: {flag}: {v:?} is not a valid number");
                std::process::exit(2)
            })
        }
        match a.as_str() {
            "--minutes" => minutes = num("--minutes", val()),
            "--seed" => seed = num("--seed", val()),
            "--out" => out = PathBuf::from(val()),
            "--bin" => bin = PathBuf::from(val()),
            "--first" => first = num("--first", val()),
            "--cases" => cases = num("--cases", val()),
            "--mem-mib" => mem_mib = num("--mem-mib", val()),
            "--timeout" => timeout = num("--timeout", val()),
            "--no-data" => data = false,
            "-h" | "--help" => {
                println!("{usage}");
                return;
            }
            _ => {
                eprintln!("error: unknown argument {a}\n{usage}");
                std::process::exit(2)
            }
        }
    }
    if !(minutes.is_finite() && minutes > 0.0) {
        eprintln!("error: --minutes must be positive");
        std::process::exit(2)
    }
    let work = std::env::temp_dir().join(format!("diffsvg-fuzz-{}", std::process::id()));
    let mut cfg = Config::new(bin, work.clone(), root.clone(), seed);
    cfg.mem_limit_kib = mem_mib * 1024;
    cfg.rss_ceiling_kib = mem_mib * 1024;
    cfg.timeout = Duration::from_secs(timeout);
    cfg.repro_dir = Some(out.clone());
    if data {
        let d = std::env::var_os("DIFFSVG_DATA")
            .map(PathBuf::from)
            .unwrap_or_else(|| root.join("../shared/data"))
            .join("resvg-tests");
        if d.is_dir() {
            cfg.extra_svgs = Some(d);
        }
    }
    let mut fz = match Fuzzer::new(cfg) {
        Ok(f) => f,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2)
        }
    };
    println!(
        "fuzz: seed {seed}, {} SVG seeds, {minutes} min, ceiling {mem_mib} MiB, {timeout} s a case; reproducers in {}",
        fz.svg_seeds(),
        out.display()
    );
    let t0 = Instant::now();
    let deadline = t0 + Duration::from_secs_f64(minutes * 60.0);
    let mut last = Instant::now();
    // The directed cases first (issue 27's regions, far arcs and tiny pictures), then
    // random ones until the deadline.
    let directed = fz.directed().len();
    let mut failures = fz.run_directed();
    println!(
        "  {directed} directed cases in {:.0} s, {} failures",
        t0.elapsed().as_secs_f64(),
        failures.len()
    );
    let (run, random_failures) = campaign(&mut fz, first, cases, Some(deadline), |n, f| {
        if last.elapsed() > Duration::from_secs(30) {
            last = Instant::now();
            println!(
                "  {n} cases in {:.0} s, {} failures, {} distinct",
                t0.elapsed().as_secs_f64(),
                f.len(),
                distinct(f).len()
            );
        }
    });
    failures.extend(random_failures);
    let kinds = distinct(&failures);
    println!(
        "fuzz: {directed} directed and {run} random cases (seed {seed}, cases {first}..{}) in {:.0} s: {} failures, {} distinct",
        first + run,
        t0.elapsed().as_secs_f64(),
        failures.len(),
        kinds.len()
    );
    for (cmd, [n, ok, refused, failed]) in &fz.stats {
        println!(
            "  {cmd:10} {n:6} cases: {ok:6} exit 0, {refused:6} refused (exit 1/2), {failed:5} failures"
        );
    }
    for (key, (count, f)) in &kinds {
        println!(
            "  {count:5} × {key}\n        first: case {}: {}\n        {}",
            f.case,
            f.command,
            f.detail.replace('\n', "\n        ")
        );
        if let Some(dir) = &f.saved {
            println!("        reproducer: {}", dir.display());
        }
    }
    let _ = std::fs::remove_dir_all(&work);
    if !failures.is_empty() {
        std::process::exit(1);
    }
}

//! `diffsvg batch JOBS.toml`: runs the jobs of a job file (fit, vectorize, digits, render),
//! each as a child process of this binary, in parallel, resumable and shardable; writes
//! `summary.csv`, `summary.json` and `report.html`. See `docs/batch.md`.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;

use anyhow::{Result, anyhow, bail};
use indicatif::ProgressBar;
use serde_json::json;

mod figures;
mod jobfile;
mod report;
mod runner;

use jobfile::{Job, JobFile};
use report::Counts;
use runner::{Context, Outcome};

/// Arguments of `diffsvg batch`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Job file: TOML (`.toml`) or JSON (`.json`); see docs/batch.md.
    jobs_file: PathBuf,
    /// Root output folder (default: the job file's `output`, else `<job file stem>.out`
    /// beside it). Each job writes into `<output>/<job name>/`.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Jobs run at the same time (each child gets cores / N threads).
    #[arg(long, default_value_t = 1, value_name = "N")]
    jobs: usize,
    /// Skip jobs whose manifest shows the same arguments and inputs and whose outputs are
    /// all there; failed jobs stay failed without running again.
    #[arg(long)]
    resume: bool,
    /// With `--resume`, run jobs recorded as failed again.
    #[arg(long)]
    retry_failed: bool,
    /// Run only the jobs whose index is K modulo N (0-based K), e.g. a Slurm array task.
    #[arg(long, value_name = "K/N", value_parser = parse_shard)]
    shard: Option<Shard>,
    /// No progress output (neither a bar nor JSON lines).
    #[arg(long, short)]
    quiet: bool,
}

/// `--shard K/N`: this process runs the jobs whose index is `k` modulo `n`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// 0-based shard number, below `n`.
    pub k: usize,
    /// Number of shards, at least 1.
    pub n: usize,
}

/// Parses `K/N` with `0 ≤ K < N`.
fn parse_shard(s: &str) -> Result<Shard, String> {
    let (k, n) = s
        .split_once('/')
        .ok_or_else(|| format!("{s:?} is not K/N (e.g. 0/4)"))?;
    let parse = |v: &str, what: &str| {
        v.trim()
            .parse::<usize>()
            .map_err(|_| format!("{s:?}: {what} {v:?} is not a whole number ≥ 0"))
    };
    let (k, n) = (parse(k, "K")?, parse(n, "N")?);
    if n == 0 {
        return Err(format!("{s:?}: N must be at least 1"));
    }
    if k >= n {
        return Err(format!(
            "{s:?}: K must be below N (shards are numbered from 0)"
        ));
    }
    Ok(Shard { k, n })
}

/// Runs `diffsvg batch`; returns 0 when every job succeeded (or was complete already), 1
/// when any failed, 2 for a bad job file or bad arguments, 130 when interrupted.
pub fn main(a: Args) -> ExitCode {
    match run(a) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(a: Args) -> Result<ExitCode> {
    if a.jobs == 0 {
        bail!("--jobs must be at least 1");
    }
    let file = jobfile::load(&a.jobs_file)?;
    let root = output_root(&a, &file);
    let todo: Vec<&Job> = file
        .jobs
        .iter()
        .filter(|j| a.shard.is_none_or(|s| j.index % s.n == s.k))
        .collect();
    // Created and written to before any job runs.
    super::progress::check_folder(&root, "output folder")?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let ctx = Context {
        root: root.clone(),
        exe: std::env::current_exe().map_err(|e| anyhow!("cannot find the diffsvg binary: {e}"))?,
        threads: (cores / a.jobs).max(1),
        resume: a.resume,
        retry_failed: a.retry_failed,
    };
    super::progress::install_interrupt_handler();
    let progress = Progress::new(a.quiet, todo.len());
    let outcomes = run_all(&todo, &ctx, a.jobs, &progress);
    let summary = report::write(&root, &a.jobs_file, a.shard, &outcomes)?;
    progress.done(&outcomes, &summary);
    Ok(exit_code(&outcomes))
}

/// `-o`, else the job file's `output`, else `<stem>.out` beside the job file.
fn output_root(a: &Args, file: &JobFile) -> PathBuf {
    if let Some(o) = &a.output {
        return o.clone();
    }
    if let Some(o) = &file.output {
        return o.clone();
    }
    let stem = file
        .path
        .file_stem()
        .map_or_else(|| "batch".into(), |s| s.to_string_lossy().into_owned());
    file.path.with_file_name(format!("{stem}.out"))
}

fn exit_code(outcomes: &[Outcome]) -> ExitCode {
    if super::progress::interrupted() {
        eprintln!("interrupted: jobs that did not finish run again with --resume");
        ExitCode::from(130)
    } else if outcomes.iter().any(Outcome::failed) {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}

/// Runs `todo` on `workers` threads; outcomes in job order.
fn run_all(todo: &[&Job], ctx: &Context, workers: usize, progress: &Progress) -> Vec<Outcome> {
    let next = AtomicUsize::new(0);
    let (tx, rx) = mpsc::channel::<(usize, Outcome)>();
    let mut slots: Vec<Option<Outcome>> = vec![None; todo.len()];
    std::thread::scope(|scope| {
        for _ in 0..workers.min(todo.len()) {
            let tx = tx.clone();
            let next = &next;
            scope.spawn(move || {
                while !super::progress::interrupted() {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    let Some(job) = todo.get(i) else { break };
                    if tx.send((i, runner::run(job, ctx))).is_err() {
                        break;
                    }
                }
            });
        }
        drop(tx);
        for (i, o) in rx {
            progress.finished(&o);
            slots[i] = Some(o);
        }
    });
    slots.into_iter().flatten().collect()
}

/// Progress: a bar on a terminal, one JSON line per finished job otherwise, or nothing.
enum Progress {
    Bar(ProgressBar),
    Json,
    Quiet,
}

impl Progress {
    fn new(quiet: bool, total: usize) -> Self {
        if quiet {
            Progress::Quiet
        } else if let Some(bar) = super::progress::terminal_bar(false, total, "jobs") {
            Progress::Bar(bar)
        } else {
            Progress::Json
        }
    }

    fn finished(&self, o: &Outcome) {
        match self {
            Progress::Bar(bar) => {
                if let Some(e) = o.error.as_deref().filter(|_| o.failed()) {
                    bar.println(format!("failed: {}: {e}", o.name));
                }
                bar.set_message(o.name.clone());
                bar.inc(1);
            }
            Progress::Json => {
                if let Ok(line) = serde_json::to_string(o) {
                    print_line(&line);
                }
            }
            Progress::Quiet => {}
        }
    }

    fn done(&self, outcomes: &[Outcome], summary: &Path) {
        let c = Counts::of(outcomes);
        match self {
            Progress::Bar(bar) => {
                bar.finish_and_clear();
                println!(
                    "batch: {} jobs: {} ok, {} skipped, {} failed; summary {}",
                    outcomes.len(),
                    c.ok,
                    c.skipped,
                    c.failed,
                    summary.display()
                );
            }
            Progress::Json => print_line(
                &json!({"done": true, "jobs": outcomes.len(), "ok": c.ok, "skipped": c.skipped,
                    "failed": c.failed, "summary": summary})
                .to_string(),
            ),
            Progress::Quiet => {}
        }
    }
}

/// Prints a line on stdout and flushes it; a closed stdout is not an error of the batch.
fn print_line(line: &str) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}").and_then(|()| out.flush());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_are_checked() {
        assert_eq!(parse_shard("1/3"), Ok(Shard { k: 1, n: 3 }));
        assert!(parse_shard("3/3").unwrap_err().contains("below N"));
        assert!(parse_shard("0/0").is_err());
        assert!(parse_shard("a/2").is_err());
        assert!(parse_shard("2").is_err());
    }
}

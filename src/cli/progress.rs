//! Progress for long runs: a bar on a terminal, JSON lines with `--json`, nothing else when
//! piped; the iteration log, snapshots and Ctrl-C.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde_json::json;

use diffsvg::fit::{Control, Step};
use diffsvg::image_io::write_atomic;
use diffsvg::raster::{RenderOptions, render};
use diffsvg::scene::Scene;

/// Output flags shared by `fit` and `vectorize`.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ReportArgs {
    /// Write a PNG and an SVG of the current scene into this folder every `--every`
    /// iterations.
    #[arg(long, value_name = "DIR")]
    pub snapshots: Option<PathBuf>,
    /// Snapshot interval in iterations.
    #[arg(long, default_value_t = 50, value_name = "K")]
    pub every: usize,
    /// Write one row per iteration (iteration, loss, PSNR, elapsed ms): JSON lines when
    /// the name ends in .json or .jsonl, CSV otherwise.
    #[arg(long, value_name = "FILE")]
    pub log: Option<PathBuf>,
    /// Print one JSON object per iteration and a summary object on stdout instead of a
    /// progress bar.
    #[arg(long)]
    pub json: bool,
    /// No progress output (the summary line is still printed).
    #[arg(long, short)]
    pub quiet: bool,
}

impl ReportArgs {
    /// Checks, before a run, that every output these flags name can be written: the
    /// `--snapshots` folder is created and written to, the `--log` file's folder too. A
    /// run then cannot stop at its first snapshot, or fail at its end, for want of a place
    /// to write.
    pub fn check_outputs(&self) -> Result<()> {
        if let Some(dir) = &self.snapshots {
            if self.every == 0 {
                anyhow::bail!("--every must be at least 1 with --snapshots");
            }
            check_folder(dir, "--snapshots")?;
        }
        if let Some(log) = &self.log {
            if log.is_dir() {
                anyhow::bail!("--log {}: is a folder", log.display());
            }
            let parent = match log.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => std::path::Path::new("."),
            };
            check_folder(parent, "--log")?;
        }
        Ok(())
    }
}

/// Creates `dir` (with its parents) and checks that a file can be written in it; errors
/// name `flag` and the folder.
pub fn check_folder(dir: &std::path::Path, flag: &str) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{flag} {}: cannot create the folder", dir.display()))?;
    let probe = dir.join(format!(".diffsvg-probe-{}", std::process::id()));
    std::fs::write(&probe, b"")
        .with_context(|| format!("{flag} {}: folder is not writable", dir.display()))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

static INTERRUPTED: AtomicBool = AtomicBool::new(false);
static HANDLER: OnceLock<()> = OnceLock::new();

/// Whether Ctrl-C was pressed since the handler was installed.
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

/// Installs (once per process) the Ctrl-C handler that sets [`interrupted`].
pub fn install_interrupt_handler() {
    HANDLER.get_or_init(|| {
        // If a handler cannot be installed (another one exists), Ctrl-C just kills the
        // process as usual; outputs are still never half-written.
        let _ = ctrlc::set_handler(|| INTERRUPTED.store(true, Ordering::SeqCst));
    });
}

/// The one progress bar style of every command: a bar on stdout when it is a terminal and
/// neither `--json` nor `--quiet` asked for something else, `None` otherwise. `unit` names
/// what is counted (iterations, digits, jobs; may be empty).
pub fn terminal_bar(json_or_quiet: bool, total: usize, unit: &str) -> Option<ProgressBar> {
    if json_or_quiet || !std::io::stdout().is_terminal() {
        return None;
    }
    let b = ProgressBar::with_draw_target(Some(total as u64), ProgressDrawTarget::stdout());
    let template =
        format!("{{bar:30.cyan/blue}} {{pos}}/{{len}} {unit} {{msg}} {{per_sec}} ETA {{eta}}");
    b.set_style(ProgressStyle::with_template(&template).expect("valid template"));
    Some(b)
}

/// Follows a run: progress, log rows, snapshots, Ctrl-C.
pub struct Reporter {
    args: ReportArgs,
    bar: Option<ProgressBar>,
    log: String,
    iter: usize,
    phase: String,
    background: Option<[f32; 4]>,
    /// The first error met while writing a snapshot; it stops the run.
    pub error: Option<anyhow::Error>,
}

impl Reporter {
    /// A reporter for about `total` iterations. Installs the Ctrl-C handler (once per
    /// process): the first Ctrl-C asks the run to stop and write its best result.
    pub fn new(args: &ReportArgs, total: usize, background: Option<[f32; 4]>) -> Self {
        install_interrupt_handler();
        let bar = terminal_bar(args.json || args.quiet, total, "");
        let log = match &args.log {
            Some(p) if !is_jsonl(p) => "iteration,phase,loss,psnr,elapsed_ms\n".to_string(),
            _ => String::new(),
        };
        Reporter {
            args: args.clone(),
            bar,
            log,
            iter: 0,
            phase: String::new(),
            background,
            error: None,
        }
    }

    /// Names the current phase (e.g. `round 3, 24 paths`), shown and logged.
    pub fn set_phase(&mut self, phase: impl Into<String>) {
        self.phase = phase.into();
    }

    /// Records one evaluation; returns whether the run should go on.
    pub fn step(&mut self, s: &Step, scene: &Scene) -> Control {
        let ms = s.elapsed.as_secs_f64() * 1e3;
        if let Some(p) = &self.args.log {
            if is_jsonl(p) {
                self.log += &json!({"iteration": self.iter, "phase": self.phase, "loss": s.loss,
                    "psnr": finite(s.psnr), "elapsed_ms": ms})
                .to_string();
                self.log.push('\n');
            } else {
                self.log += &format!(
                    "{},{},{},{},{:.3}\n",
                    self.iter,
                    csv_field(&self.phase),
                    s.loss,
                    s.psnr,
                    ms
                );
            }
        }
        if self.args.json {
            println!(
                "{}",
                json!({"iteration": self.iter, "phase": self.phase, "loss": s.loss,
                    "psnr": finite(s.psnr), "elapsed_ms": ms})
            );
        }
        if let Some(b) = &self.bar {
            b.set_position(self.iter as u64);
            let phase = if self.phase.is_empty() {
                String::new()
            } else {
                format!("{}  ", self.phase)
            };
            b.set_message(format!("{phase}loss {:.3e}  PSNR {:.2} dB", s.loss, s.psnr));
        }
        if let Some(dir) = &self.args.snapshots
            && self.args.every > 0
            && self.iter.is_multiple_of(self.args.every)
            && let Err(e) = snapshot(dir, self.iter, scene, self.background)
        {
            self.error = Some(e);
            return Control::Stop;
        }
        self.iter += 1;
        if interrupted() {
            Control::Stop
        } else {
            Control::Continue
        }
    }

    /// Clears the bar and writes the log; returns the first snapshot error instead, if
    /// any, writing no log (a failed run leaves no outputs).
    pub fn finish(mut self) -> Result<()> {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        if let Some(p) = &self.args.log {
            write_atomic(p, self.log.as_bytes())?;
        }
        Ok(())
    }
}

fn is_jsonl(p: &std::path::Path) -> bool {
    matches!(
        p.extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref(),
        Some("json" | "jsonl")
    )
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// JSON has no infinity: an exact match reports `null` PSNR.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

fn snapshot(dir: &std::path::Path, iter: usize, scene: &Scene, bg: Option<[f32; 4]>) -> Result<()> {
    let mut img = render(scene, &RenderOptions::default());
    if let Some(bg) = bg {
        img.over_background(bg);
    }
    img.save_png(dir.join(format!("{iter:06}.png")))
        .with_context(|| format!("{}: cannot write snapshot", dir.display()))?;
    scene.save_svg(dir.join(format!("{iter:06}.svg")))?;
    Ok(())
}

//! `diffsvg vectorize`: an SVG from a picture.

use std::path::PathBuf;

use anyhow::{Result, bail};
use serde_json::json;

use super::choices::{InitArg, among};
use super::fit::OptimArgs;
use super::progress::{ReportArgs, Reporter};
use super::util::{FontArgs, check_output, flag_error, sibling};
use diffsvg::choice::Choice as _;
use diffsvg::fit::load_target_with;
use diffsvg::fit::vectorize::{Event, Mode, VectorizeOptions, vectorize};
use diffsvg::image_io::side_by_side;
use diffsvg::raster::render;

/// Arguments of `diffsvg vectorize`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Target picture: PNG or JPEG, or an SVG rendered at its own size.
    target: PathBuf,
    /// Output SVG (written atomically).
    #[arg(short, long)]
    output: PathBuf,
    /// How paths are found [default: adaptive].
    #[arg(long, ignore_case = true, value_parser = among(&[Mode::Adaptive, Mode::Fixed, Mode::Painterly]))]
    mode: Option<Mode>,
    /// Start from a classical tracing instead of from nothing (not with `--mode`).
    #[arg(long, value_enum, ignore_case = true)]
    init: Option<InitArg>,
    /// Path budget (fixed and painterly: the count) [default: 64; not with
    /// `--target-psnr`, which takes `--max-paths`].
    #[arg(long)]
    paths: Option<usize>,
    /// Stop adding paths (adaptive) or optimizing once the PSNR reaches this.
    #[arg(long, value_name = "DB")]
    target_psnr: Option<f64>,
    /// Budget with `--target-psnr` [default: 512].
    #[arg(long, requires = "target_psnr")]
    max_paths: Option<usize>,
    /// Cubic segments per new closed path (adaptive only) [default: 4].
    #[arg(long)]
    segments: Option<usize>,
    /// Seed of the random initial shapes (fixed and painterly only) [default: 0].
    #[arg(long)]
    seed: Option<u64>,
    /// Optimizer steps in all rounds together (0: place the paths, optimize nothing).
    #[arg(long, default_value_t = 1000)]
    iters: usize,
    /// Resize the target to this width first (height keeps the aspect ratio).
    #[arg(long)]
    width: Option<u32>,
    /// Also write `<output>.compare.png`: target and result side by side.
    #[arg(long)]
    compare: bool,
    /// Render and differentiate the exact coverage where a path overlaps itself (as
    /// `fit --exact-overlaps`); without it those pixels take the clamped winding
    /// integral, which over-covers them.
    #[arg(long)]
    exact_overlaps: bool,
    #[command(flatten)]
    optim: OptimArgs,
    /// The fonts of an SVG target's `<text>`.
    #[command(flatten)]
    fonts: FontArgs,
    #[command(flatten)]
    report: ReportArgs,
}

/// Runs `diffsvg vectorize`.
pub fn run(a: Args) -> Result<()> {
    check_output(&a.output, "svg")?;
    let compare_path = sibling(&a.output, "compare");
    if a.compare {
        check_output(&compare_path, "png")?;
    }
    let mode = match (a.init, a.mode) {
        (Some(_), Some(m)) => bail!(
            "--init trace and --mode {} cannot be combined: tracing is a mode of its own",
            m.name()
        ),
        (Some(InitArg::Trace), None) => Mode::Trace,
        (None, m) => m.unwrap_or_default(),
    };
    if a.segments.is_some() && mode != Mode::Adaptive {
        bail!("--segments applies to --mode adaptive only (the paths it adds)");
    }
    if a.seed.is_some() && !matches!(mode, Mode::Fixed | Mode::Painterly) {
        bail!("--seed applies to --mode fixed and painterly only (their random shapes)");
    }
    if a.target_psnr.is_some() && a.optim.until_psnr.is_some() {
        bail!(
            "--target-psnr and --until-psnr cannot be combined (vectorize stops at --target-psnr)"
        );
    }
    let paths = match (a.target_psnr, a.paths) {
        (Some(_), Some(_)) => {
            bail!("--paths and --target-psnr cannot be combined: the budget is --max-paths")
        }
        (Some(_), None) => a.max_paths.unwrap_or(512),
        (None, p) => p.unwrap_or(64),
    };
    let mut fit = a.optim.fit_options(a.iters)?;
    fit.render.exact_overlaps = a.exact_overlaps;
    let defaults = VectorizeOptions::default();
    let opts = VectorizeOptions {
        mode,
        paths,
        target_psnr: a.target_psnr.or(a.optim.until_psnr),
        segments: a.segments.unwrap_or(defaults.segments),
        iters: a.iters,
        fit,
        seed: a.seed.unwrap_or(defaults.seed),
    };
    // The budget is `--max-paths` with `--target-psnr`, and `--paths` otherwise.
    opts.validate().map_err(|e| match e {
        diffsvg::Error::Setting { name, message } if name == "paths" && a.target_psnr.is_some() => {
            flag_error(diffsvg::Error::Setting {
                name: "max_paths".into(),
                message,
            })
        }
        e => flag_error(e),
    })?;
    let mut target = load_target_with(&a.target, None, &a.fonts.fonts())?;
    if let Some(w) = a.width {
        if w == 0 {
            bail!("--width must be at least 1 pixel");
        }
        let h = ((target.height as f64 * w as f64 / target.width as f64).round() as u32).max(1);
        target = target.resized_checked(w, h, std::path::Path::new("--width"))?;
    }
    let objective = a.optim.objective(&target)?;
    // Last of the checks, as it creates the snapshots folder: inputs were good.
    a.report.check_outputs()?;
    let mut reporter = Reporter::new(&a.report, a.iters + 1, objective.background());
    let out = vectorize(&objective, &opts, &mut |e| match e {
        Event::Round { round, paths } => {
            reporter.set_phase(format!("round {round}, {paths} paths"));
            diffsvg::fit::Control::Continue
        }
        Event::Step(s, sc) => reporter.step(s, sc),
    });
    // A snapshot that could not be written fails the run before anything is written.
    reporter.finish()?;
    let out = out?;
    let compare = a.compare.then(|| {
        let img = objective.composite(&render(&out.scene, &opts.fit.render));
        side_by_side(&[objective.target(), &img])
    });
    out.scene.save_svg(&a.output)?;
    // All or nothing: no SVG without the comparison asked for.
    if let Some(Err(e)) = compare.map(|img| img.save_png(&compare_path)) {
        let _ = std::fs::remove_file(&a.output);
        return Err(e.into());
    }
    let secs = out.elapsed.as_secs_f64();
    let n = out.scene.path_count();
    if a.report.json {
        println!(
            "{}",
            json!({"done": true, "output": a.output, "mode": mode.name(),
                "paths": n, "psnr": out.psnr, "mse": out.mse, "steps": out.steps,
                "rounds": out.rounds, "pruned": out.pruned, "seconds": secs,
                "step_ms": out.median_step_ms})
        );
    } else {
        println!(
            "vectorize ({}): {n} paths, PSNR {:.2} dB, MSE {:.5}, {} steps in {} round(s), {} pruned, {secs:.2} s; wrote {}",
            mode.name(),
            out.psnr,
            out.mse,
            out.steps,
            out.rounds,
            out.pruned,
            a.output.display()
        );
    }
    if super::progress::interrupted() {
        eprintln!("interrupted: the best result so far was written");
    }
    Ok(())
}

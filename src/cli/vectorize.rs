//! `diffsvg vectorize`: an SVG from a picture.

use std::path::PathBuf;

use anyhow::{Result, bail};
use serde_json::json;

use super::fit::{OptimArgs, load_target};
use super::progress::{ReportArgs, Reporter};
use super::util::{check_output, sibling};
use crate::fit::vectorize::{Event, Mode, VectorizeOptions, vectorize};
use crate::image_io::side_by_side;
use crate::raster::{RenderOptions, render};

/// Arguments of `diffsvg vectorize`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Target picture: PNG or JPEG, or an SVG rendered at its own size.
    target: PathBuf,
    /// Output SVG (written atomically).
    #[arg(short, long)]
    output: PathBuf,
    /// How paths are found: adaptive (add where the error is largest, prune the useless),
    /// fixed (DiffVG's random blobs), painterly (DiffVG's random strokes).
    #[arg(long, default_value = "adaptive")]
    mode: String,
    /// Start from a classical tracing (`trace`: vtracer's photo preset, pruned to the
    /// budget) instead of from nothing.
    #[arg(long)]
    init: Option<String>,
    /// Path budget (fixed and painterly: the count).
    #[arg(long, default_value_t = 64)]
    paths: usize,
    /// Adaptive: stop adding paths once the PSNR reaches this (then `--max-paths` is the
    /// budget).
    #[arg(long, value_name = "DB")]
    target_psnr: Option<f64>,
    /// Budget with `--target-psnr`.
    #[arg(long, default_value_t = 512)]
    max_paths: usize,
    /// Cubic segments per new closed path.
    #[arg(long, default_value_t = 4)]
    segments: usize,
    /// Optimizer steps in all rounds together (0: place the paths, optimize nothing).
    #[arg(long, default_value_t = 1000)]
    iters: usize,
    /// Resize the target to this width first (height keeps the aspect ratio).
    #[arg(long)]
    width: Option<u32>,
    /// Also write `<output>.compare.png`: target and result side by side.
    #[arg(long)]
    compare: bool,
    #[command(flatten)]
    optim: OptimArgs,
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
    let mut mode: Mode = a
        .mode
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--mode: {e}"))?;
    match a.init.as_deref() {
        None => {}
        Some("trace") => mode = Mode::Trace,
        Some(other) => bail!("--init {other:?}: unknown (expected trace)"),
    }
    if a.segments < 2 || a.segments > 64 {
        bail!("--segments {} must be between 2 and 64", a.segments);
    }
    let paths = if a.target_psnr.is_some() {
        a.max_paths
    } else {
        a.paths
    };
    if paths == 0 {
        bail!("the path budget must be at least 1");
    }
    if a.target_psnr.is_some_and(|p| !p.is_finite()) {
        bail!("--target-psnr must be a finite number");
    }
    let fit = a.optim.fit_options(a.iters)?;
    let mut target = load_target(&a.target)?;
    if let Some(w) = a.width {
        if w == 0 {
            bail!("--width must be at least 1 pixel");
        }
        let h = ((target.height as f64 * w as f64 / target.width as f64).round() as u32).max(1);
        target = target.resized_checked(w, h, std::path::Path::new("--width"))?;
    }
    let objective = a.optim.objective(&target)?;
    let opts = VectorizeOptions {
        mode,
        paths,
        target_psnr: a.target_psnr.or(a.optim.until_psnr),
        segments: a.segments,
        iters: a.iters,
        fit,
        seed: a.optim.seed,
    };
    // Last of the checks, as it creates the snapshots folder: inputs were good.
    a.report.check_outputs()?;
    let mut reporter = Reporter::new(&a.report, a.iters + 1, objective.background());
    let out = vectorize(&objective, &opts, &mut |e| match e {
        Event::Round { round, paths } => {
            reporter.set_phase(format!("round {round}, {paths} paths"));
            crate::fit::Control::Continue
        }
        Event::Step(s, sc) => reporter.step(s, sc),
    });
    // A snapshot that could not be written fails the run before anything is written.
    reporter.finish()?;
    let out = out?;
    let compare = a.compare.then(|| {
        let img = objective.composite(&render(&out.scene, &RenderOptions::default()));
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
            json!({"done": true, "output": a.output, "mode": format!("{mode:?}").to_lowercase(),
                "paths": n, "psnr": out.psnr, "mse": out.mse, "steps": out.steps,
                "rounds": out.rounds, "pruned": out.pruned, "seconds": secs,
                "forward_ms": out.median_ms.0, "backward_ms": out.median_ms.1})
        );
    } else {
        println!(
            "vectorize ({}): {n} paths, PSNR {:.2} dB, MSE {:.5}, {} steps in {} round(s), {} pruned, {secs:.2} s; wrote {}",
            format!("{mode:?}").to_lowercase(),
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
        std::process::exit(130);
    }
    Ok(())
}

//! `diffsvg recon splat`: fit 3D Gaussians to posed photos, with the progress bar, log
//! CSV, PSNR plot and Ctrl-C behaviour of `recon voxel`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Result, bail};
use serde_json::json;

use super::progress::{install_interrupt_handler, interrupted};
use super::volume::{Reporting, check_bound, sibling, write_psnr_plot};
use diffsvg::glam::Vec3;
use diffsvg::image_io::write_atomic;
use diffsvg::limits::MAX_GAUSSIANS;
use diffsvg::volume::dataset::{Dataset, View};
use diffsvg::volume::metrics::psnr;
use diffsvg::volume::splat::{self, Densify, Gaussians, RenderSettings, TrainOptions, TrainStep};

/// Arguments of `diffsvg recon splat`.
#[derive(clap::Args, Debug)]
pub struct SplatArgs {
    /// Dataset folder: NeRF-synthetic (transforms_train.json) or instant-ngp
    /// (transforms.json; photos with lens distortion are undistorted once, in memory).
    #[arg(long)]
    scene: PathBuf,
    /// Model file to write (.ply, the layout Gaussian-splatting viewers read).
    #[arg(short, long)]
    output: PathBuf,
    /// Optimizer iterations (one training view each).
    #[arg(long, default_value_t = 5000)]
    iters: usize,
    /// Divide image sizes by this integer.
    #[arg(long, default_value_t = 1)]
    downscale: u32,
    /// Most Gaussians the model may hold.
    #[arg(long, default_value_t = 300_000)]
    max_gaussians: usize,
    /// Gaussians to start from when the folder has no point cloud (points3d.ply,
    /// sparse_pc.ply or points.ply): placed at random in the scene's box.
    #[arg(long, default_value_t = 50_000)]
    initial: usize,
    /// Highest spherical-harmonic degree of the color, 0 to 3 (raised from 0 over the
    /// run).
    #[arg(long, default_value_t = 3)]
    degree: u32,
    /// Half the side of the box of the random initial points, world units (default: the
    /// cameras' median distance from where they look, times 0.4 for objects on white or 1
    /// for real photos).
    #[arg(long)]
    bound: Option<f32>,
    /// Random seed of the initial points, the view order and the splits.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    report: Reporting,
}

/// Runs `diffsvg recon splat`.
pub fn run(a: SplatArgs) -> Result<()> {
    super::util::check_output(&a.output, "ply")?;
    if a.max_gaussians == 0 || a.max_gaussians > MAX_GAUSSIANS {
        bail!(
            "--max-gaussians {} must be between 1 and {MAX_GAUSSIANS}",
            a.max_gaussians
        );
    }
    if a.degree > 3 {
        bail!("--degree {} must be 0 to 3", a.degree);
    }
    if a.downscale == 0 || a.iters == 0 || a.initial == 0 {
        bail!("--downscale, --iters and --initial must be at least 1");
    }
    if a.initial > MAX_GAUSSIANS {
        bail!("--initial {} is above {MAX_GAUSSIANS}", a.initial);
    }
    let t_load = Instant::now();
    let data = load_dataset(&a.scene, a.downscale)?;
    let settings = RenderSettings {
        background: background(&data),
        ..RenderSettings::default()
    };
    let (center, dist) = data.focus();
    let half = match a.bound {
        Some(b) if !(b.is_finite() && b > 0.0) => bail!("--bound {b} must be a positive number"),
        Some(b) => {
            // As for `recon voxel`: a box far too large or small for the cameras (or for
            // f32) would start from Gaussians of infinite or zero size.
            check_bound(b, center, dist)?;
            b
        }
        None => dist * if data.white_background { 0.4 } else { 1.0 },
    };
    if !(half.is_finite() && half > 0.0 && center.is_finite()) {
        bail!(
            "{}: cannot size the box from the cameras (median distance {dist} from {center}); \
             give --bound",
            a.scene.display()
        );
    }
    let mut model = match splat::find_point_cloud(&a.scene) {
        Some(path) => splat::from_point_cloud(&path, a.degree)?,
        None => splat::random_init(
            center,
            half,
            a.initial.min(a.max_gaussians),
            a.degree,
            a.seed,
        ),
    };
    let extent = camera_extent(&data.train);
    let iters = a.iters;
    // The reference schedule (30 000 iterations: densify 500..15 000 every 100, reset
    // opacity every 3000, SH degree up every 1000) scaled to the run's length.
    let scaled = |x: usize| ((x as f64 * iters as f64 / 30_000.0).round() as usize).max(1);
    let opts = TrainOptions {
        iterations: iters,
        seed: a.seed,
        render: settings,
        sh_degree: a.degree,
        sh_interval: scaled(1000).max(iters / 8),
        extent,
        densify: Densify {
            from: scaled(500),
            until: iters / 2,
            every: scaled(100).clamp(25, 100),
            reset_every: scaled(3000).max(200),
            max_gaussians: a.max_gaussians,
            ..Densify::default()
        },
        ..TrainOptions::default()
    };
    let load_s = t_load.elapsed().as_secs_f64();

    install_interrupt_handler();
    let bar = super::progress::terminal_bar(a.report.json || a.report.quiet, iters, "");
    let mut log: Vec<(TrainStep, Option<f64>)> = Vec::new();
    let outcome = splat::train(&mut model, &data.train, &opts, &mut |s, g| {
        let eval = a.report.eval_every > 0
            && s.iteration % a.report.eval_every == 0
            && s.iteration < iters
            && !data.test.is_empty();
        let test = if eval {
            mean_psnr(g, &data.test, &settings).ok()
        } else {
            None
        };
        if test.is_some() || s.iteration % 50 == 0 {
            log.push((*s, test));
        }
        if let Some(b) = &bar {
            b.set_position(s.iteration as u64);
            b.set_message(format!(
                "loss {:.4}  PSNR {:.2} dB  {} Gaussians  SH {}",
                s.loss, s.psnr, s.gaussians, s.sh_degree
            ));
            if let Some(p) = test {
                b.println(format!(
                    "iteration {}: test PSNR {p:.2} dB after {:.0} s, {} Gaussians",
                    s.iteration, s.elapsed, s.gaussians
                ));
            }
        }
        if a.report.json && (s.iteration % 50 == 0 || test.is_some()) {
            println!(
                "{}",
                json!({"iteration": s.iteration, "loss": s.loss, "psnr": s.psnr,
                    "gaussians": s.gaussians, "sh_degree": s.sh_degree,
                    "elapsed": s.elapsed, "test_psnr": test})
            );
        }
        !interrupted()
    })?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    splat::save(&model, &a.output)?;
    let test_psnr = if data.test.is_empty() {
        None
    } else {
        Some(mean_psnr(&model, &data.test, &settings)?)
    };
    // The final row (written by write_log) carries the end of the run.
    log.retain(|r| r.0.iteration != outcome.iterations);
    write_log(
        &a.output,
        &log,
        outcome.iterations,
        outcome.seconds,
        model.len(),
        test_psnr,
    )?;
    let [r, l, b, u, d] = outcome.parts;
    if a.report.json {
        println!(
            "{}",
            json!({"done": true, "output": a.output, "iterations": outcome.iterations,
                "seconds": outcome.seconds, "load_seconds": load_s, "test_psnr": test_psnr,
                "gaussians": model.len(), "stopped": outcome.stopped,
                "seconds_per_part": {"render": r, "loss": l, "backward": b, "update": u,
                    "density_control": d}})
        );
    } else {
        println!(
            "recon splat: {} iterations in {:.1} s ({:.0}% render, {:.0}% loss, {:.0}% backward, \
             {:.0}% update, {:.0}% density control), {} Gaussians, test PSNR {}; wrote {}",
            outcome.iterations,
            outcome.seconds,
            100.0 * r / outcome.seconds,
            100.0 * l / outcome.seconds,
            100.0 * b / outcome.seconds,
            100.0 * u / outcome.seconds,
            100.0 * d / outcome.seconds,
            model.len(),
            test_psnr
                .map(|p| format!("{p:.2} dB"))
                .unwrap_or_else(|| "n/a (no test views)".into()),
            a.output.display()
        );
    }
    if outcome.stopped {
        eprintln!("interrupted: the model so far was written");
    }
    Ok(())
}

/// Loads a dataset for splatting: photos with lens distortion are undistorted (a
/// rasterizer projects through a pinhole), with a note on stderr.
pub(super) fn load_dataset(dir: &Path, downscale: u32) -> Result<Dataset> {
    let data = Dataset::load(dir, downscale)?;
    if data.train.is_empty() {
        bail!("{}: no training views", dir.display());
    }
    let distorted = data
        .train
        .iter()
        .chain(&data.test)
        .any(|v| v.camera.has_distortion());
    if !distorted {
        return Ok(data);
    }
    let (data, outside) = diffsvg::volume::undistort::undistort_dataset(&data);
    let total: usize = data
        .train
        .iter()
        .chain(&data.test)
        .map(|v| v.rgb.len())
        .sum();
    eprintln!(
        "note: {}: the photos have lens distortion; undistorted to pinhole views ({:.2}% of \
         pixels fell outside the photos and repeat its edge)",
        dir.display(),
        100.0 * outside as f64 / total.max(1) as f64
    );
    Ok(data)
}

/// White for objects composited over white (NeRF-synthetic), black for real photos.
pub(super) fn background(data: &Dataset) -> [f32; 3] {
    if data.white_background {
        [1.0; 3]
    } else {
        [0.0; 3]
    }
}

/// The reference code's scene extent: 1.1 times the largest distance of a training
/// camera from the cameras' mean position (1 when that is 0).
fn camera_extent(views: &[View]) -> f32 {
    let n = views.len().max(1) as f32;
    let mean = views
        .iter()
        .map(|v| v.camera.position())
        .fold(Vec3::ZERO, |a, b| a + b)
        / n;
    let r = views
        .iter()
        .map(|v| v.camera.position().distance(mean))
        .fold(0.0f32, f32::max);
    if r > 0.0 && r.is_finite() {
        1.1 * r
    } else {
        1.0
    }
}

/// Mean PSNR (capped at 99 dB per view) of `model` rendered from `views`.
pub(super) fn mean_psnr(
    model: &Gaussians,
    views: &[View],
    settings: &RenderSettings,
) -> Result<f64> {
    let mut sum = 0.0;
    for v in views {
        let out = splat::render(model, &v.camera, settings)
            .map_err(|e| anyhow::anyhow!("rendering view {}: {e}", v.name))?;
        sum += psnr(&out.rgb, &v.rgb).min(99.0);
    }
    Ok(sum / views.len().max(1) as f64)
}

/// Writes `<model>.log.csv` (iteration, training seconds, Gaussians, SH degree, training
/// view PSNR, test PSNR where evaluated; the last row is the end of the run) and the
/// PSNR plot.
fn write_log(
    model: &Path,
    rows: &[(TrainStep, Option<f64>)],
    iterations: usize,
    seconds: f32,
    gaussians: usize,
    test: Option<f64>,
) -> Result<()> {
    let mut csv = String::from("iteration,seconds,gaussians,sh_degree,view_psnr,test_psnr\n");
    let cell = |t: Option<f64>| t.map(|p| format!("{p:.3}")).unwrap_or_default();
    for (s, t) in rows {
        let _ = writeln!(
            csv,
            "{},{:.3},{},{},{:.3},{}",
            s.iteration,
            s.elapsed,
            s.gaussians,
            s.sh_degree,
            s.psnr,
            cell(*t)
        );
    }
    let last_degree = rows.last().map(|r| r.0.sh_degree).unwrap_or(0);
    let last_psnr = rows
        .last()
        .map(|r| format!("{:.3}", r.0.psnr))
        .unwrap_or_default();
    let _ = writeln!(
        csv,
        "{iterations},{seconds:.3},{gaussians},{last_degree},{last_psnr},{}",
        cell(test)
    );
    write_atomic(&sibling(model, ".log.csv"), csv.as_bytes())?;
    let mut tests: Vec<(f64, f64)> = rows
        .iter()
        .filter_map(|(s, t)| t.map(|p| (s.elapsed as f64, p)))
        .collect();
    if let Some(p) = test {
        tests.push((seconds as f64, p));
    }
    let views = rows
        .iter()
        .map(|(s, _)| (s.elapsed as f64, s.psnr as f64))
        .collect();
    write_psnr_plot(model, tests, views, "training views")
}

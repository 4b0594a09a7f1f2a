//! `diffsvg recon splat`: fit 3D Gaussians to posed photos, with the progress bar, log
//! CSV, PSNR plot and Ctrl-C behaviour of `recon voxel`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Result;
use serde_json::json;

use super::progress::{install_interrupt_handler, interrupted};
use super::recon_report::{Reporting, psnr_text, sibling, undistortion_note, write_psnr_plot};
use super::util::flag_error;
use diffsvg::image_io::write_atomic;
use diffsvg::volume::recon::{SplatJob, recon_splat};
use diffsvg::volume::splat::{self, TrainStep};

/// Arguments of `diffsvg recon splat`.
#[derive(clap::Args, Debug)]
pub struct SplatArgs {
    /// Dataset folder: NeRF-synthetic (transforms_train.json), instant-ngp
    /// (transforms.json) or COLMAP (sparse/0/cameras.bin or .txt, photos in images/);
    /// photos with lens distortion are undistorted once, in memory.
    #[arg(long)]
    scene: PathBuf,
    /// Model file to write: .ply, the layout Gaussian-splatting viewers read, or .spz,
    /// Niantic's compressed format (about a tenth of the size; quantized).
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
    /// sparse_pc.ply or points.ply, or COLMAP's points3D): placed at random in the scene's
    /// box.
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
    /// Instant-ngp and COLMAP folders: hold out the views at positions 0, N, 2N, … (file
    /// order for instant-ngp, sorted by name for COLMAP) as test views; 0: none (default:
    /// every 8th). NeRF-synthetic folders use transforms_test.json.
    #[arg(long, value_name = "N")]
    test_every: Option<usize>,
    /// Instant-ngp and COLMAP folders: the test views are those named in FILE, one a
    /// line (COLMAP: the image's name, such as test/r_0.png; instant-ngp: the frame's
    /// file_path), instead of every N-th; to_colmap writes the source's as DIR/test.txt.
    #[arg(long, value_name = "FILE", conflicts_with = "test_every")]
    test_list: Option<PathBuf>,
    /// Anti-aliased splats (Mip-Splatting's 2D filter, gsplat's antialiased mode): each
    /// splat's opacity is scaled by √(det Σ / det(Σ + 0.3·I)) so that the model renders
    /// cleanly at other resolutions. Saved in the model; `view` renders it the same way.
    #[arg(long)]
    antialias: bool,
    /// Learn a per-image affine color transform (3×3 and a bias, from the identity) of
    /// each training photo, for photos of differing exposure or white balance; test views
    /// are rendered without.
    #[arg(long)]
    exposure: bool,
    /// A fixed budget of --max-gaussians Gaussians (3DGS-MCMC): transparent Gaussians
    /// are relocated onto opaque ones, and the count grows 5% at a time up to the budget,
    /// instead of cloning and splitting.
    #[arg(long)]
    mcmc: bool,
    #[command(flatten)]
    poses: super::recon_report::PoseArgs,
    #[command(flatten)]
    report: Reporting,
}

/// Runs `diffsvg recon splat`.
pub fn run(a: SplatArgs) -> Result<()> {
    let spz = a
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("spz"));
    super::util::check_output(&a.output, if spz { "spz" } else { "ply" })?;
    let job = SplatJob {
        iters: a.iters,
        downscale: a.downscale,
        max_gaussians: a.max_gaussians,
        initial: a.initial,
        degree: a.degree,
        bound: a.bound,
        seed: a.seed,
        eval_every: a.report.eval_every,
        test_every: a.test_every,
        test_list: a.test_list,
        antialias: a.antialias,
        exposure: a.exposure,
        mcmc: a.mcmc,
        refine_poses: a.poses.refine_poses,
        perturb_poses: a.poses.perturb_poses,
    };
    job.validate().map_err(flag_error)?;
    install_interrupt_handler();
    let bar = super::progress::terminal_bar(a.report.json || a.report.quiet, a.iters, "");
    let out = recon_splat(&a.scene, &job, &mut |s, test| {
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
    })
    .map_err(flag_error)?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    if let Some(outside) = out.undistorted {
        undistortion_note(&a.scene, outside);
    }
    super::util::print_warnings(&out.warnings);
    let (model, outcome) = (&out.model, &out.outcome);
    if spz {
        splat::save_spz(model, &a.output)?;
    } else {
        splat::save(model, &a.output)?;
    }
    write_log(
        &a.output,
        &out.log,
        outcome.iterations,
        outcome.seconds,
        model.len(),
        out.test_psnr,
    )?;
    let [r, l, b, u, d] = outcome.parts;
    if a.report.json {
        println!(
            "{}",
            json!({"done": true, "output": a.output, "iterations": outcome.iterations,
                "seconds": outcome.seconds, "load_seconds": out.load_seconds,
                "test_psnr": out.test_psnr, "test_psnr_in_frame": out.test_psnr_in_frame, "gaussians": model.len(), "stopped": outcome.stopped,
                "pose_error": super::recon_report::pose_error_json(&out.pose_error),
                "seconds_per_part": {"render": r, "loss": l, "backward": b, "update": u,
                    "density_control": d}})
        );
    } else {
        println!(
            "recon splat: {} iterations in {:.1} s ({:.0}% render, {:.0}% loss, {:.0}% backward, \
             {:.0}% update, {:.0}% density control), {} Gaussians, test PSNR {}{}; wrote {}",
            outcome.iterations,
            outcome.seconds,
            100.0 * r / outcome.seconds,
            100.0 * l / outcome.seconds,
            100.0 * b / outcome.seconds,
            100.0 * u / outcome.seconds,
            100.0 * d / outcome.seconds,
            model.len(),
            psnr_text(out.test_psnr),
            super::recon_report::pose_error_text(&out.pose_error, out.test_psnr_in_frame),
            a.output.display()
        );
    }
    if outcome.stopped {
        eprintln!("interrupted: the model so far was written");
    }
    Ok(())
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

//! `diffsvg recon ngp`: fit an Instant-NGP neural field (hash grid and tiny MLPs) to
//! posed photos.

use std::path::PathBuf;

use anyhow::Result;
use serde_json::json;

use super::progress::{install_interrupt_handler, interrupted};
use super::recon_report::{Reporting, psnr_text};
use super::util::flag_error;
use diffsvg::volume::field;
use diffsvg::volume::recon::{NgpJob, recon_ngp};

/// Arguments of `diffsvg recon ngp`.
#[derive(clap::Args, Debug)]
pub struct NgpArgs {
    /// Dataset folder: NeRF-synthetic (transforms_train.json), instant-ngp
    /// (transforms.json) or COLMAP (sparse/0/cameras.bin or .txt, photos in images/).
    #[arg(long)]
    scene: PathBuf,
    /// Model file to write (.ngp).
    #[arg(short, long)]
    output: PathBuf,
    /// Optimizer iterations (mini-batches of rays).
    #[arg(long, default_value_t = NgpJob::default().iters)]
    iters: usize,
    /// Training time budget in seconds (0: none); training stops when it is spent, and
    /// the learning rate decays over it.
    #[arg(long, default_value_t = 0.0)]
    seconds: f32,
    /// Most rays per iteration.
    #[arg(long, default_value_t = NgpJob::default().batch)]
    batch: usize,
    /// Samples (network evaluations) aimed at per iteration: the rays per iteration
    /// follow the samples per ray (0: always --batch rays).
    #[arg(long, default_value_t = NgpJob::default().samples)]
    samples: usize,
    /// Divide image sizes by this integer.
    #[arg(long, default_value_t = 1)]
    downscale: u32,
    /// Half the box's side, world units (default: as `recon voxel`).
    #[arg(long)]
    bound: Option<f32>,
    /// Samples along the box's diagonal.
    #[arg(long, default_value_t = NgpJob::default().steps)]
    steps: u32,
    /// Hash grid levels.
    #[arg(long, default_value_t = NgpJob::default().levels)]
    levels: u32,
    /// log2 of the hash table's entries per level.
    #[arg(long, default_value_t = NgpJob::default().log2_table)]
    log2_table: u32,
    /// Cells per axis of the coarsest level.
    #[arg(long, default_value_t = NgpJob::default().min_res)]
    min_res: u32,
    /// Cells per axis of the finest level.
    #[arg(long, default_value_t = NgpJob::default().max_res)]
    max_res: u32,
    /// Neurons per hidden layer.
    #[arg(long, default_value_t = NgpJob::default().width)]
    width: u32,
    /// Learning rate at the start.
    #[arg(long, default_value_t = NgpJob::default().lr[0])]
    lr: f32,
    /// Learning rate at the end (exponential decay from --lr).
    #[arg(long, default_value_t = NgpJob::default().lr[1])]
    lr_end: f32,
    /// Random seed of the parameters and the ray batches.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Hold out every N-th view as a test view (instant-ngp and COLMAP folders; see
    /// `recon voxel --help`).
    #[arg(long, value_name = "N")]
    test_every: Option<usize>,
    #[command(flatten)]
    report: Reporting,
}

/// Runs `diffsvg recon ngp`.
pub fn run(a: NgpArgs) -> Result<()> {
    super::util::check_output(&a.output, "ngp")?;
    let job = NgpJob {
        iters: a.iters,
        seconds: a.seconds,
        batch: a.batch,
        samples: a.samples,
        downscale: a.downscale,
        bound: a.bound,
        steps: a.steps,
        levels: a.levels,
        log2_table: a.log2_table,
        min_res: a.min_res,
        max_res: a.max_res,
        width: a.width,
        lr: [a.lr, a.lr_end],
        seed: a.seed,
        eval_every: a.report.eval_every,
        test_every: a.test_every,
    };
    job.validate().map_err(flag_error)?;
    install_interrupt_handler();
    let bar = super::progress::terminal_bar(a.report.json || a.report.quiet, a.iters, "");
    let out = recon_ngp(&a.scene, &job, &mut |s, test| {
        if let Some(b) = &bar {
            b.set_position(s.iteration as u64);
            b.set_message(format!(
                "loss {:.2e}  PSNR {:.2} dB  {:.0}k samples/s  {:.1}% occupied  {:.0} s",
                s.loss,
                s.psnr,
                s.samples_per_second / 1e3,
                100.0 * s.occupied,
                s.elapsed
            ));
            if let Some(p) = test {
                b.println(format!(
                    "iteration {}: test PSNR {p:.2} dB after {:.0} s",
                    s.iteration, s.elapsed
                ));
            }
        }
        if a.report.json && (s.iteration % 50 == 0 || test.is_some()) {
            println!(
                "{}",
                json!({"iteration": s.iteration, "loss": s.loss, "psnr": s.psnr,
                    "samples": s.samples, "samples_per_second": s.samples_per_second,
                    "rays_per_second": s.rays_per_second, "occupied": s.occupied,
                    "elapsed": s.elapsed, "test_psnr": test})
            );
        }
        !interrupted()
    })
    .map_err(flag_error)?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    super::util::print_warnings(&out.warnings);
    field::save(&out.model, &a.output)?;
    let rows: Vec<String> = out
        .log
        .iter()
        .map(|(s, t)| {
            format!(
                "{},{:.3},{},{:.0},{:.4},{:.3},{}",
                s.iteration,
                s.elapsed,
                s.samples,
                s.samples_per_second,
                s.occupied,
                s.psnr,
                t.map(|p| format!("{p:.3}")).unwrap_or_default()
            )
        })
        .collect();
    let tests = out
        .log
        .iter()
        .filter_map(|(s, t)| t.map(|p| (s.elapsed as f64, p)))
        .collect();
    let batches = out
        .log
        .iter()
        .map(|(s, _)| (s.elapsed as f64, s.psnr as f64))
        .collect();
    super::volume::write_log_rows(
        &a.output,
        "iteration,seconds,samples,samples_per_second,occupied,batch_psnr,test_psnr\n",
        &rows,
        tests,
        batches,
    )?;
    let o = out.outcome;
    let bytes = std::fs::metadata(&a.output).map(|m| m.len()).unwrap_or(0);
    let sps = o.samples as f64 / (o.seconds as f64).max(1e-9);
    if a.report.json {
        println!(
            "{}",
            json!({"done": true, "output": a.output, "iterations": o.iterations,
                "seconds": o.seconds, "load_seconds": out.load_seconds,
                "test_psnr": out.test_psnr, "samples": o.samples, "samples_per_second": sps,
                "bytes": bytes, "occupied": out.model.occupied_fraction(),
                "stopped": o.stopped})
        );
    } else {
        println!(
            "recon ngp: {} iterations in {:.1} s ({:.0}k samples/s), {} parameters, {:.1} MB, \
             test PSNR {}; wrote {}",
            o.iterations,
            o.seconds,
            sps / 1e3,
            out.model.param_count(),
            bytes as f64 / 1e6,
            psnr_text(out.test_psnr),
            a.output.display()
        );
    }
    if o.stopped {
        eprintln!("interrupted: the model so far was written");
    }
    Ok(())
}

//! `diffsvg recon ngp` and `recon nerf`: fit an Instant-NGP neural field (hash grid and
//! tiny MLPs) or a NeRF field (positional encoding and an MLP) to posed photos.

use std::path::PathBuf;

use anyhow::Result;
use serde_json::json;

use super::progress::{install_interrupt_handler, interrupted};
use super::recon_report::{Reporting, psnr_text};
use super::util::flag_error;
use diffsvg::volume::field;
use diffsvg::volume::recon::{NgpJob, recon_ngp};

/// Options of `diffsvg recon ngp` and `recon nerf` alike; those left out take the
/// kind's defaults ([`NgpJob::default`], [`NgpJob::nerf`]).
#[derive(clap::Args, Debug)]
pub struct FieldArgs {
    /// Dataset folder: NeRF-synthetic (transforms_train.json), instant-ngp
    /// (transforms.json) or COLMAP (sparse/0/cameras.bin or .txt, photos in images/).
    #[arg(long)]
    scene: PathBuf,
    /// Model file to write (.ngp for `recon ngp`, .nerf for `recon nerf`).
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
    /// follow the samples per ray (0: always --batch rays) [default: ngp 65536, nerf
    /// 16384].
    #[arg(long)]
    samples: Option<usize>,
    /// Divide image sizes by this integer.
    #[arg(long, default_value_t = 1)]
    downscale: u32,
    /// Half the box's side, world units (default: as `recon voxel`).
    #[arg(long)]
    bound: Option<f32>,
    /// Samples along the box's diagonal [default: ngp 512, nerf 256].
    #[arg(long)]
    steps: Option<u32>,
    /// Neurons per hidden layer [default: 64].
    #[arg(long)]
    width: Option<u32>,
    /// Learning rate at the start [default: ngp 1e-2, nerf 2e-3].
    #[arg(long)]
    lr: Option<f32>,
    /// Learning rate at the end (exponential decay from --lr) [default: ngp 1e-3, nerf
    /// 2e-4].
    #[arg(long)]
    lr_end: Option<f32>,
    /// Random seed of the parameters and the ray batches.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Hold out every N-th view as a test view (instant-ngp and COLMAP folders; see
    /// `recon voxel --help`).
    #[arg(long, value_name = "N")]
    test_every: Option<usize>,
    /// Hold out the views named in FILE instead (see `recon splat --help`).
    #[arg(long, value_name = "FILE", conflicts_with = "test_every")]
    test_list: Option<std::path::PathBuf>,
    #[command(flatten)]
    report: Reporting,
}

impl FieldArgs {
    /// `base` with the options given on the command line.
    fn job(&self, base: NgpJob) -> NgpJob {
        NgpJob {
            iters: self.iters,
            seconds: self.seconds,
            batch: self.batch,
            samples: self.samples.unwrap_or(base.samples),
            downscale: self.downscale,
            bound: self.bound,
            steps: self.steps.unwrap_or(base.steps),
            width: self.width.unwrap_or(base.width),
            lr: [
                self.lr.unwrap_or(base.lr[0]),
                self.lr_end.unwrap_or(base.lr[1]),
            ],
            seed: self.seed,
            eval_every: self.report.eval_every,
            test_every: self.test_every,
            test_list: self.test_list.clone(),
            ..base
        }
    }
}

/// Arguments of `diffsvg recon ngp`.
#[derive(clap::Args, Debug)]
pub struct NgpArgs {
    #[command(flatten)]
    common: FieldArgs,
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
}

/// Arguments of `diffsvg recon nerf`.
#[derive(clap::Args, Debug)]
pub struct NerfArgs {
    #[command(flatten)]
    common: FieldArgs,
    /// Octaves of the positional encoding (NeRF: 10).
    #[arg(long, default_value_t = NgpJob::nerf().frequencies)]
    frequencies: u32,
    /// Hidden layers of the density network.
    #[arg(long, default_value_t = NgpJob::nerf().density_layers)]
    density_layers: u32,
    /// Hidden layers of the color network.
    #[arg(long, default_value_t = NgpJob::nerf().color_layers)]
    color_layers: u32,
}

/// Runs `diffsvg recon ngp`.
pub fn run(a: NgpArgs) -> Result<()> {
    let job = NgpJob {
        levels: a.levels,
        log2_table: a.log2_table,
        min_res: a.min_res,
        max_res: a.max_res,
        ..a.common.job(NgpJob::default())
    };
    run_field(&a.common, job, "ngp")
}

/// Runs `diffsvg recon nerf`.
pub fn run_nerf(a: NerfArgs) -> Result<()> {
    let job = NgpJob {
        frequencies: a.frequencies,
        density_layers: a.density_layers,
        color_layers: a.color_layers,
        ..a.common.job(NgpJob::nerf())
    };
    if job.frequencies == 0 {
        return Err(flag_error(diffsvg::Error::Setting {
            name: "frequencies".into(),
            message: "0 must be 1 to 16".into(),
        }));
    }
    run_field(&a.common, job, "nerf")
}

/// Trains `job` (a field of kind `ext`, also the output's extension) and writes the
/// model, its log and the summary.
fn run_field(a: &FieldArgs, job: NgpJob, ext: &str) -> Result<()> {
    super::util::check_output(&a.output, ext)?;
    job.validate().map_err(flag_error)?;
    install_interrupt_handler();
    let bar = super::progress::terminal_bar(a.report.json || a.report.quiet, job.iters, "");
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
            "recon {ext}: {} iterations in {:.1} s ({:.0}k samples/s), {} parameters, {:.1} MB, \
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

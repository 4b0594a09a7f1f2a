//! `diffsvg ladder`: train every 3D representation on one scene with the same time
//! budget ([`diffsvg::volume::ladder`]) and write the table (markdown and JSON) and a
//! chart of batch PSNR against training time.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Result;
use serde_json::json;

use super::plot::{PlotSpec, Series, write_plot};
use super::progress::{install_interrupt_handler, interrupted};
use super::util::flag_error;
use diffsvg::image_io::write_atomic;
use diffsvg::volume::ladder::{LadderJob, LadderRow, Rung, run_ladder};

/// Arguments of `diffsvg ladder`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Dataset folder (as for `recon`); it needs test views.
    #[arg(long)]
    scene: PathBuf,
    /// Training seconds per representation.
    #[arg(long)]
    seconds: f32,
    /// Output folder: ladder.md, ladder.json, ladder.png (and .svg), and each model.
    #[arg(short, long)]
    output: PathBuf,
    /// Divide image sizes by this integer.
    #[arg(long, default_value_t = 1)]
    downscale: u32,
    /// Which representations, in order (comma-separated: voxel, splat, ngp, nerf).
    #[arg(long, value_delimiter = ',', default_value = "voxel,splat,ngp,nerf", value_parser = parse_rung)]
    rungs: Vec<Rung>,
    /// Iterations of the voxel grid (its schedule follows them; stopped at the budget).
    #[arg(long, default_value_t = 3000)]
    voxel_iters: usize,
    /// Final resolution of the voxel grid.
    #[arg(long, default_value_t = 128)]
    voxel_res: u32,
    /// Iterations of the Gaussians (their schedule follows them; stopped at the budget).
    #[arg(long, default_value_t = 7000)]
    splat_iters: usize,
    /// Hold out every N-th view (instant-ngp and COLMAP folders; see `recon voxel --help`).
    #[arg(long, value_name = "N")]
    test_every: Option<usize>,
    /// Hold out the views named in FILE, one a line, instead (instant-ngp and COLMAP
    /// folders; see `recon splat --help`).
    #[arg(long, value_name = "FILE", conflicts_with = "test_every")]
    test_list: Option<std::path::PathBuf>,
    /// Score only the first N test views (default: all); the NeRF field renders a 100²
    /// view in tens of seconds on 2 cores.
    #[arg(long, value_name = "N")]
    test_views: Option<usize>,
    /// Random seed of every model.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Print the table as JSON instead of markdown.
    #[arg(long)]
    json: bool,
}

fn parse_rung(s: &str) -> std::result::Result<Rung, String> {
    Rung::ALL
        .into_iter()
        .find(|r| r.name().eq_ignore_ascii_case(s.trim()))
        .ok_or_else(|| format!("'{s}' is not one of voxel, splat, ngp, nerf"))
}

/// Runs `diffsvg ladder`.
pub fn run(a: Args) -> Result<()> {
    let mut job = LadderJob::new(a.seconds, a.downscale).with_views(a.test_every, a.seed);
    job = job.with_test_list(a.test_list.clone());
    job.rungs = a.rungs.clone();
    job.voxel.iters = a.voxel_iters;
    job.voxel.res = a.voxel_res;
    job.splat.iters = a.splat_iters;
    job.test_views = a.test_views;
    job.validate().map_err(flag_error)?;
    if a.output.is_file() {
        return Err(flag_error(diffsvg::Error::Output {
            path: a.output.clone(),
            message: "output must be a folder".into(),
        }));
    }
    install_interrupt_handler();
    let mut last = (Rung::Voxel, -1.0f32);
    let rows = run_ladder(&a.scene, &job, &a.output, &mut |rung, t, p| {
        if !a.json && (rung != last.0 || t - last.1 >= 10.0) {
            eprintln!("{}: {t:.0} s, batch PSNR {p:.2} dB", rung.name());
            last = (rung, t);
        }
        !interrupted()
    })
    .map_err(flag_error)?;
    let md = markdown(&rows, a.seconds);
    write_atomic(&a.output.join("ladder.md"), md.as_bytes())?;
    let js = serde_json::to_string_pretty(&table_json(&rows, a.seconds))?;
    write_atomic(&a.output.join("ladder.json"), js.as_bytes())?;
    let series: Vec<Series> = rows
        .iter()
        .map(|r| Series::new(r.rung.name(), r.curve.clone()))
        .collect();
    let mut spec = PlotSpec::new(
        format!(
            "Same budget ({} s each): batch PSNR while training",
            a.seconds
        ),
        "training time (s)",
        "batch PSNR (dB)",
    );
    spec.width = 640;
    spec.height = 400;
    write_plot(
        &spec,
        &series,
        a.output.join("ladder.png"),
        a.output.join("ladder.svg"),
    )?;
    if a.json {
        println!("{js}");
    } else {
        print!("{md}");
    }
    Ok(())
}

fn table_json(rows: &[LadderRow], seconds: f32) -> serde_json::Value {
    let rows: Vec<_> = rows
        .iter()
        .map(|r| {
            json!({"model": r.rung.name(), "test_psnr": r.test_psnr, "ssim": r.ssim,
                "train_seconds": r.train_seconds, "iterations": r.iterations,
                "model_bytes": r.model_bytes, "render_seconds_per_view": r.render_seconds,
                "views": r.views, "file": r.model})
        })
        .collect();
    json!({"budget_seconds": seconds, "rows": rows})
}

fn markdown(rows: &[LadderRow], seconds: f32) -> String {
    let mut s = format!(
        "Budget {seconds} s of training per model.\n\n\
         | model | test PSNR (dB) | SSIM | training (s) | iterations | model (MB) | render (s / view) |\n\
         |---|---|---|---|---|---|---|\n"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {:.2} | {:.3} | {:.1} | {} | {:.2} | {:.3} |",
            r.rung.name(),
            r.test_psnr,
            r.ssim,
            r.train_seconds,
            r.iterations,
            r.model_bytes as f64 / 1e6,
            r.render_seconds
        );
    }
    s
}

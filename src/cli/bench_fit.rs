//! `diffsvg bench painterly` (DiffVG's painterly workload, timed) and `diffsvg bench fit`
//! (the speed-vs-error suite written to docs/).

use std::path::PathBuf;

use anyhow::{Result, bail};

use super::bench_suite::{SuiteArgs, default_photo, photo};

use diffsvg::fit::random_blobs;
use diffsvg::fit::{Control, FitOptions, refine};
use diffsvg::fit::{LearningRates, Objective};
use diffsvg::loss::Loss;

/// Benchmarks of optimization.
#[derive(clap::Subcommand, Debug)]
pub enum Which {
    /// DiffVG's painterly blob workload: N random closed blobs (3–5 cubics, random-walk
    /// step 0.05 × canvas, random RGBA, even-odd) over white, MSE over RGB, Adam with lr 1
    /// on points and 0.01 on colors and opacities; prints median forward and backward ms,
    /// total seconds and the final MSE.
    Painterly(PainterlyArgs),
    /// The speed-vs-error suite: refinement of every sample, vectorization of photos at
    /// several path counts against the painterly baseline and vtracer; writes a Markdown
    /// report and plots.
    Fit(SuiteArgs),
    /// Rays per second of the voxel renderer and of its training, on a synthetic scene
    /// held as a sparse and as a dense grid (see docs/3d.md).
    Voxel(super::bench_voxel::VoxelBenchArgs),
    /// Forward and backward time per view of the 3D Gaussian splatting renderer, on
    /// gsplat's test fixture (the garden) and on trained models (from a dataset's test
    /// cameras or an orbit).
    Splat(super::bench_splat::SplatBenchArgs),
    /// Forward and forward + backward time of the exact mesh renderer (spot at 256² by
    /// default), medians per thread count (see docs/mesh.md).
    Mesh(super::mesh::MeshBenchArgs),
}

/// Arguments of `diffsvg bench painterly`.
#[derive(clap::Args, Debug)]
pub struct PainterlyArgs {
    /// Path counts.
    #[arg(long, value_delimiter = ',', default_value = "64,256,512")]
    paths: Vec<usize>,
    /// Canvas side in pixels (the target is resized to it).
    #[arg(long, default_value_t = 256)]
    size: u32,
    /// Optimizer steps.
    #[arg(long, default_value_t = 50)]
    iters: usize,
    /// Target image (default: ../shared/data/images/astronaut.png).
    #[arg(long)]
    target: Option<PathBuf>,
    /// Seed of the random blobs.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Append the Markdown table to this file as well.
    #[arg(long)]
    report: Option<PathBuf>,
}

/// DiffVG's CPU figures on this machine class for astronaut.png at 256², 50 iterations
/// (from the issue): paths, forward ms, backward ms, final MSE.
const DIFFVG: [(usize, f64, f64, f64); 3] = [
    (64, 93.0, 380.0, 0.0296),
    (256, 198.0, 777.0, 0.0153),
    (512, 314.0, 1226.0, 0.0096),
];

fn pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 {
            bail!("--threads must be at least 1");
        }
        b = b.num_threads(n);
    }
    Ok(b.build()?)
}

/// One painterly run.
pub struct PainterlyRun {
    /// Median milliseconds of a forward pass alone (prepare and render, no gradient), timed
    /// on the scene of every step.
    pub forward_ms: f64,
    /// Median milliseconds of an optimizer step's render, objective and gradient.
    pub step_ms: f64,
    /// Seconds of the run, without the separate forward timings.
    pub seconds: f64,
    /// Final MSE.
    pub mse: f64,
}

/// Runs DiffVG's painterly workload: `paths` random blobs fitted to `target` for `iters`
/// steps.
pub fn painterly_run(
    target: &diffsvg::Image,
    paths: usize,
    iters: usize,
    seed: u64,
) -> PainterlyRun {
    let scene = random_blobs(paths, target.width, target.height, seed);
    let objective = Objective::new(target, Loss::Mse, Some([1.0; 4]), 1);
    let opts = FitOptions {
        iters,
        rates: LearningRates {
            points: 1.0,
            color: 0.01,
            opacity: 0.01,
            ..LearningRates::default()
        },
        ..FitOptions::default()
    };
    // The forward pass alone, timed on the scene each step starts from (outside the run's
    // own timing, and subtracted from its total).
    let (mut fwd, mut aside) = (Vec::new(), std::time::Duration::ZERO);
    let out = refine(scene, &objective, &opts, &mut |s, sc| {
        if s.iter < iters {
            let t = std::time::Instant::now();
            std::hint::black_box(diffsvg::raster::render(sc, &opts.render));
            let e = t.elapsed();
            fwd.push(e.as_secs_f64() * 1e3);
            aside += e;
        }
        Control::Continue
    });
    let last = out.history.last().expect("at least one evaluation");
    PainterlyRun {
        forward_ms: diffsvg::metrics::median(&mut fwd),
        step_ms: out.median_step_ms,
        seconds: last.elapsed.saturating_sub(aside).as_secs_f64(),
        mse: last.loss,
    }
}

fn run_painterly(a: PainterlyArgs) -> Result<()> {
    let path = a
        .target
        .clone()
        .unwrap_or_else(|| default_photo("astronaut.png"));
    let target = photo(&path, a.size, a.size)?;
    let pool = pool(a.threads)?;
    let threads = pool.current_num_threads();
    let mut table = format!(
        "Painterly blobs on {} at {}², {} steps, {threads} thread(s), seed {}.\n\n\
         | paths | forward (ms) | step: forward + backward (ms) | step / forward | total (s) | final MSE | DiffVG fwd+bwd (ms, quoted) | speed-up | DiffVG final MSE (quoted) |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        path.file_name().unwrap_or_default().to_string_lossy(),
        a.size,
        a.iters,
        a.seed
    );
    println!("{}", table.trim_end());
    for &n in &a.paths {
        let r = pool.install(|| painterly_run(&target, n, a.iters, a.seed));
        let (f, st, secs, mse) = (r.forward_ms, r.step_ms, r.seconds, r.mse);
        let ratio = st / f;
        let reference = DIFFVG.iter().find(|r| r.0 == n && a.size == 256);
        let row = match reference {
            Some(&(_, rf, rb, rm)) => format!(
                "| {n} | {f:.2} | {st:.2} | {ratio:.2} | {secs:.2} | {mse:.4} | {:.0} | {:.0}× | {rm:.4} |",
                rf + rb,
                (rf + rb) / st
            ),
            None => format!(
                "| {n} | {f:.2} | {st:.2} | {ratio:.2} | {secs:.2} | {mse:.4} | – | – | – |"
            ),
        };
        println!("{row}");
        table += &row;
        table.push('\n');
    }
    if let Some(r) = &a.report {
        let mut text = std::fs::read_to_string(r).unwrap_or_default();
        text += &table;
        diffsvg::image_io::write_atomic(r, text.as_bytes())?;
    }
    Ok(())
}

/// Runs a benchmark.
pub fn run(w: Which) -> Result<()> {
    match w {
        Which::Painterly(a) => run_painterly(a),
        Which::Fit(a) => super::bench_suite::run(a),
        Which::Voxel(a) => super::bench_voxel::run(a),
        Which::Splat(a) => super::bench_splat::run(a),
        Which::Mesh(a) => super::mesh::run_bench(a),
    }
}

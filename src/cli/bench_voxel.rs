//! `diffsvg bench voxel`: rays per second of the voxel renderer and of training, on a
//! synthetic scene held once as a sparse grid (a shell around the surfaces) and once as a
//! dense grid of the same values, so the ratio shows what sparsity and empty-space
//! skipping buy.

use std::fmt::Write as _;
use std::time::Instant;

use anyhow::{Result, bail};

use diffsvg::glam::Vec3;
use diffsvg::metrics::median;
use diffsvg::volume::Ray;
use diffsvg::volume::camera::orbit;
use diffsvg::volume::voxel::{self, Grid, RenderSettings, TrainOptions};

/// Arguments of `diffsvg bench voxel`.
#[derive(clap::Args, Debug)]
pub struct VoxelBenchArgs {
    /// Grid cells per axis.
    #[arg(long, default_value_t = 128)]
    res: u32,
    /// Image side of the cameras, pixels.
    #[arg(long, default_value_t = 200)]
    size: u32,
    /// Cameras on a circle around the scene.
    #[arg(long, default_value_t = 8)]
    views: usize,
    /// Training iterations (of 8192 rays) per timed run.
    #[arg(long, default_value_t = 10)]
    iters: usize,
    /// Timed runs per case; the median is reported.
    #[arg(long, default_value_t = 5)]
    runs: usize,
    /// Thread counts.
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    threads: Vec<usize>,
}

/// Three spheres in the box `[-1, 1]³`: (center, radius, color).
const SPHERES: [([f32; 3], f32, [f32; 3]); 3] = [
    ([-0.35, 0.0, 0.0], 0.45, [0.9, 0.3, 0.2]),
    ([0.4, 0.2, 0.1], 0.35, [0.2, 0.7, 0.3]),
    ([0.1, -0.45, -0.3], 0.3, [0.2, 0.3, 0.9]),
];

/// Signed distance to the nearest sphere and that sphere's color.
fn nearest(p: Vec3) -> (f32, [f32; 3]) {
    SPHERES
        .iter()
        .map(|&(c, r, col)| ((p - Vec3::from(c)).length() - r, col))
        .fold(
            (f32::INFINITY, [0.0; 3]),
            |a, b| if b.0 < a.0 { b } else { a },
        )
}

/// The scene as a grid of SH degree 2: opaque inside the spheres, empty outside, colored
/// by the nearest sphere. `shell`: allocate only within 3 voxels of a surface.
fn scene(res: u32, shell: bool) -> Grid {
    let h = 2.0 / res as f32;
    let mut g = Grid::from_fn(Vec3::splat(-1.0), Vec3::splat(1.0), res, 2, |p| {
        let d = nearest(p).0;
        (!shell || d.abs() < 3.0 * h).then_some(if d < 0.0 { 300.0 } else { -10.0 })
    });
    let k = g.coeffs();
    for s in 0..g.allocated() {
        let col = nearest(g.position(s)).1;
        let sh = &mut g.sh_mut()[s * 3 * k..(s + 1) * 3 * k];
        for ch in 0..3 {
            // sigmoid(Y₀⁰ · c) = col: c = logit(col) / Y₀⁰.
            sh[ch * k] = (col[ch] / (1.0 - col[ch])).ln() / 0.282_094_8;
            sh[ch * k + 1 + ch] = 0.1;
        }
    }
    g
}

/// Bytes the grid's values take (index, densities, SH coefficients).
fn bytes(g: &Grid) -> usize {
    let n = g.res() as usize + 1;
    4 * n * n * n + 4 * g.allocated() + 4 * g.sh().len()
}

/// Runs `diffsvg bench voxel`.
pub fn run(a: VoxelBenchArgs) -> Result<()> {
    if !(8..=512).contains(&a.res) || a.size == 0 || a.views == 0 || a.iters == 0 {
        bail!("--res must be 8 to 512, and --size, --views and --iters at least 1");
    }
    let cams = orbit(a.views, Vec3::ZERO, 3.2, 0.3, Vec3::Z, 0.69, a.size, a.size)
        .map_err(|e| anyhow::anyhow!("cameras: {e}"))?;
    let rays: Vec<Ray> = cams.iter().flat_map(|c| c.rays()).collect();
    let settings = RenderSettings::default();
    let grids = [
        ("sparse", scene(a.res, true)),
        ("dense", scene(a.res, false)),
    ];
    // The training targets: the scene's own rendering, so the loss is small but the work
    // (forward, backward, update) is the real one.
    let colors = voxel::render_rays(&grids[0].1, &rays, &settings);
    let opts = TrainOptions {
        iterations: a.iters,
        lr_density: [0.0; 2],
        lr_sh: [0.0; 2],
        render: settings,
        ..TrainOptions::default()
    };
    let mut out = format!(
        "Voxel renderer, {res}³ grid of three spheres (SH degree 2), {v} cameras at {s}×{s} \
         ({r} rays), step 0.5 voxel; medians of {runs} runs, rays per second.\n\n\
         | grid | threads | allocated | memory (MiB) | render (rays/s) | train (rays/s) |\n\
         |---|---:|---:|---:|---:|---:|\n",
        res = a.res,
        v = a.views,
        s = a.size,
        r = rays.len(),
        runs = a.runs
    );
    let mut rates = Vec::new();
    for &t in &a.threads {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(t).build()?;
        for (name, grid) in &grids {
            let (fwd, trn) = pool.install(|| -> Result<(f64, f64)> {
                let mut f = Vec::new();
                let mut tr = Vec::new();
                for _ in 0..a.runs.max(1) {
                    let t0 = Instant::now();
                    std::hint::black_box(voxel::render_rays(grid, &rays, &settings));
                    f.push(rays.len() as f64 / t0.elapsed().as_secs_f64());
                    let mut g = grid.clone();
                    let o = voxel::train(&mut g, &rays, &colors, &opts, &mut |_, _| true)?;
                    tr.push((o.iterations * opts.batch_size) as f64 / o.seconds as f64);
                }
                Ok((median(&mut f), median(&mut tr)))
            })?;
            let _ = writeln!(
                out,
                "| {name} | {t} | {} | {:.1} | {:.0} | {:.0} |",
                grid.allocated(),
                bytes(grid) as f64 / (1 << 20) as f64,
                fwd,
                trn
            );
            rates.push((fwd, trn));
        }
    }
    let _ = writeln!(out);
    for (i, &t) in a.threads.iter().enumerate() {
        let (s, d) = (rates[2 * i], rates[2 * i + 1]);
        let _ = writeln!(
            out,
            "{t} thread(s): sparse/dense speed {:.2}× rendering, {:.2}× training; memory {:.2}×.",
            s.0 / d.0,
            s.1 / d.1,
            bytes(&grids[0].1) as f64 / bytes(&grids[1].1) as f64
        );
    }
    print!("{out}");
    Ok(())
}

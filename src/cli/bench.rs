//! `diffsvg bench`: forward render time against resvg.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;

use super::parity::collect_svgs;
use super::util::FontArgs;
use diffsvg::Sizing;
use diffsvg::raster::{Alpha, Prepared, RenderOptions, render_prepared, render_rgba8};
use diffsvg::reference::render_resvg_pixmap;
use diffsvg::scene::random::curved_paths;
use diffsvg::scene::{from_tree, parse_tree, parse_tree_with};

/// Arguments of `diffsvg bench`.
#[derive(clap::Args, Debug)]
#[command(args_conflicts_with_subcommands = true)]
pub struct Args {
    #[command(subcommand)]
    what: Option<super::bench_fit::Which>,
    /// SVG files or folders to time (default: svg-samples/).
    inputs: Vec<PathBuf>,
    /// Timed runs per case; the median is reported.
    #[arg(long, default_value_t = 9)]
    runs: usize,
    /// Thread counts for diffsvg. resvg always uses one thread; it is timed beside each
    /// count, on a worker of that count's pool, and the table shows the first series.
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    threads: Vec<usize>,
    /// Canvas sizes for the random scene of 500 curved translucent paths [default:
    /// 256,512,1024 without INPUTS, none with them].
    #[arg(long, value_delimiter = ',')]
    sizes: Option<Vec<u32>>,
    /// Write the Markdown table here as well.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Time forward and forward+backward on the painterly case (N random closed cubic
    /// paths with translucent colors at 256×256) instead, with peak memory.
    #[arg(long)]
    backward: bool,
    /// Shape counts for `--backward`.
    #[arg(long, value_delimiter = ',', default_value = "64,256,512")]
    shapes: Vec<usize>,
    /// Time diffsvg's 8-bit premultiplied pixmap (`raster::render_rgba8`, like the one
    /// resvg renders into) instead of its premultiplied `f32` image (`raster::render`).
    /// Faster on large flat drawings, slower on small or busy ones (docs/performance.md).
    #[arg(long)]
    rgba8: bool,
    /// Time diffsvg with the pixels where a path overlaps itself integrated exactly, as
    /// `render --exact-overlaps` draws them (`RenderOptions::exact_overlaps`).
    #[arg(long)]
    exact_overlaps: bool,
    #[command(flatten)]
    fonts: FontArgs,
}

fn run_backward(a: &Args) -> Result<()> {
    use diffsvg::fit::Objective;
    use diffsvg::loss::Loss;
    use diffsvg::raster::render_and_backward_fused;
    let threads = a.threads.iter().copied().max().unwrap_or(1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    let mut table = format!(
        "Painterly case, 256×256, {threads} thread(s), medians of {} runs.\n\n| shapes | forward (ms) | forward+backward (ms) | ratio | backward record memory (MiB) | ×(canvas RGBA f32) |\n|---:|---:|---:|---:|---:|---:|\n",
        a.runs
    );
    print!("{table}");
    for &n in &a.shapes {
        let scene = curved_paths(n, 256, 1);
        let target = diffsvg::raster::render(&curved_paths(n, 256, 2), &RenderOptions::default());
        let opts = RenderOptions::default();
        let (fwd, both, mem) = pool.install(|| {
            let fwd = median_ms(a.runs, || {
                let _ = render_prepared(&Prepared::new(&scene, &opts));
            });
            let mut peak = 0usize;
            // The fused pass: each band rendered, scored and differentiated at once.
            let objective = Objective::new(&target, Loss::Mse, None, 1);
            let mut step = || {
                let p = Prepared::new(&scene, &opts);
                let out = render_and_backward_fused(&scene, &p, &objective);
                peak = out.stats.peak_bytes();
            };
            let both = median_ms(a.runs, &mut step);
            (fwd, both, peak as f64 / (1024.0 * 1024.0))
        });
        let canvas = (256 * 256 * 16) as f64 / (1024.0 * 1024.0);
        let row = format!(
            "| {n} | {fwd:.2} | {both:.2} | {:.2}× | {mem:.2} | {:.2} |",
            both / fwd,
            mem / canvas
        );
        println!("{row}");
        table += &row;
        table += "\n";
    }
    if let Some(r) = &a.report {
        diffsvg::image_io::write_atomic(r, table.as_bytes())?;
    }
    Ok(())
}

fn median_ms(runs: usize, mut f: impl FnMut()) -> f64 {
    f(); // warm-up
    let mut t: Vec<f64> = (0..runs.max(1))
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    diffsvg::metrics::median(&mut t)
}

/// Milliseconds `f` takes.
fn timed_ms(f: impl FnOnce()) -> f64 {
    let s = Instant::now();
    f();
    s.elapsed().as_secs_f64() * 1e3
}

/// Median of the milliseconds each of `fs` reports (each times its own work) over `runs`
/// rounds, after one warm-up round; in each round every function runs once, in turn.
fn interleaved_medians_ms(runs: usize, fs: &mut [Box<dyn FnMut() -> f64 + '_>]) -> Vec<f64> {
    for f in fs.iter_mut() {
        f();
    }
    let mut times = vec![Vec::with_capacity(runs.max(1)); fs.len()];
    for _ in 0..runs.max(1) {
        for (f, t) in fs.iter_mut().zip(&mut times) {
            t.push(f());
        }
    }
    times
        .into_iter()
        .map(|mut t| diffsvg::metrics::median(&mut t))
        .collect()
}

/// Runs `diffsvg bench`.
pub fn run(a: Args) -> Result<()> {
    if let Some(w) = a.what {
        return super::bench_fit::run(w);
    }
    if a.backward {
        return run_backward(&a);
    }
    let inputs = if a.inputs.is_empty() {
        vec![PathBuf::from("svg-samples")]
    } else {
        a.inputs.clone()
    };
    let mut cases: Vec<(String, usvg::Tree, Sizing)> = Vec::new();
    let fonts = a.fonts.fonts();
    let mut skipped = 0usize;
    for f in collect_svgs(&inputs)? {
        let data = diffsvg::image_io::read_bounded(&f, diffsvg::limits::MAX_FILE_BYTES)?;
        // A folder of real files holds some diffsvg refuses: they are named and left out
        // of the timing (every file of an explicit list would be refused as well).
        let tree = match parse_tree_with(&data, &f, &fonts)
            .and_then(|t| from_tree(&t, &f, Sizing::Natural).map(|_| t))
        {
            Ok(t) => t,
            Err(e) => {
                eprintln!("skipped {e}");
                skipped += 1;
                continue;
            }
        };
        let name = f
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        cases.push((name, tree, Sizing::Natural));
    }
    let sizes = match &a.sizes {
        Some(s) => s.clone(),
        None if a.inputs.is_empty() => vec![256, 512, 1024],
        None => Vec::new(),
    };
    for &size in &sizes {
        let scene = curved_paths(500, size, 1);
        let tree = parse_tree(scene.to_svg_string().as_bytes(), "random.svg".as_ref())?;
        cases.push((format!("500 random paths, {size}²"), tree, Sizing::Natural));
    }
    let pools: Vec<(usize, rayon::ThreadPool)> = a
        .threads
        .iter()
        .map(|&n| Ok((n, rayon::ThreadPoolBuilder::new().num_threads(n).build()?)))
        .collect::<Result<_>>()?;
    anyhow::ensure!(
        !pools.is_empty(),
        "--threads: give at least one thread count"
    );
    let mut table = String::from("| case | resvg (ms) |");
    for (n, _) in &pools {
        table += &format!(" diffsvg {n} thr (ms) | ratio |");
    }
    table += "\n|---|---:|";
    for _ in &pools {
        table += "---:|---:|";
    }
    table += "\n";
    // The header goes to the terminal too: rows without it do not say which is which.
    print!("{table}");
    let mut ratios: Vec<Vec<f64>> = vec![Vec::new(); pools.len()];
    for (name, tree, sizing) in &cases {
        let path = std::path::Path::new(name);
        let scene = from_tree(tree, path, *sizing)?;
        let opts = RenderOptions {
            exact_overlaps: a.exact_overlaps,
            ..RenderOptions::default()
        };
        // Per thread count, resvg and diffsvg take turns run by run in that count's pool,
        // both timed on a worker of it (inside the pool, without handing the work over),
        // so that a slower or faster spell of a shared machine weighs on both alike, and
        // each ratio is against the resvg runs of its own series. On this two-core
        // virtual machine, resvg timed on the main thread swung a drawing's one-thread
        // ratio between 0.8× and 1.4× from one invocation to the next (1.02–1.11× on the
        // same worker), and two-thread runs timed straight after another pool's ran at
        // one-thread speed (8.2 ms instead of 4.9 on the 256² random scene).
        let mut row = String::new();
        for (k, (_, pool)) in pools.iter().enumerate() {
            let mut contenders: [Box<dyn FnMut() -> f64 + '_>; 2] = [
                Box::new(|| {
                    pool.install(|| {
                        timed_ms(|| {
                            let _ = render_resvg_pixmap(tree, path, *sizing);
                        })
                    })
                }),
                Box::new(|| {
                    pool.install(|| {
                        timed_ms(|| {
                            if a.rgba8 {
                                let p = Prepared::new(&scene, &opts);
                                let _ = render_rgba8(&p, Alpha::Premultiplied);
                            } else {
                                let _ = diffsvg::raster::render(&scene, &opts);
                            }
                        })
                    })
                }),
            ];
            let [reference, t] = interleaved_medians_ms(a.runs, &mut contenders)[..] else {
                unreachable!("two contenders, two medians")
            };
            if k == 0 {
                row = format!("| {name} | {reference:.2} |");
            }
            let ratio = reference / t;
            ratios[k].push(ratio);
            row += &format!(" {t:.2} | {ratio:.2}× |");
        }
        println!("{row}");
        table += &row;
        table += "\n";
    }
    let mut summary = String::from("\nGeometric mean speed-up over resvg (> 1: diffsvg faster):");
    if skipped > 0 {
        summary = format!("\n{skipped} file(s) refused by diffsvg were not timed.{summary}");
    }
    for (k, (n, _)) in pools.iter().enumerate() {
        let g =
            (ratios[k].iter().map(|r| r.ln()).sum::<f64>() / ratios[k].len().max(1) as f64).exp();
        summary += &format!(" {n} thread(s) {g:.2}×;");
    }
    println!("{summary}");
    table += &summary;
    table += "\n";
    if let Some(r) = &a.report {
        diffsvg::image_io::write_atomic(r, table.as_bytes())?;
    }
    Ok(())
}

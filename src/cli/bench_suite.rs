//! `diffsvg bench fit`: the speed-vs-error suite behind docs/speed-vs-error.md.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Result, bail};

use super::plot::{PlotSpec, Series, write_plot};
use diffsvg::Sizing;
use diffsvg::fit::Objective;
use diffsvg::fit::load_target;
use diffsvg::fit::trace;
use diffsvg::fit::vectorize::{Mode, VectorizeOptions, VectorizeOutcome, vectorize};
use diffsvg::fit::{Control, FitOptions, refine};
use diffsvg::image_io::write_atomic;
use diffsvg::loss::Loss;
use diffsvg::raster::{RenderOptions, render};
use diffsvg::scene::Scene;
use diffsvg::scene::random::perturb;

/// Arguments of `diffsvg bench fit`.
#[derive(clap::Args, Debug)]
pub struct SuiteArgs {
    /// Where the report and plots go.
    #[arg(long, default_value = "docs")]
    out: PathBuf,
    /// Folder of photos (astronaut.png and chelsea.png are used).
    #[arg(long)]
    images: Option<PathBuf>,
    /// Optimizer steps per vectorization.
    #[arg(long, default_value_t = 1000)]
    iters: usize,
    /// Path counts for the photos.
    #[arg(long, value_delimiter = ',', default_value = "64,256,512")]
    paths: Vec<usize>,
}

impl SuiteArgs {
    /// The photo folder.
    pub fn images(&self) -> PathBuf {
        self.images
            .clone()
            .unwrap_or_else(|| default_photo("").to_path_buf())
    }
    /// Output folder.
    pub fn out(&self) -> &Path {
        &self.out
    }
    /// Steps per vectorization.
    pub fn iters(&self) -> usize {
        self.iters
    }
    /// Path counts.
    pub fn paths(&self) -> &[usize] {
        &self.paths
    }
}

/// A photo of `../shared/data/images` beside the checkout.
pub(super) fn default_photo(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/images")
        .join(name)
}

/// Loads an image and resizes it to `w × h` (or `w` wide when `h` is 0).
pub(super) fn photo(path: &Path, w: u32, h: u32) -> Result<diffsvg::Image> {
    let t = load_target(path, None)?;
    let h = if h == 0 {
        ((t.height as f64 * w as f64 / t.width as f64).round() as u32).max(1)
    } else {
        h
    };
    Ok(t.resized_checked(w, h, path)?)
}

/// Runs the suite and writes `<out>/speed-vs-error.md` and its plots.
pub fn run(a: SuiteArgs) -> Result<()> {
    let out = a.out();
    let img_dir = out.join("images");
    let mut md = String::from(
        "# Speed against error\n\nWritten by `cargo run --release -- bench fit` \
         (2-core machine, release build). PSNR is in dB over RGB for pictures composited \
         over white, over premultiplied RGBA for drawings with transparency.\n\n",
    );
    refinement(&mut md, &img_dir)?;
    let images = a.images();
    let photos = ["astronaut.png", "chelsea.png"];
    if photos.iter().all(|p| images.join(p).is_file()) {
        for p in photos {
            photo_section(&mut md, &img_dir, &images.join(p), &a)?;
        }
        vtracer_section(&mut md, &images)?;
    } else {
        eprintln!(
            "photos not found in {}: only the refinement part is written",
            images.display()
        );
        md += "\n(The photo sections need ../shared/data/images.)\n";
    }
    write_atomic(&out.join("speed-vs-error.md"), md.as_bytes())?;
    println!("wrote {}", out.join("speed-vs-error.md").display());
    Ok(())
}

fn log(line: &str) {
    eprintln!("{line}");
}

fn refinement(md: &mut String, img_dir: &Path) -> Result<()> {
    md.push_str(
        "## Refinement of the bundled samples\n\nEach `svg-samples/` drawing at 256 px wide, \
         control points moved by up to 8 px and colors by up to 0.2 (`diffsvg perturb --seed 1`), \
         refined back toward its own rendering with `diffsvg fit` defaults for 500 steps.\n\n\
         | sample | start (dB) | after 500 steps (dB) | time to 40 dB (s) | total (s) | ms/step |\n\
         |---|---:|---:|---:|---:|---:|\n",
    );
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("svg-samples");
    let mut files: Vec<_> = std::fs::read_dir(&root)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "svg"))
        .collect();
    files.sort();
    let mut series = Vec::new();
    let mut reached = 0;
    for f in &files {
        let name = f
            .file_stem()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        let truth = Scene::load(f, Sizing::Width(256))?;
        let target = render(&truth, &RenderOptions::default());
        let objective = Objective::new(&target, Loss::Mse, None, 1);
        let init = perturb(&truth, 8.0, 0.2, 1);
        let opts = FitOptions {
            iters: 500,
            ..FitOptions::default()
        };
        let run = refine(init, &objective, &opts, &mut |_, _| Control::Continue);
        let pts: Vec<(f64, f64)> = run
            .history
            .iter()
            .map(|s| (s.elapsed.as_secs_f64(), s.psnr.min(80.0)))
            .collect();
        let t40 = run
            .history
            .iter()
            .find(|s| s.psnr >= 40.0)
            .map(|s| s.elapsed.as_secs_f64());
        reached += t40.is_some() as usize;
        let total = run.history.last().map_or(0.0, |s| s.elapsed.as_secs_f64());
        let row = format!(
            "| {name} | {:.2} | {:.2} | {} | {total:.2} | {:.2} |",
            run.history[0].psnr,
            run.best_psnr,
            t40.map_or("not reached".into(), |t| format!("{t:.2}")),
            1e3 * total / run.steps.max(1) as f64
        );
        log(&row);
        md.push_str(&row);
        md.push('\n');
        series.push(Series::new(name, pts));
    }
    let _ = writeln!(
        md,
        "\n{reached} of {} samples reach 40 dB.\n\n![PSNR against time](images/refine-samples.png)\n",
        files.len()
    );
    let spec = PlotSpec {
        log_x: true,
        ..PlotSpec::new("Refining perturbed samples", "time (s)", "PSNR (dB)")
    };
    write_plot(
        &spec,
        &series,
        img_dir.join("refine-samples.png"),
        img_dir.join("refine-samples.svg"),
    )?;
    Ok(())
}

fn objective_for(target: &diffsvg::Image) -> Objective {
    Objective::new(target, Loss::Mse, Some([1.0; 4]), 1)
}

fn vec_run(
    obj: &Objective,
    mode: Mode,
    paths: usize,
    iters: usize,
    target_psnr: Option<f64>,
) -> VectorizeOutcome {
    let opts = VectorizeOptions {
        mode,
        paths,
        iters,
        target_psnr,
        ..VectorizeOptions::default()
    };
    vectorize(obj, &opts, &mut |_| Control::Continue).expect("vectorize runs")
}

fn photo_section(md: &mut String, img_dir: &Path, path: &Path, a: &SuiteArgs) -> Result<()> {
    let name = path
        .file_stem()
        .unwrap_or_default()
        .to_string_lossy()
        .into_owned();
    let target = photo(path, 256, 256)?;
    let obj = objective_for(&target);
    let _ = write!(
        md,
        "## Vectorizing {name}.png at 256²\n\n{} steps per run (`diffsvg vectorize --mode M --paths N --iters {}`).\n\n\
         | mode | paths asked | paths used | PSNR (dB) | MSE | time (s) |\n|---|---:|---:|---:|---:|---:|\n",
        a.iters(),
        a.iters()
    );
    let mut series = Vec::new();
    let mut fixed_psnr = None;
    for &n in a.paths() {
        for (mode, label) in [
            (Mode::Adaptive, "adaptive"),
            (Mode::Fixed, "fixed"),
            (Mode::Painterly, "painterly"),
        ] {
            let r = vec_run(&obj, mode, n, a.iters(), None);
            let row = format!(
                "| {label} | {n} | {} | {:.2} | {:.5} | {:.2} |",
                r.scene.path_count(),
                r.psnr,
                r.mse,
                r.elapsed.as_secs_f64()
            );
            log(&format!("{name}: {row}"));
            md.push_str(&row);
            md.push('\n');
            if mode == Mode::Fixed && n == 256 {
                fixed_psnr = Some(r.psnr);
            }
            series.push(Series::new(
                format!("{label} {n}"),
                r.curve.iter().map(|c| (c.1, c.2)).collect(),
            ));
            if n == 256 && mode == Mode::Adaptive {
                let mut img = render(&r.scene, &RenderOptions::default());
                img.over_background([1.0; 4]);
                diffsvg::image_io::side_by_side(&[obj.target(), &img])
                    .save_png(img_dir.join(format!("vectorize-{name}-256.png")))?;
            }
        }
    }
    if let Some(goal) = fixed_psnr {
        let r = vec_run(&obj, Mode::Adaptive, 512, a.iters(), Some(goal));
        let _ = write!(
            md,
            "\nAdaptive with `--target-psnr {goal:.2}` (the fixed mode's PSNR with 256 paths): \
             reached {:.2} dB with **{} paths** in {:.2} s.\n",
            r.psnr,
            r.scene.path_count(),
            r.elapsed.as_secs_f64()
        );
        log(&format!(
            "{name}: adaptive to {goal:.2} dB: {} paths",
            r.scene.path_count()
        ));
    }
    let _ = write!(
        md,
        "\n![{name}: target and adaptive with 256 paths](images/vectorize-{name}-256.png)\n\n\
         ![PSNR against time](images/vectorize-{name}.png)\n\n"
    );
    let spec = PlotSpec {
        log_x: true,
        ..PlotSpec::new(
            format!("Vectorizing {name} (256x256)"),
            "time (s)",
            "PSNR (dB)",
        )
    };
    write_plot(
        &spec,
        &series,
        img_dir.join(format!("vectorize-{name}.png")),
        img_dir.join(format!("vectorize-{name}.svg")),
    )?;
    Ok(())
}

fn vtracer_section(md: &mut String, images: &Path) -> Result<()> {
    md.push_str(
        "## Against the classical tracer at the same path count\n\nvtracer 0.6.5, `photo` preset, \
         as documented in the issue (rendered by resvg), and as traced here (rendered by diffsvg); \
         diffsvg adaptive (1000 steps) and trace-then-refine (300 steps) with the same path count. Goal: 3 dB more in ≤ 20 s.\n\n\
         | picture | paths | vtracer (issue) | vtracer here | adaptive | time (s) | trace + refine | time (s) |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for (file, w, h, paths, documented) in [
        ("astronaut.png", 256, 256, 142, 21.96),
        ("chelsea.png", 256, 0, 58, 25.16),
    ] {
        let target = photo(&images.join(file), w, h)?;
        let obj = objective_for(&target);
        let t0 = Instant::now();
        let traced = trace(&target)?;
        let traced_psnr = obj.psnr(&render(&traced, &RenderOptions::default()));
        let _ = t0;
        let ad = vec_run(&obj, Mode::Adaptive, paths, 1000, None);
        let tr = vec_run(&obj, Mode::Trace, paths, 300, None);
        let row = format!(
            "| {file} {}×{} | {paths} | {documented:.2} | {traced_psnr:.2} ({} paths) | {:.2} | {:.1} | {:.2} | {:.1} |",
            target.width,
            target.height,
            traced.path_count(),
            ad.psnr,
            ad.elapsed.as_secs_f64(),
            tr.psnr,
            tr.elapsed.as_secs_f64()
        );
        log(&row);
        md.push_str(&row);
        md.push('\n');
    }
    if md.is_empty() {
        bail!("empty report");
    }
    Ok(())
}

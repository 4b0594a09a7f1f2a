//! `diffsvg fit`: refine an SVG toward a target image.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Result, bail};
use serde_json::json;

use super::choices::{Background, choice, parse_background};
use super::progress::{ReportArgs, Reporter};
use super::util::{FontArgs, check_output, flag_error, sibling};
use diffsvg::Sizing;
use diffsvg::choice::Choice as _;
use diffsvg::fit::{FitOptions, ObjectiveOptions, StopReason, load_target_with, refine};
use diffsvg::fit::{LearningRates, Objective};
use diffsvg::image_io::{Image, side_by_side};
use diffsvg::loss::Loss;
use diffsvg::optim::Schedule;
use diffsvg::raster::render;
use diffsvg::scene::{ParamGroup, ParamLayout, Scene};

/// Optimizer flags shared by `fit` and `vectorize`.
#[derive(clap::Args, Debug, Clone)]
pub struct OptimArgs {
    /// Learning rate of control points, pixels per step.
    #[arg(long, default_value_t = LearningRates::default().points)]
    pub lr_points: f64,
    /// Learning rate of colors (solid and stop colors).
    #[arg(long, default_value_t = LearningRates::default().color)]
    pub lr_color: f64,
    /// Learning rate of opacities.
    #[arg(long, default_value_t = LearningRates::default().opacity)]
    pub lr_opacity: f64,
    /// Learning rate of stroke widths, pixels per step.
    #[arg(long, default_value_t = LearningRates::default().width)]
    pub lr_width: f64,
    /// Learning rate of gradient geometry (end points, centers, radii).
    #[arg(long, default_value_t = LearningRates::default().paint)]
    pub lr_paint: f64,
    /// Learning rate of gradient stop offsets.
    #[arg(long, default_value_t = LearningRates::default().stops)]
    pub lr_stops: f64,
    /// Learning rate of transforms (rotations of circles, ellipses and rectangles; group
    /// transforms' translation, angle and scale), pixels of motion at the shape's or
    /// group's edge per step.
    #[arg(long, default_value_t = LearningRates::default().transform)]
    pub lr_transform: f64,
    /// Learning rate of filter offsets and blur deviations, pixels per step (matrix
    /// values and feComposite's k move by a tenth of it).
    #[arg(long, default_value_t = LearningRates::default().filter)]
    pub lr_filter: f64,
    /// Learning-rate schedule.
    #[arg(long, ignore_case = true, value_parser = choice::<Schedule>(), default_value = Schedule::default().name())]
    pub schedule: Schedule,
    /// Loss, over the target's channels.
    #[arg(long, ignore_case = true, value_parser = choice::<Loss>(), default_value = Loss::default().name())]
    pub loss: Loss,
    /// Image pyramid levels in the loss (1 = full resolution only).
    #[arg(long, default_value_t = 1)]
    pub pyramid: usize,
    /// Parameter groups to hold fixed (comma-separated).
    #[arg(long, ignore_case = true, value_parser = choice::<ParamGroup>(), value_delimiter = ',')]
    pub freeze: Vec<ParamGroup>,
    /// Stop as soon as the PSNR reaches this many dB.
    #[arg(long, value_name = "DB")]
    pub until_psnr: Option<f64>,
    /// Color under the drawing when comparing with the target (`auto`: white for an
    /// opaque target, transparent otherwise; `none`: transparent).
    #[arg(long, default_value = "auto", value_parser = parse_background)]
    pub background: Background,
}

impl OptimArgs {
    /// The groups named by `--freeze`.
    pub fn frozen(&self) -> Vec<ParamGroup> {
        self.freeze.clone()
    }

    /// The background for `target`.
    pub fn background(&self, target: &Image) -> Option<[f32; 4]> {
        match self.background {
            Background::Auto => target.data.iter().all(|p| p[3] >= 1.0).then_some([1.0; 4]),
            Background::Color(c) => (c[3] > 0.0).then_some(c),
        }
    }

    /// The objective against `target` (the library checks the settings).
    pub fn objective(&self, target: &Image) -> Result<Objective> {
        let o = ObjectiveOptions {
            loss: self.loss,
            pyramid: self.pyramid,
            background: self.background(target),
        };
        o.objective(target).map_err(flag_error)
    }

    /// Fit options for `iters` steps, checked by the library, with frozen groups' rates
    /// set to 0 afterwards (a frozen group's rate is still checked).
    pub fn fit_options(&self, iters: usize) -> Result<FitOptions> {
        let mut opts = FitOptions {
            iters,
            rates: LearningRates {
                points: self.lr_points,
                color: self.lr_color,
                opacity: self.lr_opacity,
                width: self.lr_width,
                paint: self.lr_paint,
                stops: self.lr_stops,
                transform: self.lr_transform,
                filter: self.lr_filter,
            },
            schedule: self.schedule,
            until_psnr: self.until_psnr,
            ..FitOptions::default()
        };
        opts.validate().map_err(flag_error)?;
        opts.rates.freeze(&self.frozen());
        Ok(opts)
    }
}

/// Arguments of `diffsvg fit`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Initial SVG; it is scaled to the target's size.
    init: PathBuf,
    /// Target picture: PNG or JPEG, or an SVG rendered at its own size.
    target: PathBuf,
    /// Output SVG (written atomically).
    #[arg(short, long)]
    output: PathBuf,
    /// Optimizer steps.
    #[arg(long, default_value_t = 500)]
    iters: usize,
    /// Also write `<output>.compare.png`: target, initial and fitted renderings side by side.
    #[arg(long)]
    compare: bool,
    /// Fit circles, ellipses and rectangles as free paths (their outlines' control points
    /// become the parameters, written back as `<path>`) instead of by their own
    /// parameters (center, radii, sides, rotation).
    #[arg(long)]
    free_shapes: bool,
    /// Fit the background's color too, starting from `--background` (which must be
    /// opaque; `auto` is white for an opaque target); the fitted color is written as a
    /// canvas-sized `<rect>` under the drawing.
    #[arg(long)]
    fit_background: bool,
    /// Evaluate filters exactly (true Gaussian blurs, offsets by fractions of a pixel), so
    /// that blur deviations and offsets get a gradient; without it they stay where they
    /// are (resvg's box blurs and whole-pixel offsets are piecewise constant in them).
    #[arg(long)]
    exact_filters: bool,
    /// Render and differentiate the exact coverage where a path overlaps itself or two
    /// of its subpaths share a pixel (as `render --exact-overlaps`); without it those
    /// pixels take the clamped winding integral, which over-covers them.
    #[arg(long)]
    exact_overlaps: bool,
    #[command(flatten)]
    optim: OptimArgs,
    #[command(flatten)]
    fonts: FontArgs,
    #[command(flatten)]
    report: ReportArgs,
}

/// Runs `diffsvg fit`.
pub fn run(a: Args) -> Result<()> {
    check_output(&a.output, "svg")?;
    let compare_path = sibling(&a.output, "compare");
    if a.compare {
        check_output(&compare_path, "png")?;
    }
    let mut opts = a.optim.fit_options(a.iters)?;
    opts.fit_background = a.fit_background;
    opts.render.exact_filters = a.exact_filters;
    opts.render.exact_overlaps = a.exact_overlaps;
    let fonts = a.fonts.fonts();
    let target = load_target_with(&a.target, None, &fonts)?;
    let objective = a.optim.objective(&target)?;
    if a.fit_background && !objective.background().is_some_and(|b| b[3] >= 1.0) {
        bail!(
            "--fit-background needs an opaque background: {} has transparent pixels, so give \
             --background a color such as white",
            a.target.display()
        );
    }
    let mut scene = Scene::load_with(&a.init, Sizing::Exact(target.width, target.height), &fonts)?;
    if a.free_shapes {
        scene.outline_primitives();
    }
    super::util::warn_about(&scene, &a.init, &opts.render);
    diffsvg::raster::check_backward_memory(&scene, &opts.render, &a.init)?;
    let layout = ParamLayout::new(&scene);
    if scene.path_count() == 0 || layout.is_empty() {
        bail!(
            "{}: nothing to optimize (no filled or stroked paths)",
            a.init.display()
        );
    }
    let movable = layout
        .slots
        .iter()
        .filter(|s| opts.rates.get(s.group) > 0.0)
        .count();
    let filter_slots = layout.slots.iter().any(|s| s.group == ParamGroup::Filter);
    if filter_slots && !a.exact_filters && opts.rates.filter > 0.0 {
        eprintln!(
            "note: {} has filters; their offsets and blur deviations move only with \
             --exact-filters",
            a.init.display()
        );
    }
    if movable == 0 {
        bail!(
            "{}: nothing to optimize: every parameter group present is frozen",
            a.init.display()
        );
    }
    let start = Instant::now();
    // Last of the checks, as it creates the snapshots folder: inputs were good.
    a.report.check_outputs()?;
    let mut reporter = Reporter::new(&a.report, a.iters + 1, objective.background());
    let initial = scene.clone();
    let out = refine(scene, &objective, &opts, &mut |s, sc| reporter.step(s, sc));
    // A snapshot that could not be written fails the run before anything is written.
    reporter.finish()?;
    // The fitted background, under the drawing: what it was compared over.
    let (fitted, objective) = match out.background {
        Some(bg) => (
            with_background(&out.best, bg),
            objective.with_background(bg),
        ),
        None => (out.best.clone(), objective),
    };
    let compare = a.compare.then(|| {
        let opts = opts.render;
        let before = objective.composite(&render(&initial, &opts));
        let after = objective.composite(&render(&fitted, &opts));
        side_by_side(&[objective.target(), &before, &after])
    });
    fitted.save_svg(&a.output)?;
    // All or nothing: no SVG without the comparison asked for.
    if let Some(Err(e)) = compare.map(|img| img.save_png(&compare_path)) {
        let _ = std::fs::remove_file(&a.output);
        return Err(e.into());
    }
    let first = out.history.first().map_or(f64::NAN, |s| s.psnr);
    let secs = start.elapsed().as_secs_f64();
    let reason = match out.reason {
        StopReason::Finished => "finished",
        StopReason::ReachedPsnr => "reached the PSNR goal",
        StopReason::Interrupted => "interrupted",
    };
    let background = out.background.map(|b| [b[0], b[1], b[2]]);
    if a.report.json {
        println!(
            "{}",
            json!({"done": true, "output": a.output, "steps": out.steps, "stop": reason,
                "initial_psnr": first, "psnr": out.best_psnr, "loss": out.best_loss,
                "seconds": secs, "step_ms": out.median_step_ms, "background": background})
        );
    } else {
        if let Some(c) = background {
            println!(
                "fit: background rgb({:.1}, {:.1}, {:.1})",
                255.0 * c[0],
                255.0 * c[1],
                255.0 * c[2]
            );
        }
        println!(
            "fit: {} steps ({reason}), PSNR {first:.2} → {:.2} dB, loss {:.4e}, {secs:.2} s \
             (median step {:.2} ms); wrote {}",
            out.steps,
            out.best_psnr,
            out.best_loss,
            out.median_step_ms,
            a.output.display()
        );
    }
    if out.reason == StopReason::Interrupted && super::progress::interrupted() {
        eprintln!("interrupted: the best result so far was written");
    }
    Ok(())
}

/// `scene` with an opaque canvas-sized rectangle of `background` (straight RGBA) under
/// everything, named `background`.
fn with_background(scene: &Scene, background: [f32; 4]) -> Scene {
    use diffsvg::scene::{Fill, FillRule, Node, Paint, Path, Primitive};
    let (w, h) = (scene.width as f64, scene.height as f64);
    let mut rect = Path::from_primitive("background", Primitive::rect(0.0, 0.0, w, h, None, 0.0));
    rect.fill = Some(Fill {
        paint: Paint::Solid([0, 1, 2].map(|c| background[c] as f64)),
        opacity: 1.0,
        rule: FillRule::NonZero,
    });
    let mut out = scene.clone();
    out.nodes.insert(0, Node::Path(rect));
    out
}

//! `diffsvg loss` and `diffsvg grad`.

use std::path::PathBuf;

use anyhow::{Result, bail};
use serde_json::Value;

use super::choices::choice;
use super::util::{FontArgs, SizeArgs, parse_color};
use diffsvg::choice::Choice as _;
use diffsvg::gradcheck::{analytic, compare, numeric};
use diffsvg::image_io::Image;
use diffsvg::loss::Loss;
use diffsvg::raster::{RenderOptions, render};
use diffsvg::scene::{ParamLayout, Scene, Structure};

/// Arguments shared by `loss` and `grad`.
#[derive(clap::Args, Debug)]
pub struct Common {
    /// SVG file.
    input: PathBuf,
    /// Target image (PNG or JPEG; straight alpha in the file).
    target: PathBuf,
    /// Loss (mean over pixels and premultiplied RGBA channels).
    #[arg(long, ignore_case = true, value_parser = choice::<Loss>(), default_value = Loss::default().name())]
    loss: Loss,
    /// Resize the target to the render size instead of refusing a size mismatch.
    #[arg(long)]
    resize: bool,
    #[command(flatten)]
    size: SizeArgs,
    #[command(flatten)]
    fonts: FontArgs,
    /// Composite the render over this color before comparing (default: transparent).
    #[arg(long, value_parser = parse_color)]
    background: Option<[f32; 4]>,
    /// Render (and differentiate) the exact coverage where a path overlaps itself, as
    /// `render --exact-overlaps`.
    #[arg(long)]
    exact_overlaps: bool,
}

impl Common {
    /// The render options these arguments ask for (`--exact-overlaps`).
    fn options(&self) -> RenderOptions {
        RenderOptions {
            exact_overlaps: self.exact_overlaps,
            ..RenderOptions::default()
        }
    }
}

/// Arguments of `diffsvg loss`.
#[derive(clap::Args, Debug)]
pub struct LossArgs {
    #[command(flatten)]
    common: Common,
}

/// Arguments of `diffsvg grad`.
#[derive(clap::Args, Debug)]
pub struct GradArgs {
    #[command(flatten)]
    common: Common,
    /// Print the gradient as JSON (the default prints a per-shape summary).
    #[arg(long)]
    json: bool,
    /// Also compare every gradient with central finite differences (chord counts held
    /// fixed) and print the worst relative error per parameter group; exits with status 1
    /// when a group's worst error exceeds `--tolerance`.
    #[arg(long)]
    check: bool,
    /// Largest relative error `--check` accepts.
    #[arg(long, default_value_t = diffsvg::gradcheck::DEFAULT_TOLERANCE, requires = "check")]
    tolerance: f64,
    /// Testing the checker: negate the analytic gradient of this parameter slot before
    /// checking, which `--check` must catch.
    #[arg(long, hide = true, requires = "check")]
    corrupt: Option<usize>,
}

/// What `diffsvg grad` found: whether `--check` (when asked) passed.
pub enum GradOutcome {
    /// No check asked, or every group within tolerance.
    Passed,
    /// Some group exceeded the tolerance.
    CheckFailed,
}

struct Job {
    scene: Scene,
    target: Image,
    loss: Loss,
    background: Option<[f32; 4]>,
}

fn load(c: &Common) -> Result<Job> {
    let loss = c.loss;
    let background = c.background;
    let scene = Scene::load_with(&c.input, c.size.sizing()?, &c.fonts.fonts())?;
    super::util::warn_about(&scene, &c.input, &RenderOptions::default());
    let mut target = Image::load(&c.target)?;
    if (target.width, target.height) != (scene.width, scene.height) {
        if !c.resize {
            bail!(
                "{}: target is {}x{} but the render is {}x{} (pass --resize to resample it)",
                c.target.display(),
                target.width,
                target.height,
                scene.width,
                scene.height
            );
        }
        target = target.resized(scene.width, scene.height);
    }
    Ok(Job {
        scene,
        target,
        loss,
        background,
    })
}

/// Runs `diffsvg loss`.
pub fn run_loss(a: LossArgs) -> Result<()> {
    let job = load(&a.common)?;
    let mut img = render(&job.scene, &a.common.options());
    if let Some(bg) = job.background {
        img.over_background(bg);
    }
    // `{:?}` prints the shortest representation that reads back to the same f64.
    println!("{:?}", job.loss.value(&img, &job.target));
    Ok(())
}

/// Runs `diffsvg grad`.
pub fn run_grad(a: GradArgs) -> Result<GradOutcome> {
    if !(a.tolerance > 0.0 && a.tolerance.is_finite()) {
        bail!("--tolerance {} must be a positive number", a.tolerance);
    }
    let job = load(&a.common)?;
    let opts = a.common.options();
    diffsvg::raster::check_backward_memory(&job.scene, &opts, &a.common.input)?;
    let (loss, mut grad) = analytic(&job.scene, &job.target, job.loss, &opts, job.background);
    if let Some(i) = a.corrupt {
        if i >= grad.len() {
            bail!("--corrupt {i}: the scene has {} parameters", grad.len());
        }
        grad[i] = -grad[i];
    }
    if a.json {
        let doc = gradient_json(&job.scene, loss, &grad);
        println!("{}", serde_json::to_string_pretty(&doc)?);
    } else {
        println!("loss {loss:?}");
        let layout = ParamLayout::new(&job.scene);
        // Squared norms per owner in one pass over the slots.
        let mut sq = vec![0.0f64; layout.owners.len()];
        for (s, g) in layout.slots.iter().zip(&grad) {
            sq[s.owner] += g * g;
        }
        for (o, sq) in layout.owners.iter().zip(&sq) {
            let norm = sq.sqrt();
            let kind = if o.is_group { "group" } else { "path" };
            let id = if o.id.is_empty() { "(no id)" } else { &o.id };
            println!("{kind} {id}: |gradient| {norm:.4e}");
        }
    }
    if !a.check {
        return Ok(GradOutcome::Passed);
    }
    let which: Vec<usize> = (0..grad.len()).collect();
    let num = numeric(
        &job.scene,
        &job.target,
        job.loss,
        &opts,
        job.background,
        &which,
    );
    let groups = compare(&ParamLayout::new(&job.scene), &which, &grad, &num);
    let out = if a.json {
        &mut std::io::stderr() as &mut dyn std::io::Write
    } else {
        &mut std::io::stdout()
    };
    let mut failed = false;
    for g in groups {
        let ok = g.passes(a.tolerance);
        failed |= !ok;
        writeln!(out, "check {g} {}", if ok { "ok" } else { "FAILED" })?;
    }
    Ok(if failed {
        eprintln!(
            "error: {}: the gradient check failed (worst relative error above {})",
            a.common.input.display(),
            a.tolerance
        );
        GradOutcome::CheckFailed
    } else {
        GradOutcome::Passed
    })
}

/// The gradient as a JSON document, one entry per shape and group in paint order.
///
/// `points` follows the path data as written when it uses absolute `M`, `L`, `C` and `Z`:
/// one entry per `M` point, one per `L` (its end point), three per `C`; a `Q` gives two
/// (its control and end point). Other commands reach diffsvg as usvg normalizes them:
/// relative commands become absolute, `H`/`V` become `L`, `S`/`T` become `C`/`Q`, and an
/// arc `A` becomes one or more `C`. Internally a line or quadratic is a cubic; the
/// gradients of its derived control points are chained to the points written.
pub fn gradient_json(scene: &Scene, loss: f64, grad: &[f64]) -> Value {
    Structure::of(scene).gradient_json(scene, loss, grad)
}

//! `diffsvg perturb`: a randomly disturbed copy of an SVG, to try refinement on.

use std::path::PathBuf;

use anyhow::{Result, bail};

use super::util::{FontArgs, SizeArgs, check_output};
use diffsvg::limits::MAX_COORDINATE;
use diffsvg::scene::Scene;
use diffsvg::scene::random::perturb;

/// Arguments of `diffsvg perturb`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// SVG file.
    input: PathBuf,
    /// Output SVG.
    #[arg(short, long)]
    output: PathBuf,
    /// Largest control-point move in pixels (x and y each), at most 1e30; moved points are
    /// kept within ±1e30 pixels. A circle's, ellipse's or rectangle's position and sizes
    /// move by up to a quarter of it (sizes by at most half their value).
    #[arg(long, default_value_t = 8.0)]
    points: f64,
    /// Largest color channel shift.
    #[arg(long, default_value_t = 0.2)]
    colors: f64,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    #[command(flatten)]
    size: SizeArgs,
    #[command(flatten)]
    fonts: FontArgs,
}

/// Runs `diffsvg perturb`.
pub fn run(a: Args) -> Result<()> {
    check_output(&a.output, "svg")?;
    if !(a.points.is_finite() && a.points >= 0.0 && a.colors.is_finite() && a.colors >= 0.0) {
        bail!("--points and --colors must be finite numbers ≥ 0");
    }
    if a.points > MAX_COORDINATE {
        bail!(
            "--points {:e} is out of range (at most {MAX_COORDINATE:e} pixels)",
            a.points
        );
    }
    let scene = Scene::load_with(&a.input, a.size.sizing()?, &a.fonts.fonts())?;
    perturb(&scene, a.points, a.colors, a.seed).save_svg(&a.output)?;
    Ok(())
}

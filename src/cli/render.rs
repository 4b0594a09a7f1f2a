//! `diffsvg render`.

use std::path::PathBuf;

use anyhow::Result;

use super::util::{FontArgs, SizeArgs, check_output, parse_color, read, sibling};
use diffsvg::image_io::save_png_rgba8;
use diffsvg::metrics::{compare, difference_image};
use diffsvg::raster::{Alpha, Prepared, RenderOptions, render, render_rgba8};
use diffsvg::reference::render_resvg;
use diffsvg::scene::{from_tree, parse_tree_with};

/// Arguments of `diffsvg render`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// SVG file to render.
    input: PathBuf,
    /// PNG file to write.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    size: SizeArgs,
    #[command(flatten)]
    fonts: FontArgs,
    /// Background color under the drawing (default: transparent).
    #[arg(long, value_parser = parse_color)]
    background: Option<[f32; 4]>,
    /// Also render with resvg, print MAE, max difference and PSNR, and write
    /// `<output>.diff.png`.
    #[arg(long)]
    compare: bool,
    /// Flattening tolerance in pixels.
    #[arg(long, default_value_t = RenderOptions::default().tolerance)]
    tolerance: f64,
    /// Integrate exactly the pixels where a path overlaps itself (two coincident
    /// half-pixel rectangles in one path cover half the pixel, not all of it); the
    /// default keeps the clamped winding integral there, which is faster on thin strokes
    /// and glyphs (see docs/parity.md and docs/performance.md).
    #[arg(long)]
    exact_overlaps: bool,
    /// Evaluate filters as the SVG specification defines them: true Gaussian blurs and
    /// offsets by fractions of a pixel, as `fit --exact-filters` optimizes them (the
    /// default is resvg's box blurs and whole-pixel offsets).
    #[arg(long)]
    exact_filters: bool,
}

/// Runs `diffsvg render`.
pub fn run(a: Args) -> Result<()> {
    check_output(&a.output, "png")?;
    let bg = a.background;
    let sizing = a.size.sizing()?;
    if !(a.tolerance.is_finite() && a.tolerance > 0.0) {
        anyhow::bail!("--tolerance {} must be a positive number", a.tolerance);
    }
    let data = read(&a.input)?;
    let tree = parse_tree_with(&data, &a.input, &a.fonts.fonts())?;
    let scene = from_tree(&tree, &a.input, sizing)?;
    let opts = RenderOptions {
        exact_overlaps: a.exact_overlaps,
        exact_filters: a.exact_filters,
        tolerance: a.tolerance,
    };
    super::util::warn_about(&scene, &a.input, &opts);
    if bg.is_none() && !a.compare {
        // Straight to the file's bytes, band by band, without a whole f32 image.
        let rgba = render_rgba8(&Prepared::new(&scene, &opts), Alpha::Straight);
        save_png_rgba8(scene.width, scene.height, &rgba, &a.output)?;
        return Ok(());
    }
    let mut img = render(&scene, &opts);
    if let Some(bg) = bg {
        img.over_background(bg);
    }
    if a.compare {
        let mut reference = render_resvg(&tree, &a.input, sizing)?;
        if let Some(bg) = bg {
            reference.over_background(bg);
        }
        let c = compare(&img.quantized(), &reference);
        let diff = sibling(&a.output, "diff");
        difference_image(&img, &reference).save_png(&diff)?;
        println!(
            "{}: {}x{}, vs resvg: MAE {:.3}/255, max {:.0}/255, PSNR {:.2} dB; difference image {}",
            a.input.display(),
            img.width,
            img.height,
            c.mae,
            c.max,
            c.psnr,
            diff.display()
        );
    }
    img.save_png(&a.output)?;
    Ok(())
}

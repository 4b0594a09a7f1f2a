//! `diffsvg glyphs`: fit closed cubic outlines to rendered glyphs with as few segments as
//! an IoU goal needs, beside the source's own segment counts.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use serde_json::json;

use super::parity::collect_svgs;
use super::util::{FontArgs, check_output};
use diffsvg::Sizing;
use diffsvg::fit::glyph::{GlyphOptions, GlyphOutcome, count_ink_segments, fit_glyph};
use diffsvg::image_io::{Image, contact_sheet, write_atomic};
use diffsvg::raster::{RenderOptions, render};
use diffsvg::scene::{Fill, FillRule, Node, Paint, Scene};

/// Arguments of `diffsvg glyphs`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// SVG files or folders of SVGs (searched recursively); default `svg-samples/glyphs`.
    inputs: Vec<PathBuf>,
    /// Output folder: `<name>.svg` per glyph, `glyphs.csv` and `contact.png`.
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
    /// Width in pixels at which each glyph is rendered and fitted (height follows the
    /// aspect ratio).
    #[arg(long, default_value_t = 128)]
    size: u32,
    /// IoU of the inked areas (coverage ≥ ½) to reach.
    #[arg(long, default_value_t = GlyphOptions::default().iou_goal)]
    iou: f64,
    /// Most cubic segments per glyph.
    #[arg(long, default_value_t = GlyphOptions::default().max_segments)]
    max_segments: usize,
    /// Optimizer steps per round (after the start and after each added segment).
    #[arg(long, default_value_t = GlyphOptions::default().iters)]
    iters: usize,
    #[command(flatten)]
    fonts: FontArgs,
    /// Fill the fitted outlines with the even-odd rule instead of nonzero.
    #[arg(long)]
    evenodd: bool,
    /// One JSON object per glyph and a summary object on stdout instead of the table.
    #[arg(long)]
    json: bool,
    /// Print only the summary line.
    #[arg(long, short)]
    quiet: bool,
}

/// One glyph's result.
struct Row {
    name: String,
    font: Option<(usize, usize)>,
    target: Image,
    out: GlyphOutcome,
}

/// Runs `diffsvg glyphs`.
pub fn run(a: Args) -> Result<()> {
    if a.size < 8 {
        bail!("--size {} must be at least 8 pixels", a.size);
    }
    let opts = GlyphOptions {
        iou_goal: a.iou,
        max_segments: a.max_segments,
        iters: a.iters,
        rule: if a.evenodd {
            FillRule::EvenOdd
        } else {
            FillRule::NonZero
        },
        ..GlyphOptions::default()
    };
    opts.validate().map_err(super::util::flag_error)?;
    let inputs = if a.inputs.is_empty() {
        vec![PathBuf::from("svg-samples/glyphs")]
    } else {
        a.inputs.clone()
    };
    for i in &inputs {
        if !i.exists() {
            bail!("{}: no such file or folder", i.display());
        }
    }
    let files = collect_svgs(&inputs)?;
    if files.is_empty() {
        bail!(
            "{}: no SVG files found",
            inputs
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if a.output.is_file() {
        bail!("{}: output must be a folder", a.output.display());
    }
    let csv_path = a.output.join("glyphs.csv");
    check_output(&csv_path, "csv")?;
    // Load everything first, so that a bad file fails before the long part.
    let mut targets = Vec::with_capacity(files.len());
    let mut names = std::collections::BTreeSet::new();
    let fonts = a.fonts.fonts();
    for f in &files {
        let scene = Scene::load_with(f, Sizing::Width(a.size), &fonts)?;
        let mut target = render(&scene, &RenderOptions::default());
        target.over_background([1.0; 4]);
        let (contours, segments) = count_ink_segments(&scene);
        let font = (segments > 0).then_some((contours, segments));
        let name = stem(f);
        if !names.insert(name.clone()) {
            bail!(
                "{}: another input has the same name {name:?} (outputs would collide)",
                f.display()
            );
        }
        targets.push((name, font, target));
    }
    let table = !a.json && !a.quiet;
    if table {
        println!("{}", header());
    }
    let mut rows = Vec::with_capacity(targets.len());
    for (name, font, target) in targets {
        let out = fit_glyph(&target, &opts);
        let mut scene = out.scene.clone();
        scene.nodes.insert(0, Node::Path(background(&scene)));
        scene.save_svg(a.output.join(format!("{name}.svg")))?;
        let row = Row {
            name,
            font,
            target,
            out,
        };
        if a.json {
            println!("{}", row_json(&row));
        } else if table {
            println!("{}", table_row(&row));
        }
        rows.push(row);
    }
    let mut csv = String::from(
        "glyph,font_contours,font_segments,contours,segments,per_contour,iou,mse,ms,reached\n",
    );
    for r in &rows {
        let (fc, fs) = match r.font {
            Some((c, s)) => (c.to_string(), s.to_string()),
            None => (String::new(), String::new()),
        };
        let _ = writeln!(
            csv,
            "{},{fc},{fs},{},{},{},{:.5},{:.6e},{:.0},{}",
            r.name,
            r.out.per_contour.len(),
            r.out.segments,
            per_contour(&r.out),
            r.out.iou,
            r.out.mse,
            ms(&r.out),
            r.out.reached
        );
    }
    write_atomic(&csv_path, csv.as_bytes())?;
    let fits: Vec<Image> = rows
        .iter()
        .map(|r| {
            let mut img = render(&r.out.scene, &RenderOptions::default());
            img.over_background([1.0; 4]);
            img
        })
        .collect();
    let pairs: Vec<(&Image, &Image)> = rows.iter().map(|r| &r.target).zip(&fits).collect();
    let sheet = contact_sheet(&pairs, pairs.len().min(10), 4, [0.8, 0.8, 0.8, 1.0]);
    sheet.save_png(a.output.join("contact.png"))?;
    let reached = rows.iter().filter(|r| r.out.reached).count();
    let fitted: usize = rows.iter().map(|r| r.out.segments).sum();
    let font: usize = rows.iter().filter_map(|r| r.font.map(|f| f.1)).sum();
    let secs: f64 = rows.iter().map(|r| r.out.elapsed.as_secs_f64()).sum();
    if a.json {
        println!(
            "{}",
            json!({"done": true, "output": a.output, "glyphs": rows.len(), "reached": reached,
                "segments": fitted, "font_segments": font, "seconds": secs})
        );
    } else {
        println!(
            "glyphs: {reached} of {} reached IoU {} with {fitted} cubic segments in all \
             (font: {font}), {secs:.2} s; wrote {}",
            rows.len(),
            a.iou,
            a.output.display()
        );
    }
    Ok(())
}

/// The file name without its extension.
fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "glyph".into())
}

/// A white rectangle over the whole canvas.
fn background(scene: &Scene) -> diffsvg::scene::Path {
    let (w, h) = (scene.width as f64, scene.height as f64);
    let mut p = diffsvg::scene::Path::new("background");
    p.move_to([0.0, 0.0]);
    p.line_to([w, 0.0]);
    p.line_to([w, h]);
    p.line_to([0.0, h]);
    p.close();
    p.fill = Some(Fill {
        paint: Paint::Solid([1.0; 3]),
        opacity: 1.0,
        rule: FillRule::NonZero,
    });
    p
}

fn per_contour(o: &GlyphOutcome) -> String {
    o.per_contour
        .iter()
        .map(|n| n.to_string())
        .collect::<Vec<_>>()
        .join(";")
}

fn ms(o: &GlyphOutcome) -> f64 {
    o.elapsed.as_secs_f64() * 1e3
}

fn header() -> String {
    format!(
        "{:<12} {:>13} {:>9} {:>16} {:>8} {:>10} {:>7}",
        "glyph", "font segments", "contours", "fitted segments", "IoU", "MSE", "ms"
    )
}

fn table_row(r: &Row) -> String {
    let font = r.font.map_or("–".to_string(), |f| f.1.to_string());
    let fitted = format!(
        "{}{} ({})",
        r.out.segments,
        if r.out.reached { "" } else { "*" },
        per_contour(&r.out).replace(';', "+")
    );
    format!(
        "{:<12} {:>13} {:>9} {:>16} {:>8.4} {:>10.3e} {:>7.0}",
        r.name,
        font,
        r.out.per_contour.len(),
        fitted,
        r.out.iou,
        r.out.mse,
        ms(&r.out)
    )
}

fn row_json(r: &Row) -> serde_json::Value {
    json!({
        "glyph": r.name,
        "font_contours": r.font.map(|f| f.0),
        "font_segments": r.font.map(|f| f.1),
        "contours": r.out.per_contour.len(),
        "segments": r.out.segments,
        "per_contour": r.out.per_contour,
        "holes": r.out.holes,
        "iou": r.out.iou,
        "mse": r.out.mse,
        "reached": r.out.reached,
        "rounds": r.out.rounds,
        "steps": r.out.steps,
        "ms": ms(&r.out),
    })
}

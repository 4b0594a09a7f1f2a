//! `diffsvg digits`: strokes fitted to MNIST digits, one SVG each, a summary CSV and a
//! contact sheet.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use rayon::prelude::*;
use serde_json::json;

use diffsvg::fit::digit::{DigitFit, DigitOptions, fit_digit, gray_image};
use diffsvg::image_io::{Image, contact_sheet, write_atomic};
use diffsvg::mnist::{parse_indices, read_images, read_labels};
use diffsvg::scene::{Fill, FillRule, Node, Paint, Path, Scene};

/// Arguments of `diffsvg digits`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// IDX image file (e.g. t10k-images-idx3-ubyte, gzip or not).
    #[arg(long)]
    images: PathBuf,
    /// IDX label file, for the summary (optional).
    #[arg(long)]
    labels: Option<PathBuf>,
    /// Which digits: `0..100` (half-open), `7`, or a comma-separated mix.
    #[arg(long, default_value = "0..100")]
    indices: String,
    /// Output folder: digit-NNNNN.svg per digit, summary.csv, contact.png.
    #[arg(short, long)]
    output: PathBuf,
    /// Fitting resolution as a multiple of the image size.
    #[arg(long, default_value_t = DigitOptions::default().scale)]
    scale: u32,
    /// Add curves while the IoU of the inked areas is below this.
    #[arg(long, default_value_t = DigitOptions::default().target_iou)]
    target_iou: f64,
    /// Most strokes per digit.
    #[arg(long, default_value_t = DigitOptions::default().max_strokes)]
    max_strokes: usize,
    /// Most cubic segments per stroke.
    #[arg(long, default_value_t = DigitOptions::default().max_segments)]
    max_segments: usize,
    /// Optimizer steps for the first curve.
    #[arg(long, default_value_t = DigitOptions::default().steps)]
    steps: usize,
    /// Optimizer steps after each added curve.
    #[arg(long, default_value_t = DigitOptions::default().stage_steps)]
    stage_steps: usize,
    /// Print one JSON object per digit and a summary object instead of a progress bar.
    #[arg(long)]
    json: bool,
    /// No progress output (the summary line is still printed).
    #[arg(long, short)]
    quiet: bool,
}

struct Row {
    index: usize,
    label: Option<u8>,
    fit: DigitFit,
    ms: f64,
}

/// Runs `diffsvg digits`.
pub fn run(a: Args) -> Result<()> {
    let opts = options(&a)?;
    let images = read_images(&a.images)?;
    let labels = match &a.labels {
        Some(p) => {
            let l = read_labels(p)?;
            if l.len() != images.len() {
                bail!(
                    "{}: {} labels for {} images in {}",
                    p.display(),
                    l.len(),
                    images.len(),
                    a.images.display()
                );
            }
            Some(l)
        }
        None => None,
    };
    let listed = parse_indices(&a.indices, images.len())
        .map_err(|e| anyhow::anyhow!("--indices {}: {e}", a.indices))?;
    // Each digit is fitted and written once: a repeated index would only race two
    // writers of the same file.
    let (indices, repeated) = dedupe(&listed);
    if repeated > 0 {
        eprintln!(
            "note: --indices {} lists {repeated} index(es) more than once; each digit is fitted once",
            a.indices
        );
    }
    // The fitting canvas is the digit's size times --scale.
    let (fw, fh) = (
        (images.cols as u64 * a.scale as u64).min(u32::MAX as u64) as u32,
        (images.rows as u64 * a.scale as u64).min(u32::MAX as u64) as u32,
    );
    diffsvg::image_io::check_image_size(fw, fh, &a.images)
        .with_context(|| format!("--scale {}: fitting canvas too large", a.scale))?;
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("{}: cannot create the output folder", a.output.display()))?;

    let (w, h) = (images.cols, images.rows);
    let bar = super::progress::terminal_bar(a.json || a.quiet, indices.len(), "digits");
    let start = Instant::now();
    let error = Mutex::new(None);
    let mut rows: Vec<Row> = indices
        .par_iter()
        .map(|&index| {
            let t0 = Instant::now();
            let fit = fit_digit(&images.get(index), w, h, &opts);
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            let row = Row {
                index,
                label: labels.as_ref().map(|l| l[index]),
                fit,
                ms,
            };
            let svg = a.output.join(format!("digit-{index:05}.svg"));
            if let Err(e) = on_black(&row.fit.scene).save_svg(&svg) {
                error.lock().unwrap().get_or_insert(e);
            }
            if let Some(b) = &bar {
                b.inc(1);
            }
            if a.json {
                println!("{}", row_json(&row));
            }
            row
        })
        .collect();
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    if let Some(e) = error.into_inner().unwrap() {
        return Err(e.into());
    }
    let secs = start.elapsed().as_secs_f64();
    rows.sort_by_key(|r| r.index);
    write_atomic(&a.output.join("summary.csv"), summary_csv(&rows).as_bytes())?;
    if rows.len() > CONTACT_SHEET_DIGITS {
        eprintln!(
            "note: the contact sheet shows the first {CONTACT_SHEET_DIGITS} of {} digits",
            rows.len()
        );
    }
    contact(&rows, &images, w, h).save_png(a.output.join("contact.png"))?;

    let n = rows.len() as f64;
    let mean = |f: &dyn Fn(&Row) -> f64| rows.iter().map(f).sum::<f64>() / n;
    let (mse, iou) = (mean(&|r| r.fit.mse), mean(&|r| r.fit.iou));
    let curves = mean(&|r| r.fit.curves() as f64);
    let strokes: usize = rows.iter().map(|r| r.fit.segments.len()).sum();
    let rate = n / secs.max(1e-9);
    if a.json {
        println!(
            "{}",
            json!({"done": true, "output": a.output, "digits": rows.len(), "mean_mse": mse,
                "mean_iou": iou, "mean_curves": curves, "paths": strokes,
                "digits_per_second": rate, "seconds": secs})
        );
    } else {
        println!(
            "digits: {} fitted, mean MSE {mse:.4}, mean IoU {iou:.3}, {curves:.2} curves per digit, \
             {rate:.1} digits/s ({secs:.2} s); wrote {}",
            rows.len(),
            a.output.display()
        );
    }
    Ok(())
}

fn options(a: &Args) -> Result<DigitOptions> {
    let opts = DigitOptions {
        scale: a.scale,
        target_iou: a.target_iou,
        max_strokes: a.max_strokes,
        max_segments: a.max_segments,
        steps: a.steps,
        stage_steps: a.stage_steps,
        ..DigitOptions::default()
    };
    opts.validate().map_err(super::util::flag_error)?;
    Ok(opts)
}

/// `v` without repeats, in first-seen order, and how many repeats were dropped.
fn dedupe(v: &[usize]) -> (Vec<usize>, usize) {
    let mut seen = std::collections::HashSet::new();
    let out: Vec<usize> = v.iter().copied().filter(|i| seen.insert(*i)).collect();
    let dropped = v.len() - out.len();
    (out, dropped)
}

/// Most digits shown on the contact sheet, so that it stays a small picture (about 4
/// megapixels) whatever the number of digits fitted.
const CONTACT_SHEET_DIGITS: usize = 2000;

/// The fitted strokes over a black square, as the digit is shown.
fn on_black(scene: &Scene) -> Scene {
    let (w, h) = (scene.width as f64, scene.height as f64);
    let mut bg = Path::new("background");
    bg.move_to([0.0, 0.0]);
    bg.line_to([w, 0.0]);
    bg.line_to([w, h]);
    bg.line_to([0.0, h]);
    bg.close();
    bg.fill = Some(Fill {
        paint: Paint::Solid([0.0; 3]),
        opacity: 1.0,
        rule: FillRule::NonZero,
    });
    let mut out = scene.clone();
    out.nodes.insert(0, Node::Path(bg));
    out
}

fn row_json(r: &Row) -> serde_json::Value {
    json!({"index": r.index, "label": r.label, "strokes": r.fit.segments.len(),
        "segments": r.fit.curves(), "mse": r.fit.mse, "iou": r.fit.iou, "ms": r.ms})
}

fn summary_csv(rows: &[Row]) -> String {
    let mut s = String::from("index,label,strokes,segments,mse,iou,ms\n");
    for r in rows {
        let label = r.label.map(|l| l.to_string()).unwrap_or_default();
        let _ = writeln!(
            s,
            "{},{label},{},{},{:.6},{:.4},{:.2}",
            r.index,
            r.fit.segments.len(),
            r.fit.curves(),
            r.fit.mse,
            r.fit.iou,
            r.ms
        );
    }
    s
}

/// Target above fit for every digit (the first [`CONTACT_SHEET_DIGITS`]), 2× enlarged when
/// there are few.
fn contact(rows: &[Row], images: &diffsvg::mnist::Images, w: usize, h: usize) -> Image {
    let rows = &rows[..rows.len().min(CONTACT_SHEET_DIGITS)];
    let k = if rows.len() <= 200 { 2 } else { 1 };
    let up = |img: Image| {
        let mut out = Image::new(img.width * k, img.height * k);
        for y in 0..out.height {
            for x in 0..out.width {
                out.data[(y * out.width + x) as usize] = img.get(x / k, y / k);
            }
        }
        out
    };
    let pairs: Vec<(Image, Image)> = rows
        .iter()
        .map(|r| {
            (
                up(gray_image(&images.get(r.index), w, h)),
                up(gray_image(&r.fit.rendering, w, h)),
            )
        })
        .collect();
    let refs: Vec<(&Image, &Image)> = pairs.iter().map(|(a, b)| (a, b)).collect();
    let columns = (2.0 * rows.len() as f64).sqrt().ceil().max(1.0) as usize;
    contact_sheet(&refs, columns.clamp(1, 40), 2, [0.25, 0.25, 0.3, 1.0])
}

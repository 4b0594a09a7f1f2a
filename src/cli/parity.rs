//! `diffsvg parity`: compare diffsvg with resvg over folders of SVGs.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use super::util::{FontArgs, SizeArgs};
use diffsvg::raster::RenderOptions;
use diffsvg::reference::{
    EXACT_FACTOR, PARITY_MAE, PARITY_PSNR, ParityError, closer_to_exact, parity_checked_with,
    parity_with,
};
use diffsvg::scene::Fonts;

/// Arguments of `diffsvg parity`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// SVG files or folders (searched recursively).
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    #[command(flatten)]
    size: SizeArgs,
    #[command(flatten)]
    fonts: FontArgs,
    /// resvg's test-suite font setup: the fonts of this folder (the suite's `fonts/`),
    /// serif Noto Serif, sans-serif Noto Sans, cursive Yellowtail, fantasy Sedgwick Ave
    /// Display, monospace Noto Mono, missing families set in Noto Serif (as resvg's own
    /// test harness does). `--font` and `--font-dir` add to it.
    #[arg(long, value_name = "DIR")]
    resvg_fonts: Option<PathBuf>,
    /// Write a Markdown table of pass rates per folder here.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Write `ours | resvg | difference` images of failing files into this folder.
    #[arg(long)]
    failures: Option<PathBuf>,
    /// Instead of the pass rates: the MAE (0–255 levels) of diffsvg (as it renders by
    /// default, with the clamped winding integral where paths overlap themselves, and with
    /// `RenderOptions::exact_overlaps`) and of resvg against
    /// resvg rendered N times larger and box-filtered down (N × N samples per pixel), one
    /// row per file and the means, as a Markdown table (to `--report` as well).
    #[arg(long, value_name = "N")]
    supersampled: Option<u32>,
}

/// What happened to one file.
#[derive(Debug)]
pub enum Outcome {
    /// Rendered by both; MAE (levels) and PSNR (dB) against resvg, and for a file that
    /// does not pass, diffsvg's and resvg's MAE against the exact rendering where it
    /// could be measured ([`closer_to_exact`]).
    Compared {
        mae: f64,
        max: f64,
        psnr: f64,
        pass: bool,
        exact: Option<[f64; 2]>,
    },
    /// diffsvg refused it (unsupported feature or invalid file).
    Refused(String),
    /// diffsvg rendered it but the reference could not (resvg panicked, or the drawing
    /// lies beyond what tiny-skia rasterizes), or a renderer panicked: a failed file.
    Failed(String),
}

/// Finds SVG files under `inputs`, sorted.
pub fn collect_svgs(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in inputs {
        if p.is_dir() {
            walk(p, &mut out).with_context(|| format!("{}: cannot list folder", p.display()))?;
        } else {
            out.push(p.clone());
        }
    }
    out.sort();
    Ok(out)
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> std::io::Result<()> {
    for e in std::fs::read_dir(dir)? {
        let p = e?.path();
        if p.is_dir() {
            walk(&p, out)?;
        } else if p.extension().is_some_and(|e| e == "svg") {
            out.push(p);
        }
    }
    Ok(())
}

/// Compares one file. A panic of either renderer is caught and reported as
/// [`Outcome::Failed`], so that one file cannot stop a run over a folder.
pub fn check(path: &Path, sizing: diffsvg::Sizing, fonts: &Fonts) -> Outcome {
    let run = || parity_checked_with(path, sizing, &RenderOptions::default(), fonts);
    // The fonts' database is only read here (built before the files are shared out): a
    // panic cannot leave it half-changed.
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(run)) {
        Ok(Ok(p)) => {
            let pass = p.passes();
            // Where the two differ, which is nearer the exact rendering (a failure to
            // measure it leaves the file failed).
            let exact = if pass {
                None
            } else {
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    closer_to_exact(path, sizing, fonts)
                }))
                .ok()
                .and_then(|r| r.ok())
                .flatten()
            };
            Outcome::Compared {
                mae: p.comparison.mae,
                max: p.comparison.max,
                psnr: p.comparison.psnr,
                pass,
                exact,
            }
        }
        Ok(Err(ParityError::Ours(e))) => Outcome::Refused(e.to_string()),
        Ok(Err(ParityError::Reference(e))) => Outcome::Failed(e.to_string()),
        Err(_) => Outcome::Failed(format!("{}: diffsvg panicked", path.display())),
    }
}

impl Args {
    /// The fonts of `--resvg-fonts` (or the bundled ones) and the font flags.
    fn fonts(&self) -> Fonts {
        let base = match &self.resvg_fonts {
            Some(dir) => Fonts::resvg_test_suite(dir),
            None => Fonts::new(),
        };
        self.fonts.add_to(base)
    }
}

/// `diffsvg parity --supersampled N`: both renderers' MAE against the box-filtered
/// reference, per file.
fn supersampled(
    a: &Args,
    files: &[PathBuf],
    sizing: diffsvg::Sizing,
    fonts: &Fonts,
    factor: u32,
) -> Result<()> {
    use diffsvg::reference::supersampled_mae;
    use rayon::prelude::*;
    let (clamped, exact) = (
        RenderOptions::default(),
        RenderOptions {
            exact_overlaps: true,
            ..RenderOptions::default()
        },
    );
    type Row = diffsvg::Result<[f64; 3]>;
    let rows: Vec<(PathBuf, Row)> = files
        .par_iter()
        .map(|f| {
            let r = supersampled_mae(f, sizing, &clamped, fonts, factor).and_then(|(a, c)| {
                let (b, _) = supersampled_mae(f, sizing, &exact, fonts, factor)?;
                Ok([a, b, c])
            });
            (f.clone(), r)
        })
        .collect();
    let mut table = String::from(
        "| file | diffsvg (clamped overlaps, the default) | diffsvg, exact overlaps | resvg MAE |\n|---|---:|---:|---:|\n",
    );
    let (mut sums, mut n) = ([0.0f64; 3], 0usize);
    for (f, r) in &rows {
        match r {
            Ok(m) => {
                table += &format!(
                    "| {} | {:.3} | {:.3} | {:.3} |\n",
                    f.display(),
                    m[0],
                    m[1],
                    m[2]
                );
                for k in 0..3 {
                    sums[k] += m[k];
                }
                n += 1;
            }
            Err(e) => println!("SKIPPED {e}"),
        }
    }
    if n > 0 {
        let mean = sums.map(|v| v / n as f64);
        table += &format!(
            "| mean of {n} files | {:.3} | {:.3} | {:.3} |\n",
            mean[0], mean[1], mean[2]
        );
    }
    print!("{table}");
    if let Some(path) = &a.report {
        std::fs::write(path, &table)
            .with_context(|| format!("{}: cannot write", path.display()))?;
    }
    Ok(())
}

/// Runs `diffsvg parity`.
pub fn run(a: Args) -> Result<()> {
    use rayon::prelude::*;
    let sizing = a.size.sizing()?;
    let files = collect_svgs(&a.inputs)?;
    let fonts = a.fonts();
    // Built once, before the files are shared out, so that a bad font flag is one error.
    fonts.database()?;
    if let Some(factor) = a.supersampled {
        return supersampled(&a, &files, sizing, &fonts, factor);
    }
    let outcomes: Vec<(PathBuf, Outcome)> = files
        .par_iter()
        .map(|f| (f.clone(), check(f, sizing, &fonts)))
        .collect();
    // Per folder: (files, passed, refused, nearer the exact rendering than resvg).
    let mut per: BTreeMap<String, [usize; 4]> = BTreeMap::new();
    for (f, o) in &outcomes {
        // Folders relative to the input they were found under.
        let base = a.inputs.iter().find(|i| f.starts_with(i));
        let parent = f.parent().unwrap_or(f);
        let folder = match base {
            Some(b) if b.is_dir() => {
                let rel = parent
                    .strip_prefix(b)
                    .unwrap_or(parent)
                    .display()
                    .to_string();
                if rel.is_empty() { ".".to_string() } else { rel }
            }
            _ => parent.display().to_string(),
        };
        let e = per.entry(folder).or_default();
        e[0] += 1;
        match o {
            Outcome::Compared {
                mae,
                max,
                psnr,
                pass,
                exact,
            } => {
                if *pass {
                    e[1] += 1;
                } else if let Some([ours, theirs]) = exact.filter(|[o, r]| o <= r) {
                    e[3] += 1;
                    println!(
                        "NEARER EXACT {}: MAE {mae:.3}, PSNR {psnr:.1} dB against resvg; \
                         against {EXACT_FACTOR}×{EXACT_FACTOR} samples diffsvg {ours:.3}, \
                         resvg {theirs:.3}",
                        f.display()
                    );
                } else {
                    println!(
                        "FAIL {}: MAE {mae:.3}, max {max:.0}, PSNR {psnr:.1} dB",
                        f.display()
                    );
                    if let Some(dir) = &a.failures {
                        std::fs::create_dir_all(dir)
                            .with_context(|| format!("{}: cannot create folder", dir.display()))?;
                        // It rendered a moment ago; should it not now, skip the picture.
                        let Ok(p) = parity_with(f, sizing, &RenderOptions::default(), &fonts)
                        else {
                            continue;
                        };
                        let stem = f.file_stem().unwrap_or_default().to_string_lossy();
                        let side = diffsvg::image_io::side_by_side(&[
                            &p.ours,
                            &p.reference,
                            &diffsvg::metrics::difference_image(&p.ours, &p.reference),
                        ]);
                        side.save_png(dir.join(format!("{stem}.png")))?;
                    }
                }
            }
            Outcome::Refused(why) => {
                e[2] += 1;
                println!("REFUSED {why}");
            }
            Outcome::Failed(why) => println!("FAIL {why}"),
        }
    }
    let pct = |n: usize, of: usize| {
        if of == 0 {
            "–".to_string()
        } else {
            format!("{:.1}%", 100.0 * n as f64 / of as f64)
        }
    };
    let mut table = String::from(
        "| folder | files | pass | nearer exact | refused | fail | pass rate | of supported |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    let mut tot = [0usize; 4];
    let row = |k: &str, v: [usize; 4]| {
        let ok = v[1] + v[3];
        format!(
            "| {k} | {} | {} | {} | {} | {} | {} | {} |\n",
            v[0],
            v[1],
            v[3],
            v[2],
            v[0] - ok - v[2],
            pct(ok, v[0]),
            pct(ok, v[0] - v[2])
        )
    };
    for (k, v) in &per {
        table += &row(k, *v);
        for i in 0..4 {
            tot[i] += v[i];
        }
    }
    table += &row("**all**", tot);
    println!("{table}");
    println!(
        "pass = MAE ≤ {PARITY_MAE}/255 and PSNR ≥ {PARITY_PSNR} dB against resvg; nearer exact = \
         differs from resvg, but nearer than resvg to resvg's rendering with \
         {EXACT_FACTOR}×{EXACT_FACTOR} samples per pixel (files that turn anti-aliasing off \
         excepted); pass rate = (pass + nearer exact) / files"
    );
    if let Some(r) = &a.report {
        diffsvg::image_io::write_atomic(r, table.as_bytes())?;
    }
    Ok(())
}

//! `diffsvg compare`: several `recon` runs' test PSNR against training time in one chart.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args as ClapArgs;

use super::plot::{PlotSpec, Series, write_plot};

/// Arguments of `diffsvg compare`.
#[derive(ClapArgs, Debug)]
pub struct Args {
    /// Logs written by `recon voxel` or `recon splat` (MODEL.log.csv, with `--eval-every`
    /// for test PSNR points); each is one series, named after its file.
    #[arg(required = true)]
    logs: Vec<PathBuf>,
    /// The chart, a PNG (an SVG of it is written beside it).
    #[arg(short, long)]
    output: PathBuf,
    /// Chart title.
    #[arg(long, default_value = "Test PSNR against training time")]
    title: String,
}

/// Runs `diffsvg compare`.
pub fn run(a: Args) -> Result<()> {
    let mut series = Vec::new();
    for log in &a.logs {
        let points = test_points(log)?;
        if points.is_empty() {
            bail!(
                "{}: no test PSNR in the log (train with --eval-every)",
                log.display()
            );
        }
        series.push(Series::new(run_name(log), points));
    }
    let spec = PlotSpec::new(a.title, "training seconds", "test PSNR (dB)");
    write_plot(&spec, &series, &a.output, a.output.with_extension("svg"))?;
    println!(
        "compare: {} runs; wrote {}",
        series.len(),
        a.output.display()
    );
    Ok(())
}

/// The log's file name without `.log.csv` (or its extension).
fn run_name(log: &Path) -> String {
    let name = log
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    match name.strip_suffix(".log.csv") {
        Some(stem) => stem.to_string(),
        None => log
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or(name),
    }
}

/// The `(seconds, test_psnr)` rows of a recon log that have a test PSNR.
fn test_points(log: &Path) -> Result<Vec<(f64, f64)>> {
    let text =
        std::fs::read_to_string(log).with_context(|| format!("{}: cannot read", log.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let column = |name: &str| {
        header
            .iter()
            .position(|h| h.trim() == name)
            .with_context(|| {
                format!(
                    "{}: not a recon log (no `{name}` column in its header)",
                    log.display()
                )
            })
    };
    let (secs, psnr) = (column("seconds")?, column("test_psnr")?);
    let mut points = Vec::new();
    for (n, line) in lines.enumerate() {
        let cells: Vec<&str> = line.split(',').collect();
        let cell = |i: usize| cells.get(i).map(|c| c.trim()).unwrap_or("");
        if cell(psnr).is_empty() {
            continue;
        }
        let parse = |i: usize| -> Result<f64> {
            let v: f64 = cell(i)
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite())
                .with_context(|| {
                    format!(
                        "{}: line {}: `{}` is not a number",
                        log.display(),
                        n + 2,
                        cell(i)
                    )
                })?;
            Ok(v)
        };
        points.push((parse(secs)?, parse(psnr)?));
    }
    Ok(points)
}

//! What `recon voxel`, `recon splat` and `view` share: the progress flags, the summary's
//! PSNR text, the model's sibling files (log, PSNR plot) and notes on stderr.

use std::path::{Path, PathBuf};

use anyhow::Result;

use super::plot::{PlotSpec, Series, write_plot};
use diffsvg::volume::dataset::Dataset;
use diffsvg::volume::recon::load_for_splat;

/// Progress and evaluation flags of `recon voxel` and `recon splat`.
#[derive(clap::Args, Debug)]
pub(super) struct Reporting {
    /// Every this many iterations, render the test views and log their mean PSNR (the
    /// time this takes is not counted as training time); 0: only at the end.
    #[arg(long, default_value_t = 0)]
    pub eval_every: usize,
    /// Print one JSON object per 50 iterations and a summary instead of a progress bar.
    #[arg(long)]
    pub json: bool,
    /// No progress output (the summary line is still printed).
    #[arg(long, short)]
    pub quiet: bool,
}

/// A test PSNR for the summary line: `"31.20 dB"` or why there is none.
pub(super) fn psnr_text(p: Option<f64>) -> String {
    p.map(|p| format!("{p:.2} dB"))
        .unwrap_or_else(|| "n/a (no test views)".into())
}

/// `model` with its extension replaced by `suffix` (`lego.vox` → `lego.log.csv`).
pub(super) fn sibling(model: &Path, suffix: &str) -> PathBuf {
    let mut p = model.with_extension("").into_os_string();
    p.push(suffix);
    PathBuf::from(p)
}

/// When the test views were evaluated more than once, writes `<model>.psnr.png` and
/// `.psnr.svg`: test PSNR (and the training batches' or views', labelled `train_label`)
/// against training seconds.
pub(super) fn write_psnr_plot(
    model: &Path,
    tests: Vec<(f64, f64)>,
    train: Vec<(f64, f64)>,
    train_label: &str,
) -> Result<()> {
    if tests.len() < 2 {
        return Ok(());
    }
    let spec = PlotSpec::new(
        format!(
            "{}: PSNR against training time",
            file_stem(&model.to_string_lossy())
        ),
        "training seconds",
        "PSNR (dB)",
    );
    let series = [
        Series::new("test views", tests),
        Series::new(train_label, train),
    ];
    write_plot(
        &spec,
        &series,
        sibling(model, ".psnr.png"),
        sibling(model, ".psnr.svg"),
    )?;
    Ok(())
}

/// A view's name as a file stem (`./test/r_0` → `r_0`).
pub(super) fn file_stem(name: &str) -> String {
    Path::new(name)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| name.replace(['/', '\\'], "_"))
}

/// Says on stderr that a dataset's photos were undistorted for splatting, and how much.
pub(super) fn undistortion_note(dir: &Path, outside: f64) {
    eprintln!(
        "note: {}: the photos have lens distortion; undistorted to pinhole views ({:.2}% of \
         pixels fell outside the photos and repeat its edge)",
        dir.display(),
        100.0 * outside
    );
}

/// Loads a dataset for splatting ([`load_for_splat`]), with its warnings and a note on
/// stderr when its photos were undistorted.
pub(super) fn load_splat_dataset(dir: &Path, downscale: u32) -> Result<Dataset> {
    let loading = diffsvg::volume::dataset::Loading {
        downscale,
        test_every: None,
    };
    let (data, undistorted) = load_for_splat(dir, &loading)?;
    super::util::print_warnings(&data.warnings);
    if let Some(outside) = undistorted {
        undistortion_note(dir, outside);
    }
    Ok(data)
}

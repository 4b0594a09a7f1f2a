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

/// Pose refinement flags of `recon voxel` and `recon splat`.
#[derive(clap::Args, Debug)]
pub(super) struct PoseArgs {
    /// Learn a small correction of each training view's camera pose (a turn about its
    /// center and a move, by gradient descent next to the model); test views keep their
    /// poses.
    #[arg(long)]
    pub refine_poses: bool,
    /// Testing aid: before training, move every training camera by a random turn of DEG
    /// degrees about its center and a move of UNITS world units (seeded by --seed); test
    /// views keep their poses. The summary says how far the poses were from the loaded
    /// ones before and after training.
    #[arg(long, value_name = "DEG,UNITS", value_parser = parse_perturbation)]
    pub perturb_poses: Option<[f32; 2]>,
}

fn parse_perturbation(s: &str) -> std::result::Result<[f32; 2], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let bad = || format!("{s:?}: expected DEG,UNITS, two numbers such as 0.5,0.04");
    if parts.len() != 2 {
        return Err(bad());
    }
    let deg: f32 = parts[0].parse().map_err(|_| bad())?;
    let units: f32 = parts[1].parse().map_err(|_| bad())?;
    Ok([deg, units])
}

/// The pose error line of the summary, when poses were perturbed, with the test PSNR in
/// the model's frame (`in_frame`) where there is one.
pub(super) fn pose_error_text(
    e: &Option<diffsvg::volume::recon::PoseError>,
    in_frame: Option<f64>,
) -> String {
    let in_frame = in_frame
        .map(|p| format!(" ({p:.2} dB with the test cameras in the model's frame)"))
        .unwrap_or_default();
    match e {
        Some(e) => format!(
            "{in_frame}; training poses off by {:.3}° and {:.4} units before, {:.3}° and {:.4} after \
             ({:.3}° and {:.4} in the model's frame, which is off by {:.3}° and {:.4})",
            e.before[0],
            e.before[1],
            e.after[0],
            e.after[1],
            e.after_in_frame[0],
            e.after_in_frame[1],
            e.frame[0],
            e.frame[1]
        ),
        None => String::new(),
    }
}

/// The pose error as JSON (`null` when poses were not perturbed).
pub(super) fn pose_error_json(e: &Option<diffsvg::volume::recon::PoseError>) -> serde_json::Value {
    match e {
        Some(e) => serde_json::json!({"before": {"degrees": e.before[0], "units": e.before[1]},
            "after": {"degrees": e.after[0], "units": e.after[1]},
            "after_in_frame": {"degrees": e.after_in_frame[0], "units": e.after_in_frame[1]},
            "frame": {"degrees": e.frame[0], "units": e.frame[1]}}),
        None => serde_json::Value::Null,
    }
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
        ..Default::default()
    };
    let (data, undistorted) = load_for_splat(dir, &loading)?;
    super::util::print_warnings(&data.warnings);
    if let Some(outside) = undistorted {
        undistortion_note(dir, outside);
    }
    Ok(data)
}

//! The ladder of representations: every 3D model diffsvg fits (voxels, Gaussians,
//! Instant-NGP, NeRF) trained on one scene with the same time budget, one after the
//! other, and scored the same way.
//!
//! Each rung is trained by its `recon_*` entry point ([`super::recon`]) with its job's
//! options and stopped once `seconds` of training are spent (the fields' learning rate
//! decays over that budget; voxels and Gaussians follow their iteration schedules, so
//! give them iterations that end near the budget). The model is written to
//! `OUTDIR/NAME.EXT` and read back as `view` reads it ([`Model`]); every test view is
//! rendered, timed and compared with its photo: mean PSNR (capped at 99 dB per view, as
//! `recon` reports it) and mean SSIM ([`super::metrics::ssim`]). Render times are
//! wall-clock seconds per view on the current rayon pool.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::dataset::Loading;
use super::metrics::{psnr, ssim};
use super::recon::{NgpJob, SplatJob, VoxelJob, fit_ngp, fit_splat, fit_voxel};
use super::view::Model;
use super::{field, splat, voxel};
use crate::error::{Error, Result};

/// One representation of the ladder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rung {
    /// A sparse voxel grid (`recon voxel`, `.vox`).
    Voxel,
    /// 3D Gaussians (`recon splat`, `.ply`).
    Splat,
    /// Instant-NGP (`recon ngp`, `.ngp`).
    Ngp,
    /// A NeRF MLP (`recon nerf`, `.nerf`).
    Nerf,
}

impl Rung {
    /// Every rung, in the order the ladder trains them.
    pub const ALL: [Rung; 4] = [Rung::Voxel, Rung::Splat, Rung::Ngp, Rung::Nerf];

    /// Its name (the `recon` subcommand).
    pub fn name(self) -> &'static str {
        match self {
            Rung::Voxel => "voxel",
            Rung::Splat => "splat",
            Rung::Ngp => "ngp",
            Rung::Nerf => "nerf",
        }
    }

    /// Its model file's extension.
    pub fn extension(self) -> &'static str {
        match self {
            Rung::Voxel => "vox",
            Rung::Splat => "ply",
            Rung::Ngp => "ngp",
            Rung::Nerf => "nerf",
        }
    }
}

/// What [`run_ladder`] trains: a time budget and each rung's job.
#[derive(Clone, Debug, PartialEq)]
pub struct LadderJob {
    /// Seconds of training per rung (> 0).
    pub seconds: f32,
    /// The rungs to train, in order.
    pub rungs: Vec<Rung>,
    /// The voxel grid's job.
    pub voxel: VoxelJob,
    /// The Gaussians' job.
    pub splat: SplatJob,
    /// Instant-NGP's job.
    pub ngp: NgpJob,
    /// The NeRF field's job ([`NgpJob::nerf`]).
    pub nerf: NgpJob,
    /// Score only the first this many test views (`None`: all); rendering the NeRF
    /// field's views takes minutes.
    pub test_views: Option<usize>,
}

impl LadderJob {
    /// Every rung with its `recon` defaults, `seconds` each, photos divided by
    /// `downscale`.
    pub fn new(seconds: f32, downscale: u32) -> LadderJob {
        LadderJob {
            seconds,
            rungs: Rung::ALL.to_vec(),
            voxel: VoxelJob {
                downscale,
                ..VoxelJob::default()
            },
            splat: SplatJob {
                downscale,
                ..SplatJob::default()
            },
            ngp: NgpJob {
                downscale,
                seconds,
                iters: crate::limits::MAX_ITERS,
                ..NgpJob::default()
            },
            nerf: NgpJob {
                downscale,
                seconds,
                iters: crate::limits::MAX_ITERS,
                ..NgpJob::nerf()
            },
            test_views: None,
        }
    }

    /// Holds out the views named in `list` in every job, instead of every N-th
    /// ([`Loading::test_list`](crate::volume::dataset::Loading::test_list)).
    pub fn with_test_list(mut self, list: Option<std::path::PathBuf>) -> LadderJob {
        self.voxel.test_list = list.clone();
        self.splat.test_list = list.clone();
        self.ngp.test_list = list.clone();
        self.nerf.test_list = list;
        self
    }

    /// Sets the held-out views and the seed of every job.
    pub fn with_views(mut self, test_every: Option<usize>, seed: u64) -> LadderJob {
        self.voxel.test_every = test_every;
        self.splat.test_every = test_every;
        self.ngp.test_every = test_every;
        self.nerf.test_every = test_every;
        self.voxel.seed = seed;
        self.splat.seed = seed;
        self.ngp.seed = seed;
        self.nerf.seed = seed;
        self
    }

    /// Checks the budget and every job.
    pub fn validate(&self) -> Result<()> {
        if !(self.seconds.is_finite() && self.seconds > 0.0) {
            return Err(Error::Setting {
                name: "seconds".into(),
                message: format!("{} must be a number > 0", self.seconds),
            });
        }
        self.voxel.validate()?;
        self.splat.validate()?;
        if self.test_views == Some(0) {
            return Err(Error::Setting {
                name: "test_views".into(),
                message: "0 must be at least 1".into(),
            });
        }
        self.ngp.validate()?;
        self.nerf.validate()
    }

    fn loading(&self, rung: Rung) -> Loading {
        match rung {
            Rung::Voxel => self.voxel.loading(),
            Rung::Splat => self.splat.loading(),
            Rung::Ngp => self.ngp.loading(),
            Rung::Nerf => self.nerf.loading(),
        }
    }
}

/// One row of the ladder's table.
#[derive(Clone, Debug, PartialEq)]
pub struct LadderRow {
    /// The representation.
    pub rung: Rung,
    /// Mean PSNR of the test views, dB (each capped at 99).
    pub test_psnr: f64,
    /// Mean SSIM of the test views.
    pub ssim: f64,
    /// Seconds of training (the observer's and the final evaluation's time not counted).
    pub train_seconds: f64,
    /// Iterations done.
    pub iterations: usize,
    /// Bytes of the model file.
    pub model_bytes: u64,
    /// Median wall-clock seconds to render one test view.
    pub render_seconds: f64,
    /// Test views scored.
    pub views: usize,
    /// The model file written.
    pub model: PathBuf,
    /// `(seconds of training, batch PSNR in dB)` after every iteration: the curve of the
    /// chart.
    pub curve: Vec<(f64, f64)>,
}

/// Trains every rung of `job` on `scene` in turn, writes each model into `out_dir`, and
/// scores it on the test views. `progress` is called after every iteration with the
/// rung, seconds of training and batch PSNR; it returns false to stop the whole ladder
/// (the rows done so far are returned).
///
/// # Errors
/// An invalid job, an unreadable scene or one without test views, an unwritable
/// `out_dir`, a model that fails to render.
pub fn run_ladder(
    scene: &Path,
    job: &LadderJob,
    out_dir: &Path,
    progress: &mut dyn FnMut(Rung, f32, f32) -> bool,
) -> Result<Vec<LadderRow>> {
    job.validate()?;
    std::fs::create_dir_all(out_dir).map_err(|e| Error::io(out_dir, e))?;
    let budget = job.seconds;
    let mut rows = Vec::new();
    for &rung in &job.rungs {
        let mut curve = Vec::new();
        let mut stop_all = false;
        let mut step = |elapsed: f32, batch_psnr: f32| -> bool {
            curve.push((elapsed as f64, batch_psnr as f64));
            if !progress(rung, elapsed, batch_psnr) {
                stop_all = true;
            }
            !stop_all && elapsed < budget
        };
        let path = out_dir.join(format!("{}.{}", rung.name(), rung.extension()));
        let (train_seconds, iterations) = match rung {
            Rung::Voxel => {
                let r = fit_voxel(scene, &job.voxel, false, &mut |s, _| {
                    step(s.elapsed, s.psnr)
                })?;
                voxel::save(&r.grid, &path)?;
                (r.outcome.seconds, r.outcome.iterations)
            }
            Rung::Splat => {
                let r = fit_splat(scene, &job.splat, false, &mut |s, _| {
                    step(s.elapsed, s.psnr)
                })?;
                splat::save(&r.model, &path)?;
                (r.outcome.seconds, r.outcome.iterations)
            }
            Rung::Ngp | Rung::Nerf => {
                let j = if rung == Rung::Ngp {
                    &job.ngp
                } else {
                    &job.nerf
                };
                let r = fit_ngp(scene, j, false, &mut |s, _| step(s.elapsed, s.psnr))?;
                field::save(&r.model, &path)?;
                (r.outcome.seconds, r.outcome.iterations)
            }
        };
        let (test_psnr, ssim, render_seconds, views) = score(
            &path,
            scene,
            &job.loading(rung),
            job.voxel.step,
            job.test_views,
        )?;
        rows.push(LadderRow {
            rung,
            test_psnr,
            ssim,
            train_seconds: train_seconds as f64,
            iterations,
            model_bytes: std::fs::metadata(&path)
                .map_err(|e| Error::io(&path, e))?
                .len(),
            render_seconds,
            views,
            model: path,
            curve,
        });
        if stop_all {
            break;
        }
    }
    Ok(rows)
}

/// Mean PSNR, mean SSIM and the median render time of the (first `limit`) test views of
/// the model file `path`, read as `view` reads it.
fn score(
    path: &Path,
    scene: &Path,
    loading: &Loading,
    step: f32,
    limit: Option<usize>,
) -> Result<(f64, f64, f64, usize)> {
    let mut model = Model::load(path, step)?;
    let (data, _) = model.load_dataset(scene, loading)?;
    if data.test.is_empty() {
        return Err(Error::InvalidValue {
            path: scene.to_path_buf(),
            what: "the scene has no test views to score the ladder on".into(),
        });
    }
    let views = &data.test[..limit.unwrap_or(usize::MAX).min(data.test.len())];
    let (mut p, mut s, mut times) = (0.0, 0.0, Vec::new());
    for v in views {
        let t = Instant::now();
        let img = model.render(&v.camera)?;
        times.push(t.elapsed().as_secs_f64());
        p += psnr(&img, &v.rgb).min(99.0);
        s += ssim(&img, &v.rgb, v.width as usize, v.height as usize);
    }
    let n = views.len();
    times.sort_by(f64::total_cmp);
    Ok((p / n as f64, s / n as f64, times[n / 2], n))
}

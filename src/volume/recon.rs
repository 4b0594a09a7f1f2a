//! Reconstruction jobs: a posed-photo folder in, a fitted model out. These hold the set-up
//! that `diffsvg recon voxel` / `recon splat` and the Python package share: the scene's
//! box from the cameras, defaults by kind of dataset (objects on white or real photos),
//! the coarse-to-fine and densification schedules scaled to the run's length, and the
//! held-out evaluation. Training itself is [`voxel::train()`] and [`splat::train()`].
//!
//! Options are checked before any file is read; an option out of range is
//! [`Error::Setting`] naming the option as its field is named here (`bound`,
//! `max_gaussians`), so that a command line can name its flag instead.
//!
//! ```no_run
//! use diffsvg::volume::recon::{VoxelJob, recon_voxel};
//! let job = VoxelJob { res: 64, iters: 500, ..VoxelJob::default() };
//! let out = recon_voxel("scenes/lego".as_ref(), &job, &mut |step, test_psnr| {
//!     if let Some(p) = test_psnr {
//!         println!("iteration {}: test PSNR {p:.2} dB", step.iteration);
//!     }
//!     true // keep going
//! })?;
//! diffsvg::volume::voxel::save(&out.grid, "lego.vox")?;
//! # Ok::<(), diffsvg::Error>(())
//! ```

use std::path::Path;
use std::time::Instant;

use glam::Vec3;

use crate::error::{Error, Result};
use crate::limits::MAX_GAUSSIANS;
use crate::volume::Ray;
use crate::volume::dataset::{Dataset, Loading, View};
use crate::volume::field::{self, HashShape, Ngp, NgpShape};
use crate::volume::metrics::psnr;
use crate::volume::pose::{self, PoseDelta};
use crate::volume::splat::{self, Gaussians};
use crate::volume::voxel::{self, Grid, RenderSettings};

/// What [`recon_voxel`] fits: a sparse grid of density and spherical-harmonic color
/// (Plenoxels). The defaults are `diffsvg recon voxel`'s.
#[derive(Clone, Debug, PartialEq)]
pub struct VoxelJob {
    /// Final grid resolution, cells per axis (8 to [`voxel::MAX_RES`]); training starts
    /// coarser and doubles up to it ([`levels`]).
    pub res: u32,
    /// Optimizer iterations (mini-batches of rays), at least 1.
    pub iters: usize,
    /// Rays per iteration, at least 1 (at most the training pixels are used).
    pub batch: usize,
    /// Divide image sizes by this integer, at least 1.
    pub downscale: u32,
    /// Spherical-harmonic degree of the color, 0 to 3.
    pub degree: u32,
    /// Half the box's side, world units; `None`: the cameras' median distance from where
    /// they look times 0.4 for objects on white, 1 for real photos.
    pub bound: Option<f32>,
    /// Sample spacing along rays, in voxels.
    pub step: f32,
    /// Weight of the total-variation term on densities; `None`: 0 for objects on white,
    /// 1e-5 for real photos.
    pub tv_density: Option<f32>,
    /// Weight of the total-variation term on SH coefficients; `None`: 0 on white, 1e-6
    /// for real photos.
    pub tv_sh: Option<f32>,
    /// Weight of the sparsity term; `None`: 0 on white, 1e-2 for real photos.
    pub sparsity: Option<f32>,
    /// Random seed of the ray batches.
    pub seed: u64,
    /// Every this many iterations, evaluate the test views (not counted as training
    /// time); 0: only at the end.
    pub eval_every: usize,
    /// Which views are held out ([`Loading::test_every`]); `None`: the format's default.
    pub test_every: Option<usize>,
    /// Or the views named in this file ([`Loading::test_list`]).
    pub test_list: Option<std::path::PathBuf>,
    /// Learn a pose correction of each training view ([`crate::volume::pose`],
    /// [`voxel::TrainOptions::refine_poses`]); test views keep their poses.
    pub refine_poses: bool,
    /// For testing pose refinement: before training, move every training camera by a
    /// random turn of `[0]` degrees about its center and a move of `[1]` world units
    /// ([`pose::perturb`], seeded by `seed`); test views keep their poses.
    pub perturb_poses: Option<[f32; 2]>,
    /// After training, also score the test views with their cameras aligned to the
    /// model (test-time pose alignment, [`VoxelResult::test_psnr_aligned`]): the protocol
    /// of pose-refining reconstructions, whose frame the photos fix only up to a small
    /// motion. Apply it to the runs being compared alike.
    pub align_test_poses: bool,
}

impl Default for VoxelJob {
    fn default() -> Self {
        VoxelJob {
            res: 128,
            iters: 3000,
            batch: 8192,
            downscale: 1,
            degree: 2,
            bound: None,
            step: 0.5,
            tv_density: None,
            tv_sh: None,
            sparsity: None,
            seed: 0,
            eval_every: 0,
            test_every: None,
            test_list: None,
            refine_poses: false,
            perturb_poses: None,
            align_test_poses: false,
        }
    }
}

/// What [`recon_splat`] fits: 3D Gaussians (Kerbl et al. 2023). The defaults are
/// `diffsvg recon splat`'s.
#[derive(Clone, Debug, PartialEq)]
pub struct SplatJob {
    /// Optimizer iterations (one training view each), at least 1.
    pub iters: usize,
    /// Divide image sizes by this integer, at least 1.
    pub downscale: u32,
    /// Most Gaussians the model may hold, 1 to [`MAX_GAUSSIANS`].
    pub max_gaussians: usize,
    /// Gaussians to start from when the folder has no point cloud, placed at random in
    /// the scene's box; 1 to [`MAX_GAUSSIANS`].
    pub initial: usize,
    /// Highest spherical-harmonic degree of the color, 0 to 3 (raised from 0 over the
    /// run).
    pub degree: u32,
    /// Half the side of the box of the random initial points, world units; `None` as for
    /// [`VoxelJob::bound`].
    pub bound: Option<f32>,
    /// Random seed of the initial points, the view order and the splits.
    pub seed: u64,
    /// Every this many iterations, evaluate the test views; 0: only at the end.
    pub eval_every: usize,
    /// Which views are held out ([`Loading::test_every`]); `None`: the format's default.
    pub test_every: Option<usize>,
    /// Or the views named in this file ([`Loading::test_list`]).
    pub test_list: Option<std::path::PathBuf>,
    /// Train [anti-aliased](splat::Gaussians::antialiased) splats (saved with the model).
    pub antialias: bool,
    /// Learn a per-image affine color transform of each training view
    /// ([`splat::TrainOptions::exposure`]); test views are rendered without.
    pub exposure: bool,
    /// A fixed budget of [`max_gaussians`](Self::max_gaussians) by relocation
    /// (3DGS-MCMC, [`splat::Densify::mcmc`]) instead of cloning and splitting.
    pub mcmc: bool,
    /// Learn a pose correction of each training view ([`crate::volume::pose`],
    /// [`splat::TrainOptions::refine_poses`]); test views keep their poses.
    pub refine_poses: bool,
    /// As [`VoxelJob::perturb_poses`].
    pub perturb_poses: Option<[f32; 2]>,
}

impl Default for SplatJob {
    fn default() -> Self {
        SplatJob {
            iters: 5000,
            downscale: 1,
            max_gaussians: 300_000,
            initial: 50_000,
            degree: 3,
            bound: None,
            seed: 0,
            eval_every: 0,
            test_every: None,
            test_list: None,
            antialias: false,
            exposure: false,
            mcmc: false,
            refine_poses: false,
            perturb_poses: None,
        }
    }
}

/// What [`recon_ngp`] fits: an Instant-NGP neural field (hash encoding and tiny MLPs),
/// or with `frequencies` ≥ 1 a NeRF field (positional encoding and a deeper MLP; see
/// [`NgpJob::nerf`]). The defaults are `diffsvg recon ngp`'s.
#[derive(Clone, Debug, PartialEq)]
pub struct NgpJob {
    /// Optimizer iterations (mini-batches of rays), at least 1.
    pub iters: usize,
    /// Training time budget in seconds (0: none): training stops when it is spent and the
    /// learning rate decays over it instead of over `iters`.
    pub seconds: f32,
    /// Most rays per iteration, at least 1.
    pub batch: usize,
    /// Samples aimed at per iteration ([`field::TrainOptions::batch_samples`]; 0: always
    /// `batch` rays).
    pub samples: usize,
    /// Divide image sizes by this integer, at least 1.
    pub downscale: u32,
    /// Half the box's side, world units; `None` as for [`VoxelJob::bound`].
    pub bound: Option<f32>,
    /// Samples along the box's diagonal (16 to 8192).
    pub steps: u32,
    /// Hash levels (1 to 32).
    pub levels: u32,
    /// `log2` of the entries per level (4 to 24).
    pub log2_table: u32,
    /// Cells per axis of the coarsest level (at least 2).
    pub min_res: u32,
    /// Cells per axis of the finest level (`min_res` to 65536).
    pub max_res: u32,
    /// Neurons per hidden layer (8 to 256).
    pub width: u32,
    /// Octaves of NeRF's positional encoding: 0 for a hash field (Instant-NGP), 1 to 16
    /// for a NeRF field (then the hash options are ignored).
    pub frequencies: u32,
    /// Hidden layers of the density network (1 to 4).
    pub density_layers: u32,
    /// Hidden layers of the color network (1 to 4).
    pub color_layers: u32,
    /// Learning rate at the start and the end (exponential decay in between).
    pub lr: [f32; 2],
    /// Random seed of the parameters and the ray batches.
    pub seed: u64,
    /// Every this many iterations, evaluate the test views; 0: only at the end.
    pub eval_every: usize,
    /// Which views are held out ([`Loading::test_every`]); `None`: the format's default.
    pub test_every: Option<usize>,
    /// Or the views named in this file ([`Loading::test_list`]).
    pub test_list: Option<std::path::PathBuf>,
}

impl Default for NgpJob {
    fn default() -> Self {
        let s = NgpShape::default();
        let o = field::TrainOptions::default();
        NgpJob {
            iters: o.iterations,
            seconds: 0.0,
            batch: o.batch_size,
            samples: o.batch_samples,
            downscale: 1,
            bound: None,
            steps: o.render.steps,
            levels: s.hash.levels,
            log2_table: s.hash.log2_table,
            min_res: s.hash.n_min,
            max_res: s.hash.n_max,
            width: s.width,
            frequencies: 0,
            density_layers: s.density_layers,
            color_layers: s.color_layers,
            lr: o.lr,
            seed: 0,
            eval_every: 0,
            test_every: None,
            test_list: None,
        }
    }
}

impl NgpJob {
    /// `diffsvg recon nerf`'s defaults: the shape of [`NgpShape::nerf`], learning rate
    /// 2e-3 → 2e-4 (without a hash table, 1e-2 makes the deeper network diverge), 256
    /// samples along the diagonal and 2¹⁴ samples per iteration (the networks cost about
    /// twice Instant-NGP's per sample); the rest as [`NgpJob::default`].
    pub fn nerf() -> NgpJob {
        let s = NgpShape::nerf();
        NgpJob {
            width: s.width,
            frequencies: s.frequencies,
            density_layers: s.density_layers,
            color_layers: s.color_layers,
            lr: [2e-3, 2e-4],
            steps: 256,
            samples: 1 << 14,
            ..NgpJob::default()
        }
    }

    /// Which encoding the job's field uses.
    pub fn kind(&self) -> field::FieldKind {
        self.shape().kind()
    }

    /// How the job loads its dataset.
    pub fn loading(&self) -> Loading {
        Loading {
            downscale: self.downscale,
            test_every: self.test_every,
            test_list: self.test_list.clone(),
        }
    }

    /// The model's shape.
    pub fn shape(&self) -> NgpShape {
        let hash = if self.frequencies > 0 {
            HashShape::NONE
        } else {
            HashShape {
                levels: self.levels,
                log2_table: self.log2_table,
                n_min: self.min_res,
                n_max: self.max_res,
            }
        };
        NgpShape {
            hash,
            frequencies: self.frequencies,
            width: self.width,
            density_layers: self.density_layers,
            color_layers: self.color_layers,
            ..NgpShape::default()
        }
    }

    /// Checks every option that does not depend on the photos.
    pub fn validate(&self) -> Result<()> {
        at_least_one("downscale", self.downscale as u64)?;
        at_least_one("iters", self.iters as u64)?;
        crate::limits::check_count("iters", self.iters, 1..=crate::limits::MAX_ITERS)?;
        at_least_one("batch", self.batch as u64)?;
        crate::limits::check_count("batch", self.batch, 1..=crate::limits::MAX_NGP_BATCH)?;
        if !(self.seconds.is_finite() && self.seconds >= 0.0) {
            return Err(setting(
                "seconds",
                format!("{} must be a number ≥ 0", self.seconds),
            ));
        }
        if let Some(b) = self.bound {
            check_positive(b)?;
        }
        if !(16..=8192).contains(&self.steps) {
            return Err(setting(
                "steps",
                format!("{} must be 16 to 8192", self.steps),
            ));
        }
        if !self.lr.iter().all(|r| r.is_finite() && *r > 0.0) {
            return Err(setting(
                "lr",
                format!("{:?} must be positive numbers", self.lr),
            ));
        }
        let s = self.shape();
        if s.kind() == field::FieldKind::Ngp {
            s.hash.validate().map_err(|e| {
                let (name, prefix) = if e.starts_with("levels") {
                    ("levels", "levels ")
                } else if e.starts_with("log2") {
                    ("log2_table", "log2 table size ")
                } else {
                    ("max_res", "")
                };
                setting(name, e.trim_start_matches(prefix).into())
            })?;
        }
        s.validate().map_err(|e| {
            let name = e.split(' ').next().unwrap_or("width");
            let flag = match name {
                "density_layers" | "color_layers" | "frequencies" | "width" => name,
                _ => "width",
            };
            setting(flag, e.trim_start_matches(name).trim_start().into())
        })?;
        Ok(())
    }
}

/// A fitted neural field and how the run went.
#[derive(Clone, Debug)]
pub struct NgpResult {
    /// The model after training.
    pub model: Ngp,
    /// The dataset's warnings ([`Dataset::warnings`]), for the caller to show.
    pub warnings: Vec<String>,
    /// How training ended.
    pub outcome: field::TrainOutcome,
    /// One row per 50 iterations and per evaluation, as in [`VoxelResult::log`]; the last
    /// row is the end of the run with the final test PSNR.
    pub log: Vec<(field::TrainStep, Option<f64>)>,
    /// Mean PSNR of the test views at the end; `None` when the dataset has none.
    pub test_psnr: Option<f64>,
    /// Seconds spent loading the photos.
    pub load_seconds: f64,
    /// The settings the model was trained and is rendered with.
    pub render: field::RenderSettings,
}

/// Fits an Instant-NGP field to the photos in `scene` ([`Dataset::load`]): a box as for
/// [`recon_voxel`], the background of the dataset's kind, [`field::train()`] with the
/// job's options. `observe` is called as in [`recon_voxel`].
///
/// # Errors
/// As [`recon_voxel`].
pub fn recon_ngp(
    scene: &Path,
    job: &NgpJob,
    observe: &mut dyn FnMut(&field::TrainStep, Option<f64>) -> bool,
) -> Result<NgpResult> {
    fit_ngp(scene, job, true, observe)
}

/// [`recon_ngp`], scoring the test views at the end only when `final_test` (the
/// ladder renders them itself).
pub(crate) fn fit_ngp(
    scene: &Path,
    job: &NgpJob,
    final_test: bool,
    observe: &mut dyn FnMut(&field::TrainStep, Option<f64>) -> bool,
) -> Result<NgpResult> {
    job.validate()?;
    let t_load = Instant::now();
    let data = Dataset::load_with(scene, &job.loading())?;
    if data.train.is_empty() {
        return Err(no_training_views(scene));
    }
    let (rays, colors) = pixels(&data.train);
    let test_rays: Vec<Vec<Ray>> = data.test.iter().map(|v| v.camera.rays()).collect();
    let defaults = Defaults::for_dataset(&data);
    let (center, half) = scene_box(scene, &data, job.bound, defaults.box_factor)?;
    let load_seconds = t_load.elapsed().as_secs_f64();
    let render = field::RenderSettings {
        steps: job.steps,
        background: background(&data),
        ..field::RenderSettings::default()
    };
    let mut model = Ngp::new(
        center - Vec3::splat(half),
        center + Vec3::splat(half),
        job.shape(),
        job.seed,
    );
    let opts = field::TrainOptions {
        iterations: job.iters,
        seconds: job.seconds,
        batch_size: job.batch,
        batch_samples: job.samples,
        seed: job.seed,
        render,
        lr: job.lr,
        ..field::TrainOptions::default()
    };
    let mut log: Vec<(field::TrainStep, Option<f64>)> = Vec::new();
    let mut last: Option<field::TrainStep> = None;
    let outcome = field::train(&mut model, &rays, &colors, &opts, &mut |s, m| {
        last = Some(*s);
        let test = evaluate_now(job.eval_every, s.iteration, job.iters, &data)
            .then(|| ngp_psnr(m, &test_rays, &data.test, &render));
        if test.is_some() || s.iteration % 50 == 0 {
            log.push((*s, test));
        }
        observe(s, test)
    })?;
    let test_psnr = (final_test && !data.test.is_empty())
        .then(|| ngp_psnr(&model, &test_rays, &data.test, &render));
    if let Some(s) = last {
        log.retain(|r| r.0.iteration != s.iteration);
        log.push((s, test_psnr));
    }
    Ok(NgpResult {
        warnings: data.warnings.clone(),
        model,
        outcome,
        log,
        test_psnr,
        load_seconds,
        render,
    })
}

/// Mean PSNR (dB, capped at 99 per view) of a field rendered along each view's rays.
fn ngp_psnr(m: &Ngp, rays: &[Vec<Ray>], views: &[View], render: &field::RenderSettings) -> f64 {
    let sum: f64 = rays
        .iter()
        .zip(views)
        .map(|(r, v)| psnr(&field::render_rays(m, r, render), &v.rgb).min(99.0))
        .sum();
    sum / views.len().max(1) as f64
}

/// A fitted grid and how the run went.
#[derive(Clone, Debug)]
pub struct VoxelResult {
    /// The grid after training and the final prune.
    pub grid: Grid,
    /// The dataset's warnings ([`Dataset::warnings`]), for the caller to show.
    pub warnings: Vec<String>,
    /// How training ended.
    pub outcome: voxel::TrainOutcome,
    /// One row per 50 iterations and per evaluation: the step and, where evaluated, the
    /// test views' mean PSNR. The last row is the end of the run, with the size after
    /// the final prune and the final test PSNR.
    pub log: Vec<(voxel::TrainStep, Option<f64>)>,
    /// Mean PSNR (dB, capped at 99 per view) of the test views at the end; `None` when
    /// the dataset has none.
    pub test_psnr: Option<f64>,
    /// With [`VoxelJob::perturb_poses`], the same with the test cameras carried into the
    /// model's frame ([`PoseError::frame`]), so that the perturbation's common part, which
    /// no refinement can see, costs nothing. `None` otherwise.
    pub test_psnr_in_frame: Option<f64>,
    /// Seconds spent loading the photos.
    pub load_seconds: f64,
    /// Rays per iteration used: the job's, or the number of training pixels if fewer.
    pub batch: usize,
    /// With [`VoxelJob::refine_poses`], the learned correction of each training view
    /// ([`crate::volume::pose`]); else empty.
    pub poses: Vec<PoseDelta>,
    /// With [`VoxelJob::perturb_poses`], how far the training poses were from the
    /// loaded ones before and after training.
    pub pose_error: Option<PoseError>,
    /// With [`VoxelJob::align_test_poses`]: the test views' mean PSNR (dB, capped at 99
    /// per view) once each view's camera is aligned to the model held fixed
    /// ([`align_voxel_views`]), and the mean turn (degrees) that took.
    pub test_psnr_aligned: Option<(f64, f64)>,
}

/// The mean distance of the training poses from the loaded ones ([`pose::pose_error`]),
/// when they were perturbed: `[degrees, world units]` as perturbed and as corrected by
/// training (the same when poses were not refined).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseError {
    /// Mean rotation angle (degrees) and center distance (world units) before training.
    pub before: [f64; 2],
    /// The same after training, with the learned corrections applied.
    pub after: [f64; 2],
    /// The rigid motion of the whole scene that best carries the corrected cameras onto
    /// the loaded ones ([`pose::frame_motion`]): its angle (degrees) and how far it moves
    /// the cameras' mean center (world units). Photos cannot tell it (bundle adjustment's
    /// gauge freedom): it is the perturbation's common part that anchoring keeps.
    pub frame: [f64; 2],
    /// [`after`](Self::after) once that motion is removed: what the photos can tell.
    pub after_in_frame: [f64; 2],
}

/// Fitted Gaussians and how the run went.
#[derive(Clone, Debug)]
pub struct SplatResult {
    /// The model after training.
    pub model: Gaussians,
    /// The dataset's warnings ([`Dataset::warnings`]), for the caller to show.
    pub warnings: Vec<String>,
    /// How training ended.
    pub outcome: splat::TrainOutcome,
    /// One row per 50 iterations and per evaluation, as in [`VoxelResult::log`]; the
    /// end of the run is in `outcome` and `test_psnr`.
    pub log: Vec<(splat::TrainStep, Option<f64>)>,
    /// Mean PSNR of the test views at the end; `None` when the dataset has none.
    pub test_psnr: Option<f64>,
    /// As [`VoxelResult::test_psnr_in_frame`].
    pub test_psnr_in_frame: Option<f64>,
    /// Seconds spent loading (and undistorting) the photos.
    pub load_seconds: f64,
    /// When the photos had lens distortion: the fraction of undistorted pixels that fell
    /// outside the photos (and repeat its edge).
    pub undistorted: Option<f64>,
    /// As [`VoxelResult::poses`].
    pub poses: Vec<PoseDelta>,
    /// As [`VoxelResult::pose_error`].
    pub pose_error: Option<PoseError>,
}

/// Checks [`VoxelJob::perturb_poses`] (and `mesh fit --perturb-poses`): degrees in
/// `[0, 180]`, a finite distance ≥ 0.
pub fn check_perturbation(p: Option<[f32; 2]>) -> Result<()> {
    if let Some([deg, dist]) = p
        && !(deg.is_finite() && (0.0..=180.0).contains(&deg) && dist.is_finite() && dist >= 0.0)
    {
        return Err(setting(
            "perturb_poses",
            format!("{deg},{dist}: need degrees in [0, 180] and a finite distance ≥ 0"),
        ));
    }
    Ok(())
}

/// Perturbs the training views as `perturb` asks (seeded by `seed`), returning the loaded
/// cameras to measure against.
fn perturb_training(
    data: &mut Dataset,
    perturb: Option<[f32; 2]>,
    seed: u64,
) -> Option<Vec<crate::volume::camera::Camera>> {
    let [deg, dist] = perturb?;
    let loaded = data.train.iter().map(|v| v.camera).collect();
    pose::perturb(&mut data.train, deg, dist, seed);
    Some(loaded)
}

/// [`PoseError`] of the training views (perturbed) against `loaded`, before and after
/// the learned corrections `poses` (empty: none).
fn pose_error_of(
    loaded: &[crate::volume::camera::Camera],
    views: &[View],
    poses: &[PoseDelta],
    points: &[Vec3],
) -> (PoseError, pose::RigidMotion) {
    let given: Vec<_> = views.iter().map(|v| v.camera).collect();
    pose_report(loaded, &given, poses, points)
}

/// [`PoseError`] of cameras `given` (perturbed) against `loaded` (where they belong),
/// before and after the corrections `poses` (`pose::apply`; a missing one counts as
/// zero): the mean rotation angle (degrees) and center distance (world units); the
/// frame and the error in it ([`PoseError::frame`]) judged at `points`, where the scene
/// is ([`pose::frame_motion`]).
pub fn mean_pose_error(
    loaded: &[crate::volume::camera::Camera],
    given: &[crate::volume::camera::Camera],
    poses: &[PoseDelta],
    points: &[Vec3],
) -> PoseError {
    pose_report(loaded, given, poses, points).0
}

/// [`mean_pose_error`] and the frame motion itself.
fn pose_report(
    loaded: &[crate::volume::camera::Camera],
    given: &[crate::volume::camera::Camera],
    poses: &[PoseDelta],
    points: &[Vec3],
) -> (PoseError, pose::RigidMotion) {
    use crate::volume::camera::Camera;
    let mean = |f: &dyn Fn(usize) -> Camera| {
        let mut sum = [0.0f64; 2];
        for (i, l) in loaded.iter().enumerate() {
            let (a, d) = pose::pose_error(l, &f(i));
            sum[0] += a;
            sum[1] += d;
        }
        sum.map(|v| v / loaded.len().max(1) as f64)
    };
    let corrected: Vec<Camera> = (0..loaded.len().min(given.len()))
        .map(|i| match poses.get(i) {
            Some(d) => pose::apply(&given[i], d),
            None => given[i],
        })
        .collect();
    let frame = pose::frame_motion(loaded, &corrected, points);
    let center =
        corrected.iter().map(Camera::position).sum::<Vec3>() / corrected.len().max(1) as f32;
    let (angle, moved) = frame.size(center);
    let error = PoseError {
        before: mean(&|i| given[i]),
        after: mean(&|i| corrected[i]),
        frame: [angle, moved],
        after_in_frame: mean(&|i| frame.move_camera(&corrected[i])),
    };
    (error, frame)
}

/// The `views` with their cameras carried into the frame of a model trained on
/// perturbed and corrected cameras, whose motion against the truth is `frame`
/// ([`pose::frame_motion`]; carried by its inverse): the held-out views as that model
/// places them.
fn views_in_frame(views: &[View], frame: &pose::RigidMotion) -> Vec<View> {
    let into = frame.inverse();
    views
        .iter()
        .map(|v| View {
            camera: into.move_camera(&v.camera),
            ..v.clone()
        })
        .collect()
}

/// An option error naming `name` (a field of the job).
fn setting(name: &str, message: String) -> Error {
    Error::Setting {
        name: name.into(),
        message,
    }
}

fn at_least_one(name: &str, v: u64) -> Result<()> {
    if v == 0 {
        return Err(setting(name, "0 must be at least 1".into()));
    }
    Ok(())
}

fn check_degree(degree: u32) -> Result<()> {
    if degree > 3 {
        return Err(setting("degree", format!("{degree} must be 0 to 3")));
    }
    Ok(())
}

impl VoxelJob {
    /// How the job loads its dataset.
    pub fn loading(&self) -> Loading {
        Loading {
            downscale: self.downscale,
            test_every: self.test_every,
            test_list: self.test_list.clone(),
        }
    }

    /// Checks every option that does not depend on the photos.
    pub fn validate(&self) -> Result<()> {
        if !(8..=voxel::MAX_RES).contains(&self.res) {
            return Err(setting(
                "res",
                format!("{} must be between 8 and {}", self.res, voxel::MAX_RES),
            ));
        }
        check_degree(self.degree)?;
        at_least_one("downscale", self.downscale as u64)?;
        at_least_one("iters", self.iters as u64)?;
        crate::limits::check_count("iters", self.iters, 1..=crate::limits::MAX_ITERS)?;
        at_least_one("batch", self.batch as u64)?;
        if let Some(b) = self.bound {
            check_positive(b)?;
        }
        for (name, w) in [
            ("tv_density", self.tv_density),
            ("tv_sh", self.tv_sh),
            ("sparsity", self.sparsity),
        ] {
            if let Some(w) = w
                && !(w.is_finite() && w >= 0.0)
            {
                return Err(setting(name, format!("{w} must be a finite number ≥ 0")));
            }
        }
        self.render()?;
        check_perturbation(self.perturb_poses)?;
        Ok(())
    }

    fn render(&self) -> Result<RenderSettings> {
        // The renderer's message starts with the option's name.
        RenderSettings::with_step(self.step)
            .map_err(|e| setting("step", e.trim_start_matches("step ").into()))
    }
}

impl SplatJob {
    /// How the job loads its dataset.
    pub fn loading(&self) -> Loading {
        Loading {
            downscale: self.downscale,
            test_every: self.test_every,
            test_list: self.test_list.clone(),
        }
    }

    /// Checks every option that does not depend on the photos.
    pub fn validate(&self) -> Result<()> {
        if self.max_gaussians == 0 || self.max_gaussians > MAX_GAUSSIANS {
            return Err(setting(
                "max_gaussians",
                format!(
                    "{} must be between 1 and {MAX_GAUSSIANS}",
                    self.max_gaussians
                ),
            ));
        }
        check_degree(self.degree)?;
        at_least_one("downscale", self.downscale as u64)?;
        at_least_one("iters", self.iters as u64)?;
        crate::limits::check_count("iters", self.iters, 1..=crate::limits::MAX_ITERS)?;
        at_least_one("initial", self.initial as u64)?;
        if self.initial > MAX_GAUSSIANS {
            return Err(setting(
                "initial",
                format!("{} is above {MAX_GAUSSIANS}", self.initial),
            ));
        }
        if let Some(b) = self.bound {
            check_positive(b)?;
        }
        check_perturbation(self.perturb_poses)?;
        Ok(())
    }
}

fn check_positive(b: f32) -> Result<()> {
    if !(b.is_finite() && b > 0.0) {
        return Err(setting("bound", format!("{b} must be a positive number")));
    }
    Ok(())
}

/// Fits a sparse voxel grid to the photos in the dataset folder `scene` (see
/// [`Dataset::load`]). Coarse to fine: a dense grid at the first of [`levels`], doubled
/// after 10 % of the run and every further 30 %; slots no training ray weighs are freed
/// at every resampling, every tenth of the run and at the end.
///
/// `observe` runs after every iteration with its step and, every `eval_every`
/// iterations, the test views' mean PSNR; it returns false to stop (the grid so far is
/// returned, with `outcome.stopped`).
///
/// # Errors
/// An option out of range ([`Error::Setting`]), an unreadable dataset, no training
/// views, a box the cameras cannot size.
pub fn recon_voxel(
    scene: &Path,
    job: &VoxelJob,
    observe: &mut dyn FnMut(&voxel::TrainStep, Option<f64>) -> bool,
) -> Result<VoxelResult> {
    fit_voxel(scene, job, true, observe)
}

/// [`recon_voxel`], scoring the test views at the end only when `final_test` (the
/// ladder renders them itself).
pub(crate) fn fit_voxel(
    scene: &Path,
    job: &VoxelJob,
    final_test: bool,
    observe: &mut dyn FnMut(&voxel::TrainStep, Option<f64>) -> bool,
) -> Result<VoxelResult> {
    job.validate()?;
    let render = job.render()?;
    let t_load = Instant::now();
    let mut data = Dataset::load_with(scene, &job.loading())?;
    if data.train.is_empty() {
        return Err(no_training_views(scene));
    }
    let loaded = perturb_training(&mut data, job.perturb_poses, job.seed);
    let (rays, colors) = pixels(&data.train);
    let view_of_ray = if job.refine_poses {
        view_of_each_pixel(&data.train)
    } else {
        Vec::new()
    };
    // The test views' rays, made once for every evaluation.
    let test_rays: Vec<Vec<Ray>> = data.test.iter().map(|v| v.camera.rays()).collect();
    let defaults = Defaults::for_dataset(&data);
    let (center, half) = scene_box(scene, &data, job.bound, defaults.box_factor)?;
    // Where the scene is, to judge a model's frame by (`pose::frame_motion`).
    let points = pose::lattice(center - Vec3::splat(half), center + Vec3::splat(half), 5);
    let load_seconds = t_load.elapsed().as_secs_f64();

    let levels = levels(job.res);
    let upsample: Vec<(usize, u32)> = levels[1..]
        .iter()
        .enumerate()
        .map(|(i, &r)| (((0.1 + 0.3 * i as f64) * job.iters as f64) as usize, r))
        .map(|(it, r)| (it.max(1), r))
        .collect();
    let mut grid = Grid::dense(
        center - Vec3::splat(half),
        center + Vec3::splat(half),
        levels[0],
        job.degree,
        0.1,
    );
    // Rays are drawn with replacement; more per batch than there are pixels only repeats.
    let batch = job.batch.min(rays.len());
    let opts = voxel::TrainOptions {
        iterations: job.iters,
        batch_size: batch,
        seed: job.seed,
        render,
        upsample,
        prune_every: (job.iters / 10).max(1),
        tv_density: job.tv_density.unwrap_or(defaults.tv_density),
        tv_sh: job.tv_sh.unwrap_or(defaults.tv_sh),
        sparsity: job.sparsity.unwrap_or(defaults.sparsity),
        refine_poses: job.refine_poses,
        ..voxel::TrainOptions::default()
    };
    let mut log: Vec<(voxel::TrainStep, Option<f64>)> = Vec::new();
    let mut last: Option<voxel::TrainStep> = None;
    let observe = &mut |s: &voxel::TrainStep, g: &Grid| {
        last = Some(*s);
        let test = evaluate_now(job.eval_every, s.iteration, job.iters, &data)
            .then(|| voxel_psnr(g, &test_rays, &data.test, &render));
        if test.is_some() || s.iteration.is_multiple_of(50) {
            log.push((*s, test));
        }
        observe(s, test)
    };
    let (outcome, poses) =
        voxel::train_with_poses(&mut grid, &rays, &colors, &view_of_ray, &opts, observe)?;
    let test_psnr = (final_test && !data.test.is_empty())
        .then(|| voxel_psnr(&grid, &test_rays, &data.test, &render));
    let test_psnr_aligned = if job.align_test_poses && final_test && !data.test.is_empty() {
        let (moved, turn) = align_voxel_views(&grid, &data.test, &render, job.seed)?;
        let rays: Vec<Vec<Ray>> = moved.iter().map(|v| v.camera.rays()).collect();
        Some((voxel_psnr(&grid, &rays, &moved, &render), turn))
    } else {
        None
    };
    let report = loaded.map(|l| pose_error_of(&l, &data.train, &poses, &points));
    let test_psnr_in_frame = match &report {
        Some((_, frame)) if final_test && !data.test.is_empty() => {
            let moved = views_in_frame(&data.test, frame);
            let rays: Vec<Vec<Ray>> = moved.iter().map(|v| v.camera.rays()).collect();
            Some(voxel_psnr(&grid, &rays, &moved, &render))
        }
        _ => None,
    };
    let pose_error = report.map(|r| r.0);
    if let Some(s) = last {
        // The last row carries the final test PSNR (and the size after the final prune).
        log.retain(|r| r.0.iteration != s.iteration);
        let s = voxel::TrainStep {
            allocated: grid.allocated(),
            ..s
        };
        log.push((s, test_psnr));
    }
    Ok(VoxelResult {
        warnings: data.warnings.clone(),
        grid,
        outcome,
        log,
        test_psnr,
        test_psnr_in_frame,
        load_seconds,
        batch,
        poses,
        pose_error,
        test_psnr_aligned,
    })
}

/// Test-time pose alignment: each of `views` gets its camera aligned to `grid`, held
/// fixed, by the pose refinement alone ([`voxel::train_with_poses`] with the grid's
/// rates at zero), from its loaded pose: 600 steps of 8,192 of the views' rays, each
/// correction in pivoted coordinates from the start (`pose::Refiner`), rate 2e-3 → 2e-5
/// rad, no anchor (the fixed grid sets the frame). This is how pose-refining
/// reconstructions are scored (BARF, Lin et al. 2021): their frame is fixed by the
/// photos only up to a small motion, and per view. Returns the views with their aligned
/// cameras and the mean turn (degrees) from the loaded ones.
///
/// # Errors
/// Training's, on views without pixels.
pub fn align_voxel_views(
    grid: &Grid,
    views: &[View],
    render: &RenderSettings,
    seed: u64,
) -> Result<(Vec<View>, f64)> {
    let (rays, colors) = pixels(views);
    let view_of_ray = view_of_each_pixel(views);
    let opts = voxel::TrainOptions {
        iterations: 600,
        batch_size: 8192.min(rays.len()),
        seed,
        render: *render,
        lr_poses: [2e-3, 2e-5],
        anchor_poses: false,
        ..voxel::TrainOptions::default()
    }
    .poses_only();
    let mut held = grid.clone();
    let (_, poses) = voxel::train_with_poses(
        &mut held,
        &rays,
        &colors,
        &view_of_ray,
        &opts,
        &mut |_, _| true,
    )?;
    let mut turn = 0.0;
    let moved: Vec<View> = views
        .iter()
        .zip(&poses)
        .map(|(v, d)| {
            let camera = pose::apply(&v.camera, d);
            turn += pose::pose_error(&v.camera, &camera).0 / views.len() as f64;
            View {
                camera,
                ..v.clone()
            }
        })
        .collect();
    Ok((moved, turn))
}

/// Fits 3D Gaussians to the photos in `scene` (photos with lens distortion are first
/// undistorted, see [`load_for_splat`]). The model starts from the folder's point cloud
/// ([`splat::find_point_cloud`]), else the dataset's sparse points ([`Dataset::points`],
/// COLMAP's `points3D`), else `initial` random Gaussians in the scene's box;
/// the reference schedule (30 000 iterations: densify from 500 to 15 000 every 100,
/// opacity reset every 3000, SH degree up every 1000) is scaled to `iters`.
///
/// `observe` is called as in [`recon_voxel`].
///
/// # Errors
/// As [`recon_voxel`], and an unreadable point cloud or a model that training empties.
pub fn recon_splat(
    scene: &Path,
    job: &SplatJob,
    observe: &mut dyn FnMut(&splat::TrainStep, Option<f64>) -> bool,
) -> Result<SplatResult> {
    fit_splat(scene, job, true, observe)
}

/// [`recon_splat`], scoring the test views at the end only when `final_test` (the
/// ladder renders them itself).
pub(crate) fn fit_splat(
    scene: &Path,
    job: &SplatJob,
    final_test: bool,
    observe: &mut dyn FnMut(&splat::TrainStep, Option<f64>) -> bool,
) -> Result<SplatResult> {
    job.validate()?;
    let t_load = Instant::now();
    let (mut data, undistorted) = load_for_splat(scene, &job.loading())?;
    let loaded = perturb_training(&mut data, job.perturb_poses, job.seed);
    let settings = splat::RenderSettings {
        background: background(&data),
        ..splat::RenderSettings::default()
    };
    let box_factor = Defaults::for_dataset(&data).box_factor;
    let (center, half) = scene_box(scene, &data, job.bound, box_factor)?;
    // Where the scene is, to judge a model's frame by (`pose::frame_motion`).
    let points = pose::lattice(center - Vec3::splat(half), center + Vec3::splat(half), 5);
    let mut model = match (splat::find_point_cloud(scene), &data.points) {
        (Some(path), _) => splat::from_point_cloud(&path, job.degree)?,
        (None, Some(points)) => splat::from_points(points, job.degree),
        (None, None) => splat::random_init(
            center,
            half,
            job.initial.min(job.max_gaussians),
            job.degree,
            job.seed,
        ),
    };
    model.antialiased = job.antialias;
    if job.mcmc {
        splat::mcmc_start(&mut model);
    }
    let iters = job.iters;
    let scaled = |x: usize| ((x as f64 * iters as f64 / 30_000.0).round() as usize).max(1);
    let opts = splat::TrainOptions {
        iterations: iters,
        seed: job.seed,
        render: settings,
        sh_degree: job.degree,
        sh_interval: scaled(1000).max(iters / 8),
        extent: camera_extent(&data.train),
        densify: splat::Densify {
            from: scaled(500),
            // 3DGS-MCMC relocates until 25 000 of 30 000 iterations.
            until: if job.mcmc { scaled(25_000) } else { iters / 2 },
            every: scaled(100).clamp(25, 100),
            reset_every: scaled(3000).max(200),
            max_gaussians: job.max_gaussians,
            mcmc: job.mcmc.then(splat::Mcmc::default),
            ..splat::Densify::default()
        },
        exposure: job.exposure,
        refine_poses: job.refine_poses,
        ..splat::TrainOptions::default()
    };
    let load_seconds = t_load.elapsed().as_secs_f64();
    let mut log: Vec<(splat::TrainStep, Option<f64>)> = Vec::new();
    let mut failed: Option<Error> = None;
    let outcome = splat::train(&mut model, &data.train, &opts, &mut |s, g| {
        let test = if evaluate_now(job.eval_every, s.iteration, iters, &data) {
            match splat_psnr(g, &data.test, &settings) {
                Ok(p) => Some(p),
                Err(e) => {
                    failed = Some(e);
                    return false;
                }
            }
        } else {
            None
        };
        if test.is_some() || s.iteration % 50 == 0 {
            log.push((*s, test));
        }
        observe(s, test)
    })?;
    if let Some(e) = failed {
        return Err(e);
    }
    let test_psnr = if data.test.is_empty() || !final_test {
        None
    } else {
        Some(splat_psnr(&model, &data.test, &settings)?)
    };
    log.retain(|r| r.0.iteration != outcome.iterations);
    let report = loaded.map(|l| pose_error_of(&l, &data.train, &outcome.poses, &points));
    let test_psnr_in_frame = match &report {
        Some((_, frame)) if final_test && !data.test.is_empty() => Some(splat_psnr(
            &model,
            &views_in_frame(&data.test, frame),
            &settings,
        )?),
        _ => None,
    };
    let pose_error = report.map(|r| r.0);
    Ok(SplatResult {
        test_psnr_in_frame,
        poses: outcome.poses.clone(),
        pose_error,
        warnings: data.warnings.clone(),
        model,
        outcome,
        log,
        test_psnr,
        load_seconds,
        undistorted,
    })
}

/// Whether iteration `it` of `iters` evaluates the test views.
fn evaluate_now(every: usize, it: usize, iters: usize, data: &Dataset) -> bool {
    every > 0 && it.is_multiple_of(every) && it < iters && !data.test.is_empty()
}

fn no_training_views(scene: &Path) -> Error {
    Error::InvalidValue {
        path: scene.to_path_buf(),
        what: "no training views".into(),
    }
}

/// Loads a dataset for splatting: photos with lens distortion are undistorted to pinhole
/// views (a rasterizer projects through a pinhole). Returns the dataset and, when it was
/// undistorted, the fraction of pixels that fell outside the photos.
///
/// # Errors
/// As [`Dataset::load_with`], and a dataset without training views.
pub fn load_for_splat(dir: &Path, loading: &Loading) -> Result<(Dataset, Option<f64>)> {
    let data = Dataset::load_with(dir, loading)?;
    if data.train.is_empty() {
        return Err(no_training_views(dir));
    }
    let distorted = data
        .train
        .iter()
        .chain(&data.test)
        .any(|v| v.camera.has_distortion());
    if !distorted {
        return Ok((data, None));
    }
    let (data, outside) = crate::volume::undistort::undistort_dataset(&data);
    let total: usize = data
        .train
        .iter()
        .chain(&data.test)
        .map(|v| v.rgb.len())
        .sum();
    Ok((data, Some(outside as f64 / total.max(1) as f64)))
}

/// The color a ray that leaves the scene sees: white for objects composited over white
/// (NeRF-synthetic), black for real photos.
pub fn background(data: &Dataset) -> [f32; 3] {
    if data.white_background {
        [1.0; 3]
    } else {
        [0.0; 3]
    }
}

/// What the jobs use where the options say nothing, by kind of dataset.
struct Defaults {
    /// Half the box's side over the cameras' median distance.
    box_factor: f32,
    tv_density: f32,
    tv_sh: f32,
    sparsity: f32,
}

impl Defaults {
    fn for_dataset(data: &Dataset) -> Defaults {
        if data.white_background {
            // An object on white: a box around the object, no regularization.
            Defaults {
                box_factor: 0.4,
                tv_density: 0.0,
                tv_sh: 0.0,
                sparsity: 0.0,
            }
        } else {
            // Real photos show the room around the object, which the box must reach
            // (fox: only 62% of a view's rays meet a 0.4 box; the rest can only be
            // white). 43 fox views from one side let the grid explain each photo with
            // floaters in front of its camera (held-out 13 dB at 64³); these terms gave
            // 19.5 dB.
            Defaults {
                box_factor: 1.0,
                tv_density: 1e-5,
                tv_sh: 1e-6,
                sparsity: 1e-2,
            }
        }
    }
}

/// The scene's box, `center ± half`: around where the cameras look, with `bound` as the
/// half side or, without one, `box_factor` times the cameras' median distance.
fn scene_box(
    scene: &Path,
    data: &Dataset,
    bound: Option<f32>,
    box_factor: f32,
) -> Result<(Vec3, f32)> {
    let (center, dist) = data.focus();
    if let Some(b) = bound {
        // Positive and finite already (`validate`). A box far too large or small for the cameras (or for f32) would start from
        // cells or Gaussians of infinite or zero size.
        check_bound(b, center, dist).map_err(|e| setting("bound", e))?;
        return Ok((center, b));
    }
    let half = box_factor * dist;
    let sized = if !(half.is_finite() && half > 0.0 && center.is_finite()) {
        Err(format!("median distance {dist} from {center}"))
    } else {
        check_box(center, half)
    };
    sized.map_err(|e| Error::InvalidValue {
        path: scene.to_path_buf(),
        what: format!("cannot size the box from the cameras ({e}); give a bound"),
    })?;
    Ok((center, half))
}

/// Smallest and largest bound as a multiple of the cameras' median distance from where
/// they look: a box a thousandth of that distance is smaller than a pixel of any view,
/// one a thousand times larger puts the scene in a single cell.
const BOUND_RANGE: (f32, f32) = (1e-3, 1e3);

/// Checks a bound `b` against the cameras: within [`BOUND_RANGE`] times their distance
/// `dist` (when that is known) and a box that `f32` can hold around `center`. The message
/// follows the value (`"1e30 must be between …"`).
fn check_bound(b: f32, center: Vec3, dist: f32) -> std::result::Result<(), String> {
    if dist.is_finite() && dist > 0.0 {
        let (lo, hi) = (BOUND_RANGE.0 * dist, BOUND_RANGE.1 * dist);
        if !(lo..=hi).contains(&b) {
            return Err(format!(
                "{b:?} must be between {lo} and {hi} ({:e} to {:e} times the cameras' median \
                 distance {dist} from where they look)",
                BOUND_RANGE.0, BOUND_RANGE.1
            ));
        }
    }
    check_box(center, b).map_err(|e| format!("{b:?}: {e}"))
}

/// Errors unless `center ± half` is a finite box whose sides `f32` can tell apart from a
/// point (64 distinct values per axis at least).
fn check_box(center: Vec3, half: f32) -> std::result::Result<(), String> {
    let (min, max) = (center - Vec3::splat(half), center + Vec3::splat(half));
    if !(min.is_finite() && max.is_finite()) {
        return Err(format!("the box around {center} is not finite"));
    }
    let ulp = center.abs().max_element().max(f32::MIN_POSITIVE) * f32::EPSILON;
    if 2.0 * half < 64.0 * ulp {
        return Err(format!(
            "a box of half side {half} around {center} is too small for f32"
        ));
    }
    Ok(())
}

/// The resolutions of the coarse-to-fine schedule: from 64 (or `res / 2` when that is
/// at least 32 and `res` less than 128, or `res` itself for small grids) doubling to
/// `res`. (64³ → 128³ reached 30 dB on lego at 200².)
pub fn levels(res: u32) -> Vec<u32> {
    let mut r = if res >= 128 {
        64
    } else if res / 2 >= 32 {
        res / 2
    } else {
        res
    };
    let mut v = vec![r];
    while r < res {
        r = (2 * r).min(res);
        v.push(r);
    }
    v
}

/// Every pixel of every view as a ray and its color.
fn pixels(views: &[View]) -> (Vec<Ray>, Vec<[f32; 3]>) {
    let mut rays = Vec::new();
    let mut colors = Vec::new();
    for v in views {
        rays.extend(v.camera.rays());
        colors.extend_from_slice(&v.rgb);
    }
    (rays, colors)
}

/// The index in `views` of each pixel of [`pixels`]`(views)`: what pose refinement
/// reads to know whose camera a ray came from.
fn view_of_each_pixel(views: &[View]) -> Vec<u32> {
    views
        .iter()
        .enumerate()
        .flat_map(|(i, v)| std::iter::repeat_n(i as u32, v.rgb.len()))
        .collect()
}

/// Mean PSNR (dB, capped at 99 per view) of `views`, each rendered along its rays
/// `rays[i]`.
fn voxel_psnr(grid: &Grid, rays: &[Vec<Ray>], views: &[View], render: &RenderSettings) -> f64 {
    let sum: f64 = rays
        .iter()
        .zip(views)
        .map(|(r, v)| psnr(&voxel::render_rays(grid, r, render), &v.rgb).min(99.0))
        .sum();
    sum / views.len().max(1) as f64
}

/// Mean PSNR (dB, capped at 99 per view) of `model` rendered from `views`.
fn splat_psnr(model: &Gaussians, views: &[View], settings: &splat::RenderSettings) -> Result<f64> {
    let mut sum = 0.0;
    for v in views {
        let out = splat::render(model, &v.camera, settings).map_err(|e| Error::InvalidValue {
            path: v.name.clone().into(),
            what: format!("rendering the view: {e}"),
        })?;
        sum += psnr(&out.rgb, &v.rgb).min(99.0);
    }
    Ok(sum / views.len().max(1) as f64)
}

/// The reference code's scene extent: 1.1 times the largest distance of a training
/// camera from the cameras' mean position (1 when that is 0).
fn camera_extent(views: &[View]) -> f32 {
    let n = views.len().max(1) as f32;
    let mean = views
        .iter()
        .map(|v| v.camera.position())
        .fold(Vec3::ZERO, |a, b| a + b)
        / n;
    let r = views
        .iter()
        .map(|v| v.camera.position().distance(mean))
        .fold(0.0f32, f32::max);
    if r > 0.0 && r.is_finite() {
        1.1 * r
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn held_out_views_are_carried_into_the_model_s_frame() {
        use crate::volume::camera::Camera;
        use crate::volume::pose::RigidMotion;
        let cam = |i: usize| {
            let a = i as f32 * 0.7;
            let eye = Vec3::new(4.0 * a.cos(), 4.0 * a.sin(), 1.0);
            Camera::look_at(eye, Vec3::ZERO, Vec3::Z, 0.8, 8, 6).unwrap()
        };
        let view = |camera: Camera| View {
            name: String::new(),
            camera,
            width: 8,
            height: 6,
            rgb: vec![[0.0; 3]; 48],
        };
        // Training cameras that moved with the whole scene by `g` (and learned nothing):
        // a model trained on them sees the scene moved by `g`, so a held-out view is
        // where `g` takes it.
        let g = RigidMotion {
            rotation: pose::rotation(Vec3::new(0.01, 0.0, -0.02)),
            translation: Vec3::new(0.05, 0.02, 0.0),
        };
        let loaded: Vec<Camera> = (0..8).map(cam).collect();
        let train: Vec<View> = loaded.iter().map(|c| view(g.move_camera(c))).collect();
        let test = [view(cam(20))];
        let points = pose::lattice(Vec3::splat(-1.0), Vec3::ONE, 3);
        let frame = pose_error_of(&loaded, &train, &[], &points).1;
        let moved = views_in_frame(&test, &frame);
        let (angle, dist) = pose::pose_error(&g.move_camera(&test[0].camera), &moved[0].camera);
        assert!(angle < 1e-3 && dist < 1e-5, "{angle} {dist}");
        // Corrections that bring the training cameras home leave nothing to carry.
        let back: Vec<PoseDelta> = train
            .iter()
            .zip(&loaded)
            .map(|(v, l)| {
                let r = glam::Mat3::from(l.c2w.matrix3)
                    * glam::Mat3::from(v.camera.c2w.matrix3).transpose();
                let w = glam::Quat::from_mat3(&r).to_scaled_axis();
                let m = l.position() - v.camera.position();
                [w.x, w.y, w.z, m.x, m.y, m.z]
            })
            .collect();
        let frame = pose_error_of(&loaded, &train, &back, &points).1;
        let moved = views_in_frame(&test, &frame);
        let (angle, dist) = pose::pose_error(&test[0].camera, &moved[0].camera);
        assert!(angle < 1e-3 && dist < 1e-5, "{angle} {dist}");
    }

    #[test]
    fn test_views_aligned_to_a_fixed_grid_come_back() {
        use crate::volume::camera::Camera;
        let grid = voxel::train::eight_balls();
        let render = RenderSettings::default();
        let truth: Vec<Camera> = (0..4)
            .map(|i| {
                let a = i as f32 * 1.3 + 0.2;
                let eye = Vec3::new(2.6 * a.cos(), 0.5 - 0.3 * i as f32, 2.6 * a.sin());
                Camera::look_at(eye, Vec3::ZERO, Vec3::Y, 1.1, 32, 28).unwrap()
            })
            .collect();
        let mut loaded = truth.clone();
        pose::perturb_cameras(&mut loaded, 0.5, 0.02, 3);
        let views: Vec<View> = truth
            .iter()
            .zip(&loaded)
            .map(|(t, l)| View {
                name: String::new(),
                camera: *l,
                width: 32,
                height: 28,
                rgb: voxel::render_rays(&grid, &t.rays(), &render),
            })
            .collect();
        let score = |vs: &[View]| {
            let rays: Vec<Vec<Ray>> = vs.iter().map(|v| v.camera.rays()).collect();
            voxel_psnr(&grid, &rays, vs, &render)
        };
        let error = |vs: &[View]| {
            vs.iter()
                .zip(&truth)
                .map(|(v, t)| pose::pose_error(t, &v.camera).0)
                .sum::<f64>()
                / vs.len() as f64
        };
        let (aligned, turn) = align_voxel_views(&grid, &views, &render, 0).unwrap();
        let (before, after) = (error(&views), error(&aligned));
        assert!((before - 0.5).abs() < 1e-3, "{before}");
        assert!(after < 0.005, "the cameras end {after}° off");
        assert!((turn - 0.5).abs() < 0.1, "turned {turn}°");
        let (p0, p1) = (score(&views), score(&aligned));
        assert!(p1 > p0 + 20.0, "{p0} dB → {p1} dB");
        // The photos and names are the views' own; the grid was held fixed.
        assert!(aligned.iter().zip(&views).all(|(a, v)| a.rgb == v.rgb));
    }

    #[test]
    fn coarse_to_fine_levels_start_at_64_and_double() {
        assert_eq!(levels(256), [64, 128, 256]);
        assert_eq!(levels(128), [64, 128]);
        assert_eq!(levels(200), [64, 128, 200]);
        assert_eq!(levels(64), [32, 64]);
        assert_eq!(levels(40), [40]);
    }

    #[test]
    fn options_out_of_range_are_named() {
        let bad_voxel = [
            (
                VoxelJob {
                    res: 4,
                    ..VoxelJob::default()
                },
                "res",
                "4 must be between 8",
            ),
            (
                VoxelJob {
                    degree: 4,
                    ..VoxelJob::default()
                },
                "degree",
                "4 must be 0 to 3",
            ),
            (
                VoxelJob {
                    iters: 0,
                    ..VoxelJob::default()
                },
                "iters",
                "at least 1",
            ),
            (
                VoxelJob {
                    batch: 0,
                    ..VoxelJob::default()
                },
                "batch",
                "at least 1",
            ),
            (
                VoxelJob {
                    downscale: 0,
                    ..VoxelJob::default()
                },
                "downscale",
                "at least 1",
            ),
            (
                VoxelJob {
                    bound: Some(-1.0),
                    ..VoxelJob::default()
                },
                "bound",
                "-1 must be a positive",
            ),
            (
                VoxelJob {
                    step: f32::NAN,
                    ..VoxelJob::default()
                },
                "step",
                "NaN",
            ),
            (
                VoxelJob {
                    sparsity: Some(-1.0),
                    ..VoxelJob::default()
                },
                "sparsity",
                "≥ 0",
            ),
        ];
        for (job, name, needle) in bad_voxel {
            match job.validate() {
                Err(Error::Setting { name: n, message }) => {
                    assert_eq!(n, name);
                    assert!(message.contains(needle), "{message:?} lacks {needle:?}");
                }
                other => panic!("{name}: {other:?}"),
            }
        }
        assert!(VoxelJob::default().validate().is_ok());
        let bad_splat = [
            (
                SplatJob {
                    max_gaussians: 0,
                    ..SplatJob::default()
                },
                "max_gaussians",
            ),
            (
                SplatJob {
                    max_gaussians: MAX_GAUSSIANS + 1,
                    ..SplatJob::default()
                },
                "max_gaussians",
            ),
            (
                SplatJob {
                    initial: 0,
                    ..SplatJob::default()
                },
                "initial",
            ),
            (
                SplatJob {
                    initial: MAX_GAUSSIANS + 1,
                    ..SplatJob::default()
                },
                "initial",
            ),
            (
                SplatJob {
                    degree: 9,
                    ..SplatJob::default()
                },
                "degree",
            ),
            (
                SplatJob {
                    bound: Some(f32::INFINITY),
                    ..SplatJob::default()
                },
                "bound",
            ),
        ];
        for (job, name) in bad_splat {
            assert!(
                matches!(job.validate(), Err(Error::Setting { name: ref n, .. }) if n == name),
                "{name}"
            );
        }
        assert!(SplatJob::default().validate().is_ok());
    }

    #[test]
    fn bounds_far_from_the_cameras_scale_are_refused() {
        let c = Vec3::new(1.0, 2.0, 3.0);
        assert!(check_bound(1.5, c, 4.0).is_ok());
        let e = check_bound(1e30, c, 4.0).unwrap_err();
        assert!(e.starts_with("1e30 must be between"), "{e}");
        assert!(check_bound(1e-30, c, 4.0).is_err());
        // Unknown distance: only f32 limits the box.
        assert!(check_bound(1.0, c, f32::NAN).is_ok());
        assert!(check_box(Vec3::splat(1e6), 1e-6).is_err());
        assert!(check_box(Vec3::splat(3e38), 1e38).is_err());
    }
}

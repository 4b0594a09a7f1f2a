//! Fitting Gaussians to posed photos (Kerbl et al. 2023): one whole view per iteration,
//! loss `(1 − λ)·L1 + λ·(1 − SSIM)`, Adam per parameter group through [`crate::optim`],
//! SH degree raised over time, and adaptive density control.
//!
//! One iteration: take the next view of a seeded shuffle of the training views, render it
//! ([`render`]), take the loss and its gradient with respect to the image, run
//! [`backward_into`], accumulate each visible Gaussian's view-space gradient norm, and
//! step every parameter group with its own rate (the means' rate decays exponentially).
//! Every [`Densify::every`] iterations inside `[from, until)`:
//!
//! * **clone** Gaussians whose mean view-space gradient reached the threshold and whose
//!   largest scale is at most [`Densify::percent_dense`] of the scene extent (a copy at
//!   the same place, with fresh optimizer moments);
//! * **split** the larger ones into two drawn from their own distribution, scales divided
//!   by 1.6;
//! * **prune** those whose opacity fell below [`Densify::min_opacity`], and (after the
//!   first opacity reset) those larger than [`Densify::max_screen_radius`] pixels on
//!   screen or a tenth of the extent in the world;
//! * keep the count within [`Densify::max_gaussians`] (the candidates with the largest
//!   gradients win);
//!
//! and every [`Densify::reset_every`] iterations, opacities are lowered to at most 0.01 so
//! that pruning can find what no view needs. Results are deterministic for a fixed seed,
//! on any number of threads (the renderer, the backward pass and the loss are).

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{Mat3, Vec3};
use rayon::prelude::*;

use super::Gaussians;
use super::backward::{Gradients, backward_into};
use super::loss::photometric_loss;
use super::render::{RenderSettings, render};
use crate::error::{Error, Result};
use crate::limits::MAX_GAUSSIANS;
use crate::optim::{Moments, Rule, exponential, progress};
use crate::rng::Rng;
use crate::volume::dataset::View;
use crate::volume::sh;

/// Adaptive density control (see the module documentation). Iteration counts are of
/// [`TrainOptions::iterations`].
#[derive(Clone, Debug, PartialEq)]
pub struct Densify {
    /// First iteration that densifies.
    pub from: usize,
    /// Densification stops before this iteration (pruning of transparent Gaussians too).
    pub until: usize,
    /// Densify every this many iterations.
    pub every: usize,
    /// Threshold of the mean view-space gradient norm, in normalized device units
    /// (`∂L/∂pixel · size/2`, the reference code's 0.0002).
    pub grad_threshold: f32,
    /// Gaussians whose largest scale is at most this fraction of the extent are cloned;
    /// larger ones are split.
    pub percent_dense: f32,
    /// Lower every opacity to at most 0.01 every this many iterations (0: never).
    pub reset_every: usize,
    /// Prune Gaussians whose opacity is below this.
    pub min_opacity: f32,
    /// After the first opacity reset, prune Gaussians whose screen radius exceeded this
    /// many pixels since the last densification.
    pub max_screen_radius: f32,
    /// Most Gaussians the model may hold (at least 1).
    pub max_gaussians: usize,
}

impl Default for Densify {
    fn default() -> Self {
        Densify {
            from: 500,
            until: 15_000,
            every: 100,
            grad_threshold: 0.0002,
            percent_dense: 0.01,
            reset_every: 3000,
            min_opacity: 0.005,
            max_screen_radius: 20.0,
            max_gaussians: 1_000_000,
        }
    }
}

/// Everything [`train`] needs besides the Gaussians and the views.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainOptions {
    /// Number of iterations (one view each).
    pub iterations: usize,
    /// Seed of the view order and of the splits.
    pub seed: u64,
    /// How views are rendered (the background should be the one the photos were
    /// composited over).
    pub render: RenderSettings,
    /// Highest SH degree used (at most the model's); the active degree starts at 0.
    pub sh_degree: u32,
    /// Raise the active SH degree by one every this many iterations.
    pub sh_interval: usize,
    /// Weight `λ` of the SSIM term in `(1 − λ)·L1 + λ·(1 − SSIM)`.
    pub ssim_weight: f32,
    /// Scene extent, world units (the radius of the camera centers around their mean,
    /// times 1.1, as in the reference code): it scales the position learning rate and the
    /// clone/split and world-size pruning thresholds.
    pub extent: f32,
    /// Learning rate of the means, in units of the extent, at the first and the last
    /// iteration (exponential decay between).
    pub lr_means: [f32; 2],
    /// Learning rate of the log-scales.
    pub lr_log_scales: f32,
    /// Learning rate of the quaternions.
    pub lr_rotations: f32,
    /// Learning rate of the logit opacities.
    pub lr_opacities: f32,
    /// Learning rate of the constant SH term.
    pub lr_sh_dc: f32,
    /// Learning rate of the higher SH terms.
    pub lr_sh_rest: f32,
    /// Adaptive density control.
    pub densify: Densify,
}

impl Default for TrainOptions {
    /// The reference code's settings for 30 000 iterations.
    fn default() -> Self {
        TrainOptions {
            iterations: 30_000,
            seed: 0,
            render: RenderSettings::default(),
            sh_degree: 3,
            sh_interval: 1000,
            ssim_weight: 0.2,
            extent: 1.0,
            lr_means: [1.6e-4, 1.6e-6],
            lr_log_scales: 5e-3,
            lr_rotations: 1e-3,
            lr_opacities: 5e-2,
            lr_sh_dc: 2.5e-3,
            lr_sh_rest: 2.5e-3 / 20.0,
            densify: Densify::default(),
        }
    }
}

/// Progress after one iteration, passed to the observer of [`train`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainStep {
    /// Iterations done so far (1 after the first).
    pub iteration: usize,
    /// Training loss of this iteration's view, before the update.
    pub loss: f32,
    /// PSNR of this iteration's view, dB, before the update.
    pub psnr: f32,
    /// Gaussians in the model after this iteration.
    pub gaussians: usize,
    /// Active SH degree.
    pub sh_degree: u32,
    /// Seconds of training so far (the time spent in the observer is not counted).
    pub elapsed: f32,
}

/// How [`train`] ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainOutcome {
    /// Iterations done.
    pub iterations: usize,
    /// Whether the observer stopped training early.
    pub stopped: bool,
    /// Training loss of the last iteration.
    pub loss: f32,
    /// Wall time of training, seconds (without the observer's).
    pub seconds: f32,
    /// Seconds spent per part of a step, summed over the run: render, loss, backward,
    /// optimizer update, density control.
    pub parts: [f32; 5],
}

/// `count` Gaussians at uniformly random places in the cube `center ± half`, with random
/// colors, no rotation, and isotropic scales `s` equal to the expected mean distance to
/// the three nearest neighbours of such a cloud, as the reference code initializes
/// synthetic scenes. SH of degree `sh_degree` (higher terms 0).
///
/// The opacity is not the reference's 0.1, which makes a dense cloud an opaque haze (a
/// ray through 50 000 of them in lego's box meets about 60, and keeps 0.2% of its light),
/// whose gradients stay weak until the first opacity reset. It is chosen so that a ray
/// through the box keeps about half its light: each Gaussian takes `o·2πs²` of the
/// light of rays crossing it, so `o = ln 2 · (2·half)² / (count · 2πs²)`, clamped to
/// `[0.01, 0.1]`.
///
/// # Panics
/// If `sh_degree > 3`.
pub fn random_init(center: Vec3, half: f32, count: usize, sh_degree: u32, seed: u64) -> Gaussians {
    let mut rng = Rng::new(seed);
    let mut g = Gaussians::new(sh_degree);
    let k = g.coeffs_per_channel();
    // Poisson points of density ρ: E[d_k] = Γ(k + 1/3)/Γ(k)·(3/(4πρ))^(1/3); the mean of
    // k = 1, 2, 3 is 1.158 times the radius (3/(4πρ))^(1/3).
    let volume = (2.0 * half).powi(3);
    let radius = (3.0 * volume / (4.0 * std::f32::consts::PI * count.max(1) as f32)).cbrt();
    let scale = 1.158 * radius;
    let log_scale = scale.ln();
    let side = 2.0 * half;
    let opacity = (std::f32::consts::LN_2 * side * side
        / (count.max(1) as f32 * 2.0 * std::f32::consts::PI * scale * scale))
        .clamp(0.01, 0.1);
    let mut coeffs = vec![0.0f32; 3 * k];
    for _ in 0..count {
        let offset = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - 1.0;
        let mean = (center + offset * half).to_array();
        for c in 0..3 {
            coeffs[c * k] = (rng.uniform() - 0.5) / SH_C0;
        }
        g.push(
            mean,
            [log_scale; 3],
            [1.0, 0.0, 0.0, 0.0],
            logit(opacity),
            &coeffs,
        );
    }
    g
}

/// The point cloud file of a dataset folder, if it has one: the first of `points3d.ply`,
/// `sparse_pc.ply` and `points.ply`.
pub fn find_point_cloud(dir: &Path) -> Option<PathBuf> {
    super::points::find_point_cloud(dir)
}

/// Gaussians at the points of a PLY point cloud (vertices with `x y z`, and `red green
/// blue` if present, else grey), as the reference code initializes from structure from
/// motion: opacity 0.1, no rotation, isotropic scales equal to the mean distance to the
/// three nearest other points. SH of degree `sh_degree` (higher terms 0).
///
/// # Errors
/// The file's problem, named with the file (`points::load_points`), or a cloud
/// with no points.
///
/// # Panics
/// If `sh_degree > 3`.
pub fn from_point_cloud(path: &Path, sh_degree: u32) -> Result<Gaussians> {
    let cloud = super::points::load_points(path).map_err(|what| Error::InvalidValue {
        path: path.to_path_buf(),
        what,
    })?;
    if cloud.positions.is_empty() {
        return Err(Error::InvalidValue {
            path: path.to_path_buf(),
            what: "the point cloud has no points".into(),
        });
    }
    Ok(from_points(&cloud, sh_degree))
}

/// Gaussians at the points of `cloud`, as [`from_point_cloud`] makes them (an empty
/// cloud gives no Gaussians).
///
/// # Panics
/// If `sh_degree > 3`, or `cloud.colors` has fewer entries than `cloud.positions`.
pub fn from_points(cloud: &super::PointCloud, sh_degree: u32) -> Gaussians {
    if cloud.positions.is_empty() {
        return Gaussians::new(sh_degree);
    }
    let scales = nearest_distances(&cloud.positions);
    let mut g = Gaussians::new(sh_degree);
    let k = g.coeffs_per_channel();
    let mut coeffs = vec![0.0f32; 3 * k];
    for (i, p) in cloud.positions.iter().enumerate() {
        let color = cloud.colors.as_ref().map_or([0.5; 3], |c| c[i]);
        for c in 0..3 {
            coeffs[c * k] = (color[c] - 0.5) / SH_C0;
        }
        g.push(
            *p,
            [scales[i].ln(); 3],
            [1.0, 0.0, 0.0, 0.0],
            logit(0.1),
            &coeffs,
        );
    }
    g
}

/// Per point, the mean distance to its three nearest other points (found in a uniform
/// grid of about two points per cell, searching the 27 cells around each point; points
/// with fewer neighbours there use the grid's typical spacing). Never below 1e-7.
fn nearest_distances(points: &[[f32; 3]]) -> Vec<f32> {
    let n = points.len();
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for p in points {
        lo = lo.min(Vec3::from_array(*p));
        hi = hi.max(Vec3::from_array(*p));
    }
    let size = (hi - lo).max(Vec3::splat(1e-6));
    let cell = (size.x * size.y * size.z * 2.0 / n as f32)
        .cbrt()
        .max(size.max_element() / 1024.0);
    let dims = (size / cell).ceil().max(Vec3::ONE).as_uvec3();
    let key = |p: Vec3| {
        let c = ((p - lo) / cell).as_uvec3().min(dims - 1);
        (c.x as usize, c.y as usize, c.z as usize)
    };
    let flat = |(x, y, z): (usize, usize, usize)| (z * dims.y as usize + y) * dims.x as usize + x;
    // Points sorted by cell: cell c holds order[start[c]..start[c + 1]].
    let cells = dims.x as usize * dims.y as usize * dims.z as usize;
    let mut start = vec![0usize; cells + 1];
    for p in points {
        start[flat(key(Vec3::from_array(*p))) + 1] += 1;
    }
    for c in 0..cells {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut order = vec![0u32; n];
    for (i, p) in points.iter().enumerate() {
        let c = flat(key(Vec3::from_array(*p)));
        order[fill[c]] = i as u32;
        fill[c] += 1;
    }
    let fallback = 1.158 * cell / 2f32.cbrt();
    (0..n)
        .into_par_iter()
        .map(|i| {
            let p = Vec3::from_array(points[i]);
            let (cx, cy, cz) = key(p);
            let mut best = [f32::INFINITY; 3];
            for z in cz.saturating_sub(1)..=(cz + 1).min(dims.z as usize - 1) {
                for y in cy.saturating_sub(1)..=(cy + 1).min(dims.y as usize - 1) {
                    for x in cx.saturating_sub(1)..=(cx + 1).min(dims.x as usize - 1) {
                        let c = flat((x, y, z));
                        for &j in &order[start[c]..start[c + 1]] {
                            if j as usize == i {
                                continue;
                            }
                            let d = p.distance_squared(Vec3::from_array(points[j as usize]));
                            if d < best[2] {
                                best[2] = d;
                                best.sort_by(|a, b| a.total_cmp(b));
                            }
                        }
                    }
                }
            }
            if best[2].is_finite() {
                ((best[0].sqrt() + best[1].sqrt() + best[2].sqrt()) / 3.0).max(1e-7)
            } else {
                fallback.max(1e-7)
            }
        })
        .collect()
}

/// The constant SH basis function: a DC coefficient `c` gives color `c·SH_C0 + 0.5`.
const SH_C0: f32 = 0.282_094_8;

fn logit(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

/// Fits `gaussians` to the training `views` (photos composited over
/// `opts.render.background`). `observe` runs after every iteration with its progress and
/// the updated model (to log, evaluate or checkpoint) and returns false to stop.
///
/// # Errors
/// No views, views whose sizes differ from their cameras', an invalid model or options,
/// a model whose SH degree is below `opts.sh_degree`, and a model that pruning empties
/// (every Gaussian transparent: the message says at which iteration).
pub fn train(
    gaussians: &mut Gaussians,
    views: &[View],
    opts: &TrainOptions,
    observe: &mut dyn FnMut(&TrainStep, &Gaussians) -> bool,
) -> Result<TrainOutcome> {
    let invalid = |what: String| Error::InvalidValue {
        path: "splat training".into(),
        what,
    };
    validate(gaussians, views, opts).map_err(invalid)?;
    let mut state = State::new(gaussians);
    let mut rng = Rng::new(opts.seed);
    let mut order: Vec<usize> = Vec::new();
    let mut grads = Gradients::default();
    let mut d_img: Vec<[f32; 3]> = Vec::new();
    let start = Instant::now();
    let mut observing = std::time::Duration::ZERO;
    let mut outcome = TrainOutcome {
        iterations: 0,
        stopped: false,
        loss: f32::NAN,
        seconds: 0.0,
        parts: [0.0; 5],
    };
    let d = &opts.densify;
    let mut active_degree = 0u32;
    for it in 0..opts.iterations {
        if opts.sh_interval > 0 && it > 0 && it % opts.sh_interval == 0 {
            active_degree = (active_degree + 1).min(opts.sh_degree);
        }
        if order.is_empty() {
            order = (0..views.len()).collect();
            for i in (1..order.len()).rev() {
                order.swap(i, rng.below(i + 1));
            }
        }
        let view = &views[order.pop().expect("refilled above")];
        let mut clock = Instant::now();
        let mut lap = |part: usize, outcome: &mut TrainOutcome| {
            outcome.parts[part] += clock.elapsed().as_secs_f32();
            clock = Instant::now();
        };
        let out = render(gaussians, &view.camera, &opts.render).map_err(invalid)?;
        lap(0, &mut outcome);
        d_img.resize(out.rgb.len(), [0.0; 3]);
        let (w, h) = (view.width as usize, view.height as usize);
        let loss = photometric_loss(&out.rgb, &view.rgb, w, h, opts.ssim_weight, &mut d_img);
        let mse = crate::volume::metrics::mse(&out.rgb, &view.rgb);
        lap(1, &mut outcome);
        backward_into(
            gaussians,
            &view.camera,
            &opts.render,
            &out,
            &d_img,
            &mut grads,
        )
        .map_err(invalid)?;
        // View-space gradient statistics for densification.
        let half = glam::Vec2::new(0.5 * w as f32, 0.5 * h as f32);
        for p in &out.projected {
            let i = p.index as usize;
            let [gx, gy] = grads.mean2d[i];
            state.grad_sum[i] += (glam::Vec2::new(gx, gy) * half).length();
            state.seen[i] += 1;
            state.max_radius[i] = state.max_radius[i].max(p.radius);
        }
        lap(2, &mut outcome);
        let frac: f32 = progress(it, opts.iterations);
        state.step(gaussians, &grads, opts, frac, active_degree);
        lap(3, &mut outcome);
        let iter = it + 1;
        if iter >= d.from && iter < d.until && iter % d.every == 0 {
            let after_reset = d.reset_every > 0 && iter > d.reset_every;
            densify(gaussians, &mut state, opts, after_reset, &mut rng);
            if gaussians.is_empty() {
                return Err(invalid(format!(
                    "every Gaussian was pruned at iteration {iter} (all transparent, too \
                     large or outside the views): nothing is left to fit"
                )));
            }
        }
        lap(4, &mut outcome);
        let step = TrainStep {
            iteration: iter,
            loss: loss.value as f32,
            psnr: crate::metrics::psnr_from_mse(mse) as f32,
            gaussians: gaussians.len(),
            sh_degree: active_degree,
            elapsed: (start.elapsed() - observing).as_secs_f32(),
        };
        outcome.iterations = iter;
        outcome.loss = step.loss;
        let t_obs = Instant::now();
        let go_on = observe(&step, gaussians);
        observing += t_obs.elapsed();
        if !go_on {
            outcome.stopped = true;
            break;
        }
        // The opacity reset comes after the observer has seen this iteration's model, so
        // that an evaluation (or a stop) never meets the model just after a reset.
        if d.reset_every > 0 && iter % d.reset_every == 0 && iter < d.until {
            let t_reset = Instant::now();
            let cap = logit(0.01);
            for l in &mut gaussians.logit_opacities {
                *l = l.min(cap);
            }
            state.opacities.clear();
            outcome.parts[4] += t_reset.elapsed().as_secs_f32();
        }
    }
    outcome.seconds = (start.elapsed() - observing).as_secs_f32();
    Ok(outcome)
}

fn validate(
    gaussians: &Gaussians,
    views: &[View],
    opts: &TrainOptions,
) -> std::result::Result<(), String> {
    gaussians.validate()?;
    if gaussians.is_empty() {
        return Err("no Gaussians to train".into());
    }
    if views.is_empty() {
        return Err("no training views".into());
    }
    for v in views {
        if v.rgb.len() != v.width as usize * v.height as usize
            || (v.width, v.height) != (v.camera.width, v.camera.height)
        {
            return Err(format!("view {}: image and camera sizes differ", v.name));
        }
    }
    if opts.sh_degree > gaussians.sh_degree {
        return Err(format!(
            "SH degree {} asked of a model of degree {}",
            opts.sh_degree, gaussians.sh_degree
        ));
    }
    let d = &opts.densify;
    if d.max_gaussians == 0 || d.max_gaussians > MAX_GAUSSIANS {
        return Err(format!(
            "max_gaussians {} is not in 1 ..= {MAX_GAUSSIANS}",
            d.max_gaussians
        ));
    }
    if d.every == 0 {
        return Err("densify every 0 iterations".into());
    }
    let rates = [
        opts.lr_means[0],
        opts.lr_means[1],
        opts.lr_log_scales,
        opts.lr_rotations,
        opts.lr_opacities,
        opts.lr_sh_dc,
        opts.lr_sh_rest,
    ];
    let rates_ok = rates.iter().all(|r| r.is_finite() && *r >= 0.0);
    if !(rates_ok && opts.extent > 0.0 && opts.extent.is_finite()) {
        return Err("learning rates must be finite and ≥ 0, the extent > 0".into());
    }
    if !(0.0..=1.0).contains(&opts.ssim_weight) {
        return Err(format!("SSIM weight {} is not in [0, 1]", opts.ssim_weight));
    }
    Ok(())
}

/// Optimizer moments per parameter group and the densification statistics.
struct State {
    means: Moments<f32>,
    log_scales: Moments<f32>,
    rotations: Moments<f32>,
    opacities: Moments<f32>,
    sh: Moments<f32>,
    /// Per Gaussian since the last densification: sum of view-space gradient norms,
    /// views in which it was drawn, largest screen radius.
    grad_sum: Vec<f32>,
    seen: Vec<u32>,
    max_radius: Vec<f32>,
}

/// Adam with the reference code's constants (ε = 1e-15).
const ADAM: Rule<f32> = Rule::Adam {
    beta1: 0.9,
    beta2: 0.999,
    eps: 1e-15,
};

impl State {
    fn new(g: &Gaussians) -> State {
        let n = g.len();
        State {
            means: Moments::new(ADAM, 3 * n),
            log_scales: Moments::new(ADAM, 3 * n),
            rotations: Moments::new(ADAM, 4 * n),
            opacities: Moments::new(ADAM, n),
            sh: Moments::new(ADAM, g.sh.len()),
            grad_sum: vec![0.0; n],
            seen: vec![0; n],
            max_radius: vec![0.0; n],
        }
    }

    /// One Adam step of every group.
    fn step(
        &mut self,
        g: &mut Gaussians,
        grads: &Gradients,
        opts: &TrainOptions,
        frac: f32,
        degree: u32,
    ) {
        let k = g.coeffs_per_channel();
        let lr_mean = exponential(opts.lr_means, frac) * opts.extent;
        adam(
            &mut self.means,
            g.means.as_flattened_mut(),
            grads.means.as_flattened(),
            |_| lr_mean,
        );
        let lr = opts.lr_log_scales;
        adam(
            &mut self.log_scales,
            g.log_scales.as_flattened_mut(),
            grads.log_scales.as_flattened(),
            |_| lr,
        );
        let lr = opts.lr_rotations;
        adam(
            &mut self.rotations,
            g.rotations.as_flattened_mut(),
            grads.rotations.as_flattened(),
            |_| lr,
        );
        let lr = opts.lr_opacities;
        adam(
            &mut self.opacities,
            &mut g.logit_opacities,
            &grads.logit_opacities,
            |_| lr,
        );
        let active = sh::coeff_count(degree);
        let (dc, rest) = (opts.lr_sh_dc, opts.lr_sh_rest);
        adam(&mut self.sh, &mut g.sh, &grads.sh, |j| match j % k {
            0 => dc,
            c if c < active => rest,
            _ => 0.0,
        });
        // Keep the quaternions away from zero (they are normalized on use).
        for q in &mut g.rotations {
            if q.iter().all(|v| v.abs() < 1e-12) {
                *q = [1.0, 0.0, 0.0, 0.0];
            }
        }
    }

    /// Keeps the flagged Gaussians' state, in order, then appends fresh state for `added`.
    fn compact(&mut self, keep: &[bool], added: usize, k3: usize) {
        for (m, stride) in [
            (&mut self.means, 3),
            (&mut self.log_scales, 3),
            (&mut self.rotations, 4),
            (&mut self.opacities, 1),
            (&mut self.sh, k3),
        ] {
            m.retain(keep, stride);
            m.extend(added * stride);
        }
        let n = keep.iter().filter(|&&k| k).count() + added;
        self.grad_sum = vec![0.0; n];
        self.seen = vec![0; n];
        self.max_radius = vec![0.0; n];
    }
}

/// One dense Adam step over `params` in parallel blocks; slot `j` moves at rate `lr(j)`
/// (0: frozen), non-finite gradients are skipped.
fn adam(m: &mut Moments<f32>, params: &mut [f32], grads: &[f32], lr: impl Fn(usize) -> f32 + Sync) {
    const BLOCK: usize = 1 << 14;
    let blocks: Vec<_> = m.lazy_step().blocks(BLOCK).collect();
    blocks
        .into_par_iter()
        .zip(params.par_chunks_mut(BLOCK))
        .zip(grads.par_chunks(BLOCK))
        .enumerate()
        .for_each(|(b, ((mut step, p), g))| {
            for i in 0..p.len() {
                let rate = lr(b * BLOCK + i);
                if rate > 0.0 && g[i].is_finite() {
                    step.apply(i, &mut p[i], g[i], rate);
                }
            }
        });
}

/// Clone, split and prune (see the module documentation).
fn densify(
    g: &mut Gaussians,
    state: &mut State,
    opts: &TrainOptions,
    after_reset: bool,
    rng: &mut Rng,
) {
    let d = &opts.densify;
    let n = g.len();
    let k3 = 3 * g.coeffs_per_channel();
    let big = d.percent_dense * opts.extent;
    // Candidates by mean view-space gradient, largest first (ties by index).
    let mut cand: Vec<(f32, usize)> = (0..n)
        .filter_map(|i| {
            let mean = if state.seen[i] > 0 {
                state.grad_sum[i] / state.seen[i] as f32
            } else {
                0.0
            };
            (mean >= d.grad_threshold && mean.is_finite()).then_some((mean, i))
        })
        .collect();
    cand.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    // Pruning first decides what stays.
    let mut keep: Vec<bool> = (0..n)
        .map(|i| {
            let transparent = g.opacity(i) < d.min_opacity;
            let huge = after_reset
                && (state.max_radius[i] > d.max_screen_radius
                    || g.scale(i).max_element() > 0.1 * opts.extent);
            !(transparent || huge)
        })
        .collect();
    let mut count = keep.iter().filter(|&&k| k).count();
    let mut clones = Vec::new();
    let mut splits = Vec::new();
    for &(_, i) in &cand {
        if !keep[i] {
            continue;
        }
        if g.scale(i).max_element() <= big {
            if count + 1 > d.max_gaussians {
                continue;
            }
            clones.push(i);
            count += 1;
        } else {
            if count + 1 > d.max_gaussians {
                continue;
            }
            splits.push(i);
            keep[i] = false;
            count += 1; // two children replace one
        }
    }
    // The new Gaussians: clones, then two children per split.
    let mut added = Gaussians::new(g.sh_degree);
    for &i in &clones {
        added.push(
            g.means[i],
            g.log_scales[i],
            g.rotations[i],
            g.logit_opacities[i],
            &g.sh[i * k3..(i + 1) * k3],
        );
    }
    for &i in &splits {
        let scale = g.scale(i);
        let rot = Mat3::from_quat(g.rotation(i));
        let mean = Vec3::from_array(g.means[i]);
        let ls = g.log_scales[i].map(|v| v - 1.6f32.ln());
        for _ in 0..2 {
            let offset = rot * (scale * Vec3::new(rng.normal(), rng.normal(), rng.normal()));
            added.push(
                (mean + offset).to_array(),
                ls,
                g.rotations[i],
                g.logit_opacities[i],
                &g.sh[i * k3..(i + 1) * k3],
            );
        }
    }
    let n_added = added.len();
    retain(g, &keep);
    g.means.extend_from_slice(&added.means);
    g.log_scales.extend_from_slice(&added.log_scales);
    g.rotations.extend_from_slice(&added.rotations);
    g.logit_opacities.extend_from_slice(&added.logit_opacities);
    g.sh.extend_from_slice(&added.sh);
    state.compact(&keep, n_added, k3);
}

/// Keeps the flagged Gaussians, in order.
fn retain(g: &mut Gaussians, keep: &[bool]) {
    let k3 = 3 * g.coeffs_per_channel();
    let mut out = 0;
    for i in 0..keep.len() {
        if keep[i] {
            g.means[out] = g.means[i];
            g.log_scales[out] = g.log_scales[i];
            g.rotations[out] = g.rotations[i];
            g.logit_opacities[out] = g.logit_opacities[i];
            g.sh.copy_within(i * k3..(i + 1) * k3, out * k3);
            out += 1;
        }
    }
    g.means.truncate(out);
    g.log_scales.truncate(out);
    g.rotations.truncate(out);
    g.logit_opacities.truncate(out);
    g.sh.truncate(out * k3);
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Affine3A;

    #[test]
    fn nearest_distances_of_a_lattice() {
        // A 6×6×6 lattice of spacing 0.5: interior points have 6 neighbours at 0.5.
        let mut pts = Vec::new();
        for z in 0..6 {
            for y in 0..6 {
                for x in 0..6 {
                    pts.push([x as f32 * 0.5, y as f32 * 0.5, z as f32 * 0.5]);
                }
            }
        }
        let d = nearest_distances(&pts);
        assert!(d.iter().all(|&v| (v - 0.5).abs() < 1e-5), "{:?}", &d[..8]);
        // Two points: no third neighbour in reach, the fallback is finite and positive.
        let d = nearest_distances(&[[0.0; 3], [1.0, 0.0, 0.0]]);
        assert!(d.iter().all(|v| v.is_finite() && *v > 0.0));
    }

    #[test]
    fn random_init_fills_the_box() {
        let g = random_init(Vec3::new(1.0, 2.0, 3.0), 0.5, 1000, 2, 9);
        assert_eq!(g.len(), 1000);
        assert_eq!(g.validate(), Ok(()));
        for m in &g.means {
            assert!((0.5..=1.5).contains(&m[0]) && (1.5..=2.5).contains(&m[1]));
            assert!((2.5..=3.5).contains(&m[2]));
        }
        // 1000 in a unit box: s = 1.158·(3/(4π·1000))^(1/3) = 0.0718, so the opacity that
        // leaves half the light of a ray through the box is ln 2/(1000·2π·s²) = 0.0214.
        assert!((g.opacity(0) - 0.0214).abs() < 2e-4, "{}", g.opacity(0));
        // A sparse cloud keeps the reference's 0.1; a very dense one stops at 0.01.
        let sparse = random_init(Vec3::ZERO, 0.5, 5, 0, 1);
        assert!((sparse.opacity(0) - 0.1).abs() < 1e-6);
        let dense = random_init(Vec3::ZERO, 0.5, 200_000, 0, 1);
        assert!((dense.opacity(0) - 0.01).abs() < 1e-6);
        assert_eq!(g, random_init(Vec3::new(1.0, 2.0, 3.0), 0.5, 1000, 2, 9));
    }

    /// A few views of a small colored cloud: training lowers the loss, densifies within
    /// the budget and is deterministic.
    #[test]
    fn training_fits_a_small_scene_within_budget() {
        // Target: renders of a hand-made model from 6 cameras around it.
        let mut truth = Gaussians::new(0);
        let colors = [[0.9, 0.1, 0.1], [0.1, 0.8, 0.2], [0.2, 0.3, 0.9]];
        for (k, c) in colors.iter().enumerate() {
            let dc = c.map(|v| (v - 0.5) / SH_C0);
            let x = k as f32 * 0.4 - 0.4;
            truth.push(
                [x, 0.0, 0.0],
                [-1.6, -2.0, -1.8],
                [1.0, 0.2, 0.0, 0.1],
                3.0,
                &dc,
            );
        }
        let settings = RenderSettings {
            background: [1.0; 3],
            ..Default::default()
        };
        let views: Vec<View> = (0..6)
            .map(|i| {
                let a = i as f32 * std::f32::consts::TAU / 6.0;
                let eye = Vec3::new(3.0 * a.cos(), 0.5, 3.0 * a.sin());
                let cam =
                    crate::volume::camera::Camera::look_at(eye, Vec3::ZERO, Vec3::Y, 0.7, 48, 40)
                        .unwrap();
                let rgb = render(&truth, &cam, &settings).unwrap().rgb;
                View {
                    name: format!("v{i}"),
                    camera: cam,
                    width: 48,
                    height: 40,
                    rgb,
                }
            })
            .collect();
        let _ = Affine3A::IDENTITY;
        let opts = TrainOptions {
            iterations: 300,
            render: settings,
            sh_degree: 1,
            sh_interval: 100,
            extent: 3.3,
            densify: Densify {
                from: 50,
                until: 250,
                every: 25,
                reset_every: 0,
                max_gaussians: 120,
                ..Densify::default()
            },
            ..TrainOptions::default()
        };
        let run = || {
            let mut g = random_init(Vec3::ZERO, 0.8, 60, 1, 3);
            let mut first = None;
            let mut last = 0.0;
            let mut most = 0;
            let out = train(&mut g, &views, &opts, &mut |s, _| {
                first.get_or_insert(s.psnr);
                last = s.psnr;
                most = most.max(s.gaussians);
                true
            })
            .unwrap();
            (g, out, first.unwrap(), last, most)
        };
        let (g, out, first, last, most) = run();
        assert_eq!(out.iterations, 300);
        assert!(most <= 120, "{most} Gaussians above the budget");
        assert!(g.len() > 60, "densification added Gaussians ({})", g.len());
        assert!(last > first + 5.0, "PSNR {first} → {last}");
        let (g2, ..) = run();
        assert_eq!(g, g2, "deterministic");
    }

    /// One 8 × 8 grey view from 4 units away on +Z, looking at the origin.
    fn grey_view() -> View {
        let camera = crate::volume::camera::Camera::look_at(
            Vec3::new(0.0, 0.0, 4.0),
            Vec3::ZERO,
            Vec3::Y,
            0.7,
            8,
            8,
        )
        .unwrap();
        View {
            name: "v".into(),
            camera,
            width: 8,
            height: 8,
            rgb: vec![[0.5; 3]; 64],
        }
    }

    #[test]
    fn bad_options_and_empty_models_are_refused() {
        let g = random_init(Vec3::ZERO, 1.0, 10, 0, 1);
        let view = grey_view();
        let opts = TrainOptions {
            iterations: 5,
            ..TrainOptions::default()
        };
        let err = |g: &mut Gaussians, views: &[View], o: &TrainOptions| {
            train(g, views, o, &mut |_, _| true)
                .unwrap_err()
                .to_string()
        };
        assert!(err(&mut g.clone(), &[], &opts).contains("no training views"));
        assert!(
            err(&mut Gaussians::new(0), std::slice::from_ref(&view), &opts)
                .contains("no Gaussians")
        );
        let zero = TrainOptions {
            sh_degree: 0,
            densify: Densify {
                max_gaussians: 0,
                ..Densify::default()
            },
            ..opts.clone()
        };
        assert!(
            err(&mut g.clone(), std::slice::from_ref(&view), &zero).contains("max_gaussians 0")
        );
        assert!(err(&mut g.clone(), std::slice::from_ref(&view), &opts).contains("SH degree 3"));
    }

    /// Pruning everything (every Gaussian below the opacity floor) is an error naming
    /// the iteration, not a panic.
    #[test]
    fn pruning_everything_is_a_clear_error() {
        let mut g = random_init(Vec3::ZERO, 1.0, 10, 0, 1);
        g.logit_opacities.iter_mut().for_each(|l| *l = -12.0);
        let view = grey_view();
        let opts = TrainOptions {
            iterations: 20,
            sh_degree: 0,
            lr_opacities: 0.0,
            densify: Densify {
                from: 10,
                until: 20,
                every: 10,
                ..Densify::default()
            },
            ..TrainOptions::default()
        };
        let e = train(&mut g, &[view], &opts, &mut |_, _| true)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("every Gaussian was pruned at iteration 10"),
            "{e}"
        );
    }
}

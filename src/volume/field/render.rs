//! Ray marching through the field: the voxel grid's sampling and compositing
//! conventions (see [`crate::volume::voxel::render`]) with a step fixed in world units
//! and the occupancy grid for empty space.
//!
//! **Samples.** A ray is clipped to the model's box; on the clipped interval `[t₀, t₁)`
//! it is sampled at `t_k = t₀ + (k + j)·Δ` while `t_k < t₁`, where `Δ` is the box
//! diagonal over [`RenderSettings::steps`] and `j ∈ [0, 1)` a jitter (½ when rendering,
//! random per ray and iteration when training). Samples whose occupancy cell is empty
//! are skipped: they stand for no density. Each sample stands for a segment of length `Δ`.
//!
//! **Compositing** as the voxel grid's: `α_k = 1 − exp(−σ_k·Δ)`, `T_{k+1} = T_k·(1 −
//! α_k)`, `C = Σ_k T_k·α_k·c_k + T_end·background`, marching stops after the first sample
//! with `T_{k+1} < early_stop`. **Backward:** `∂C/∂c_k = T_k·α_k`,
//! `∂C/∂σ_k = Δ·(T_{k+1}·c_k − S_k)` with `S_k` the color still to come.

use glam::Vec3;
use rayon::prelude::*;

use super::model::{DIR_DIM, Ngp, tape_len};
use crate::volume::{Ray, sh};

/// How rays are marched and composited.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Samples along the box's diagonal (the step is the diagonal over this), 16 to 8192.
    pub steps: u32,
    /// Color shown through the remaining transmittance, linear RGB in `[0, 1]`.
    pub background: [f32; 3],
    /// Marching stops once the transmittance falls below this (0 disables).
    pub early_stop: f32,
}

impl Default for RenderSettings {
    /// 512 samples along the diagonal, white background, stop below transmittance 1e-3.
    fn default() -> Self {
        RenderSettings {
            steps: 512,
            background: [1.0; 3],
            early_stop: 1e-3,
        }
    }
}

impl RenderSettings {
    /// Checks the settings; the message names the bad value.
    pub fn validate(&self) -> Result<(), String> {
        if !(16..=8192).contains(&self.steps) {
            return Err(format!("steps {} must be 16 to 8192", self.steps));
        }
        if !(self.early_stop.is_finite() && (0.0..1.0).contains(&self.early_stop)) {
            return Err(format!("early_stop {} is outside [0, 1)", self.early_stop));
        }
        if !self.background.iter().all(|c| c.is_finite()) {
            return Err(format!("background {:?} is not finite", self.background));
        }
        Ok(())
    }

    /// The sample length `Δ` for `model`, world units.
    pub(crate) fn delta(&self, model: &Ngp) -> f32 {
        (model.max() - model.min()).length() / self.steps as f32
    }
}

/// One composited sample, as kept for the backward pass.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Rec {
    /// `T_k·α_k`.
    weight: f32,
    /// `T_{k+1}`.
    t_after: f32,
    c: [f32; 3],
}

/// Per-thread buffers of one ray's march.
#[derive(Debug, Default)]
pub(crate) struct RayTape {
    /// One record of [`tape_len`] floats per sample.
    floats: Vec<f32>,
    recs: Vec<Rec>,
    /// Scratch of the backward pass.
    scratch: Vec<f32>,
    d_enc: Vec<f32>,
}

impl RayTape {
    /// Samples of the last march.
    #[cfg(test)]
    pub(crate) fn samples(&self) -> usize {
        self.recs.len()
    }
}

/// The ray clipped to the box: `[t0, t1)`, or `None` when it misses.
fn clip(model: &Ngp, ray: &Ray) -> Option<(f32, f32)> {
    let (lo, hi) = (model.min(), model.max());
    let (mut t0, mut t1) = (0.0f32, f32::INFINITY);
    for a in 0..3 {
        let (o, d) = (ray.origin[a], ray.dir[a]);
        if d.abs() < 1e-20 {
            if !(lo[a]..=hi[a]).contains(&o) {
                return None;
            }
        } else {
            let inv = 1.0 / d;
            let (ta, tb) = ((lo[a] - o) * inv, (hi[a] - o) * inv);
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
    }
    (t0 < t1).then_some((t0, t1))
}

/// Marches one ray (see the module doc) with jitter `jitter`; when `keep`, records every
/// composited sample in `tape` for [`ray_backward`]. Returns the color.
pub(crate) fn ray_forward(
    model: &Ngp,
    ray: &Ray,
    s: &RenderSettings,
    jitter: f32,
    tape: &mut RayTape,
    keep: bool,
) -> [f32; 3] {
    tape.recs.clear();
    let Some((t0, t1)) = clip(model, ray) else {
        return s.background;
    };
    let delta = s.delta(model);
    let tl = tape_len(model);
    if tape.floats.len() < tl {
        tape.floats.resize(tl, 0.0);
    }
    let basis = dir_basis(ray.dir);
    let o = model.normalize(ray.origin);
    let d = ray.dir / (model.max() - model.min());
    let mut tr = 1.0f32;
    let mut col = [0.0f32; 3];
    let mut k = 0u32;
    loop {
        let t = t0 + (k as f32 + jitter) * delta;
        if !(t < t1) {
            break;
        }
        k += 1;
        let x = o + d * t;
        if !model.occupancy.at(x) {
            continue;
        }
        let at = if keep { tape.recs.len() * tl } else { 0 };
        if tape.floats.len() < at + tl {
            tape.floats.resize(at + tl, 0.0);
        }
        let (sigma, c) = model.sample(x, &basis, &mut tape.floats[at..at + tl]);
        let e = (-sigma * delta).exp();
        let weight = tr * (1.0 - e);
        for ch in 0..3 {
            col[ch] += weight * c[ch];
        }
        tr *= e;
        if keep {
            tape.recs.push(Rec {
                weight,
                t_after: tr,
                c,
            });
        }
        if tr < s.early_stop {
            break;
        }
    }
    for ch in 0..3 {
        col[ch] += tr * s.background[ch];
    }
    col
}

/// The view direction's encoding: degree-3 real spherical harmonics.
#[inline]
pub(crate) fn dir_basis(dir: Vec3) -> [f32; DIR_DIM] {
    sh::basis(3, dir)
}

/// Gradient sinks of [`ray_backward`]: the networks' parameter gradients and, per
/// sample, its position and `∂L/∂encoding` (`3 + L·F` floats) for the hash scatter
/// (the position alone for a NeRF field).
#[derive(Debug)]
pub(crate) struct Grads {
    pub(crate) density: Vec<f32>,
    pub(crate) color: Vec<f32>,
    pub(crate) records: Vec<f32>,
}

impl Grads {
    pub(crate) fn new(model: &Ngp) -> Grads {
        Grads {
            density: vec![0.0; model.density.params.len()],
            color: vec![0.0; model.color.params.len()],
            records: Vec::new(),
        }
    }
}

/// Floats of one sample's record in [`Grads::records`] (3 for a NeRF field, which has
/// no table to scatter into).
pub(crate) fn record_len(model: &Ngp) -> usize {
    3 + model.hash.dim()
}

/// Backward pass of the ray last marched into `tape` (with `keep`), whose color was
/// `color`, given `g = ∂L/∂color`.
pub(crate) fn ray_backward(
    model: &Ngp,
    s: &RenderSettings,
    tape: &mut RayTape,
    color: [f32; 3],
    g: [f32; 3],
    grads: &mut Grads,
) {
    let delta = s.delta(model);
    let tl = tape_len(model);
    let widest = model
        .density
        .dims()
        .iter()
        .chain(model.color.dims())
        .copied()
        .max()
        .unwrap_or(0);
    let need = 2 * (model.shape().geo_features as usize + DIR_DIM) + 2 * widest + 2;
    if tape.scratch.len() < need {
        tape.scratch.resize(need, 0.0);
    }
    let ne = model.shape().encoding_dim();
    let nh = model.hash.dim();
    if tape.d_enc.len() < ne {
        tape.d_enc.resize(ne, 0.0);
    }
    let mut prefix = [0.0f32; 3];
    for (i, r) in tape.recs.iter().enumerate() {
        let mut d_sigma = 0.0;
        let mut d_c = [0.0f32; 3];
        for ch in 0..3 {
            prefix[ch] += r.weight * r.c[ch];
            let rest = color[ch] - prefix[ch];
            d_sigma += g[ch] * (r.t_after * r.c[ch] - rest);
            d_c[ch] = g[ch] * r.weight;
        }
        let rec = &tape.floats[i * tl..(i + 1) * tl];
        model.sample_backward(
            rec,
            d_sigma * delta,
            d_c,
            &mut grads.density,
            &mut grads.color,
            &mut tape.d_enc[..ne],
            &mut tape.scratch,
        );
        grads.records.extend_from_slice(&rec[..3]);
        grads.records.extend_from_slice(&tape.d_enc[..nh]);
    }
}

/// The color of one ray, linear RGB.
///
/// # Panics
/// If `settings` fails [`RenderSettings::validate`].
pub fn render_ray(model: &Ngp, ray: &Ray, settings: &RenderSettings) -> [f32; 3] {
    settings.validate().expect("RenderSettings");
    ray_forward(model, ray, settings, 0.5, &mut RayTape::default(), false)
}

/// The colors of many rays, in parallel (rayon), in order.
///
/// # Panics
/// If `settings` fails [`RenderSettings::validate`].
pub fn render_rays(model: &Ngp, rays: &[Ray], settings: &RenderSettings) -> Vec<[f32; 3]> {
    settings.validate().expect("RenderSettings");
    rays.par_iter()
        .with_min_len(64)
        .map_init(RayTape::default, |tape, r| {
            ray_forward(model, r, settings, 0.5, tape, false)
        })
        .collect()
}

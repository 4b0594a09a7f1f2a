//! Ray marching through the grid: front-to-back compositing with early termination and
//! empty-space skipping, its analytic backward pass, and per-slot rendering weights.
//!
//! **Samples.** A ray is clipped to the grid's box and to `t ≥ t_min`; on the clipped
//! interval `[t₀, t₁)` it is sampled at `t_k = t₀ + (k + ½)·Δ` for `k = 0, 1, …` while
//! `t_k < t₁`, where `Δ` is `step` voxels measured along the ray in grid space (world length
//! `step / |dir ⊘ voxel_size|`). Each sample stands for a segment of world length `Δ`.
//! Sample positions do not depend on the allocation: skipping only leaves out samples
//! whose cell has no allocated corner, which contribute nothing.
//!
//! **Compositing.** With `σ_k = max(interpolated raw density, 0)`,
//! `α_k = 1 − exp(−σ_k·Δ)`, `T_0 = 1`, `T_{k+1} = T_k·(1 − α_k)` and per-channel
//! `c_k = sigmoid(SH · basis(dir))` of the interpolated coefficients:
//! `C = Σ_k T_k·α_k·c_k + T_end·background`. Marching stops after the first sample whose
//! `T_{k+1} < early_stop` (the remaining transmittance still shows the background).
//!
//! **Backward.** `∂C/∂c_k = T_k·α_k` and `∂C/∂σ_k = Δ·(T_{k+1}·c_k − S_k)` with
//! `S_k = C − Σ_{j ≤ k} T_j·α_j·c_j` the color still to come (no division by `1 − α`, so
//! saturated samples are fine); these are spread to the 8 corners with the trilinear
//! weights. The result is the exact gradient of the rendered color as a function of the
//! grid values, except where it has kinks: interpolated raw density exactly 0 (ReLU) and
//! parameters at which early termination moves to another sample.

use glam::Vec3;
use rayon::prelude::*;

use super::grid::{BLOCK, Grid, cell_slots, trilinear};
use crate::volume::{Ray, sh};

/// How rays are marched and composited.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Distance between samples in voxels (grid-space length along the ray), at least
    /// 0.01. Plenoxels uses 0.5.
    pub step: f32,
    /// Color shown through the remaining transmittance, linear RGB in `[0, 1]`.
    pub background: [f32; 3],
    /// Samples start at this ray parameter (world units, ≥ 0): a near plane.
    pub t_min: f32,
    /// Marching stops once the transmittance falls below this (0 disables early
    /// termination).
    pub early_stop: f32,
}

impl Default for RenderSettings {
    /// Half-voxel steps, white background, no near plane, stop below transmittance 1e-3.
    fn default() -> Self {
        RenderSettings {
            step: 0.5,
            background: [1.0; 3],
            t_min: 0.0,
            early_stop: 1e-3,
        }
    }
}

impl RenderSettings {
    /// The default settings with samples `step` voxels apart; an error (naming the
    /// value) when `step` is not a finite number of at least 0.01.
    pub fn with_step(step: f32) -> Result<RenderSettings, String> {
        let render = RenderSettings {
            step,
            ..RenderSettings::default()
        };
        render.validate()?;
        Ok(render)
    }

    /// Checks the settings; the message names the bad value.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.step.is_finite() && self.step >= 0.01) {
            return Err(format!(
                "step {} is not a number of voxels ≥ 0.01",
                self.step
            ));
        }
        if !(self.t_min.is_finite() && self.t_min >= 0.0) {
            return Err(format!("t_min {} is not a finite value ≥ 0", self.t_min));
        }
        if !(self.early_stop.is_finite() && (0.0..1.0).contains(&self.early_stop)) {
            return Err(format!("early_stop {} is outside [0, 1)", self.early_stop));
        }
        if !self.background.iter().all(|c| c.is_finite()) {
            return Err(format!("background {:?} is not finite", self.background));
        }
        Ok(())
    }

    fn check(&self) {
        if let Err(e) = self.validate() {
            panic!("RenderSettings: {e}");
        }
    }
}

/// Gradient of a scalar loss with respect to the grid values: same layout as
/// [`Grid::density`] and [`Grid::sh`] (one entry per slot, [`Grid::sh_stride`] per slot).
/// The density gradient is with respect to the raw (pre-ReLU) value.
#[derive(Clone, Debug, PartialEq)]
pub struct Grads {
    /// `∂L/∂raw density` per slot.
    pub density: Vec<f32>,
    /// `∂L/∂SH coefficient`, laid out as [`Grid::sh`].
    pub sh: Vec<f32>,
}

impl Grads {
    /// Zero gradients shaped like `grid`.
    pub fn new(grid: &Grid) -> Grads {
        Grads {
            density: vec![0.0; grid.allocated()],
            sh: vec![0.0; grid.sh().len()],
        }
    }

    /// Sets every entry to 0.
    pub fn clear(&mut self) {
        self.density.iter_mut().for_each(|g| *g = 0.0);
        self.sh.iter_mut().for_each(|g| *g = 0.0);
    }
}

/// Calls `$body` with `$k` bound to the SH coefficient count of `$degree` as a constant.
macro_rules! with_k {
    ($degree:expr, $k:ident => $body:expr) => {
        match $degree {
            0 => {
                const $k: usize = 1;
                $body
            }
            1 => {
                const $k: usize = 4;
                $body
            }
            2 => {
                const $k: usize = 9;
                $body
            }
            _ => {
                const $k: usize = 16;
                $body
            }
        }
    };
}
pub(crate) use with_k;

/// The color of one ray (see the module doc), linear RGB.
///
/// # Panics
/// If `settings` fails [`RenderSettings::validate`].
pub fn render_ray(grid: &Grid, ray: &Ray, settings: &RenderSettings) -> [f32; 3] {
    settings.check();
    with_k!(grid.degree(), K => forward::<K>(grid, ray, settings, |_| {}).0)
}

/// The colors of many rays, in parallel (rayon), in order.
///
/// # Panics
/// If `settings` fails [`RenderSettings::validate`].
pub fn render_rays(grid: &Grid, rays: &[Ray], settings: &RenderSettings) -> Vec<[f32; 3]> {
    settings.check();
    with_k!(grid.degree(), K => rays
        .par_iter()
        .with_min_len(64)
        .map(|r| forward::<K>(grid, r, settings, |_| {}).0)
        .collect())
}

/// Backward pass of one ray: adds `Σ_ch d_color[ch] · ∂color[ch]/∂(grid values)` to
/// `grads` and returns the ray's color (the same as [`render_ray`]). The ray is marched
/// once; the samples are kept in a small buffer and walked again for the gradient.
///
/// # Panics
/// If `settings` fails [`RenderSettings::validate`] or `grads` is not shaped like `grid`.
pub fn ray_backward(
    grid: &Grid,
    ray: &Ray,
    settings: &RenderSettings,
    d_color: [f32; 3],
    grads: &mut Grads,
) -> [f32; 3] {
    settings.check();
    assert!(
        grads.density.len() == grid.allocated() && grads.sh.len() == grid.sh().len(),
        "ray_backward: gradients not shaped like the grid"
    );
    let mut tape = Vec::new();
    with_k!(grid.degree(), K => {
        let basis = sh::basis(grid.degree(), ray.dir);
        let (color, delta) = forward::<K>(grid, ray, settings, |r| tape.push(r));
        backward::<K, _>(&tape, &basis, delta, color, d_color, 0.0, grads);
        color
    })
}

/// The depth images of the view of `camera` (the [`Depth`](crate::volume::splat::Depth)
/// of Gaussians, with samples in place of splats): per pixel, with the samples' weights
/// `w_k = T_k·α_k` and depths `z_k` (the distance along the viewing axis of the sample's
/// position), the expected depth `Σ w_k·z_k / Σ w_k` (0 where no sample has weight),
/// the median depth (that of the sample with which `1 − T` reaches 0.5, front to back;
/// 0 where it never does) and the accumulated opacity `1 − T`.
///
/// # Panics
/// If `settings` fails [`RenderSettings::validate`].
pub fn render_depth(
    grid: &Grid,
    camera: &crate::volume::camera::Camera,
    settings: &RenderSettings,
) -> crate::volume::splat::Depth {
    settings.check();
    let rays = camera.rays();
    let forward_axis = camera.forward();
    let per_pixel: Vec<[f32; 3]> = with_k!(grid.degree(), K => rays
        .par_iter()
        .with_min_len(64)
        .map(|ray| {
            let along = ray.dir.dot(forward_axis);
            let (mut sum, mut total, mut median, mut after) = (0.0f32, 0.0f32, 0.0f32, 1.0f32);
            forward::<K>(grid, ray, settings, |r| {
                sum += r.weight * r.t * along;
                total += r.weight;
                if median == 0.0 && r.t_after <= 0.5 {
                    median = r.t * along;
                }
                after = r.t_after;
            });
            let expected = if total > 0.0 { sum / total } else { 0.0 };
            [expected, median, 1.0 - after]
        })
        .collect());
    crate::volume::splat::Depth {
        width: camera.width,
        height: camera.height,
        expected: per_pixel.iter().map(|p| p[0]).collect(),
        median: per_pixel.iter().map(|p| p[1]).collect(),
        opacity: per_pixel.iter().map(|p| p[2]).collect(),
    }
}

/// Per slot, the largest rendering weight `T_k·α_k` of any sample of `rays` whose cell
/// has the slot's vertex as a corner with nonzero trilinear weight (0 for slots no ray
/// reaches). Used to prune space that no view sees ([`Grid::prune_by_weight`]).
/// Parallel over rays, one buffer per thread.
///
/// # Panics
/// If `settings` fails [`RenderSettings::validate`].
pub fn max_weights(grid: &Grid, rays: &[Ray], settings: &RenderSettings) -> Vec<f32> {
    settings.check();
    let n = grid.allocated();
    if rays.is_empty() {
        return vec![0.0; n];
    }
    let chunk = rays.len().div_ceil(rayon::current_num_threads().max(1));
    with_k!(grid.degree(), K => rays
        .par_chunks(chunk)
        .map(|part| {
            let mut mw = vec![0.0f32; n];
            for ray in part {
                forward::<K>(grid, ray, settings, |r| {
                    for c in 0..8 {
                        if r.slots[c] >= 0 && r.w[c] > 0.0 {
                            let m = &mut mw[r.slots[c] as usize];
                            *m = m.max(r.weight);
                        }
                    }
                });
            }
            mw
        })
        .reduce_with(|mut a, b| {
            a.iter_mut().zip(b).for_each(|(x, y)| *x = x.max(y));
            a
        })
        .unwrap_or_else(|| vec![0.0; n]))
}

/// One composited sample with nonzero density, as kept for the backward pass.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SampleRec {
    /// Corner slots (−1: unallocated).
    pub(crate) slots: [i32; 8],
    /// Trilinear weights of the corners.
    pub(crate) w: [f32; 8],
    /// `T_k·α_k`.
    pub(crate) weight: f32,
    /// `T_{k+1}`.
    pub(crate) t_after: f32,
    /// `σ_k`.
    pub(crate) sigma: f32,
    /// The sample's color after the sigmoid.
    pub(crate) c: [f32; 3],
    /// The sample's ray parameter `t_k`, in the grid-space units of [`Setup`].
    pub(crate) t: f32,
}

/// A ray in grid space (vertex units) clipped to the box.
pub(crate) struct Setup {
    o: Vec3,
    d: Vec3,
    t_start: f32,
    t_end: f32,
    dt: f32,
}

/// Components of the grid-space direction below this count as parallel to the axis.
const PARALLEL: f32 = 1e-20;

fn setup(grid: &Grid, ray: &Ray, settings: &RenderSettings) -> Option<Setup> {
    let r = grid.res() as f32;
    let inv_vs = Vec3::splat(r) / (grid.max() - grid.min());
    let o = (ray.origin - grid.min()) * inv_vs;
    let d = ray.dir * inv_vs;
    let (mut t0, mut t1) = (settings.t_min, f32::INFINITY);
    for a in 0..3 {
        if d[a].abs() < PARALLEL {
            // NaN-safe: a NaN origin fails `contains` and misses.
            if !(0.0..=r).contains(&o[a]) {
                return None;
            }
        } else {
            let inv = 1.0 / d[a];
            let (ta, tb) = (-o[a] * inv, (r - o[a]) * inv);
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
    }
    let dt = settings.step / d.length();
    (t0 < t1 && dt.is_finite() && dt > 0.0).then_some(Setup {
        o,
        d,
        t_start: t0,
        t_end: t1,
        dt,
    })
}

/// Visits every sample (in order) whose cell has an allocated corner, with the corner
/// slots and trilinear weights; `visit` returns false to stop.
#[inline(always)]
fn march(grid: &Grid, s: &Setup, mut visit: impl FnMut(&[i32; 8], &[f32; 8], f32) -> bool) {
    let res = grid.res();
    let r = res as f32;
    let last = res - 1;
    let skip = grid.skip();
    let nb = skip.nb as usize;
    let n = res as usize + 1;
    let index = grid.index_table();
    let mut k: u32 = 0;
    loop {
        let t = s.t_start + (k as f32 + 0.5) * s.dt;
        if !(t < s.t_end) {
            break;
        }
        let q = (s.o + s.d * t).clamp(Vec3::ZERO, Vec3::splat(r));
        let cx = (q.x as u32).min(last);
        let cy = (q.y as u32).min(last);
        let cz = (q.z as u32).min(last);
        let b = [cx / BLOCK, cy / BLOCK, cz / BLOCK];
        let dist = skip.dist[b[0] as usize + nb * (b[1] as usize + nb * b[2] as usize)];
        if dist > 0 {
            // Leave the cube of empty blocks around this one.
            let mut te = f32::INFINITY;
            for a in 0..3 {
                let da = s.d[a];
                if da > 0.0 {
                    let plane = ((b[a] + dist as u32) * BLOCK) as f32;
                    te = te.min((plane - s.o[a]) / da);
                } else if da < 0.0 {
                    let plane = ((b[a] as i64 + 1 - dist as i64) * BLOCK as i64) as f32;
                    te = te.min((plane - s.o[a]) / da);
                }
            }
            let kn = ((te - s.t_start) / s.dt - 0.5).ceil();
            k = (k + 1).max(kn as u32);
            continue;
        }
        let base = cx as usize + n * (cy as usize + n * cz as usize);
        let slots = cell_slots(index, base, n);
        k += 1;
        if slots.iter().all(|&v| v < 0) {
            continue;
        }
        let w = trilinear(q.x - cx as f32, q.y - cy as f32, q.z - cz as f32);
        if !visit(&slots, &w, t) {
            break;
        }
    }
}

#[inline(always)]
fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Renders one ray with `K` coefficients per channel; `rec` sees every sample with
/// positive density. Returns the color and the sample length `Δ` (world units; 0 when the
/// ray misses the box).
#[inline(always)]
pub(crate) fn forward<const K: usize>(
    grid: &Grid,
    ray: &Ray,
    settings: &RenderSettings,
    mut rec: impl FnMut(SampleRec),
) -> ([f32; 3], f32) {
    let bg = settings.background;
    let Some(s) = setup(grid, ray, settings) else {
        return (bg, 0.0);
    };
    let basis = sh::basis(grid.degree(), ray.dir);
    let dens = grid.density();
    let shd = grid.sh();
    let delta = s.dt;
    let stop = settings.early_stop;
    let mut tr = 1.0f32;
    let mut col = [0.0f32; 3];
    march(grid, &s, |slots, w, t| {
        let mut raw = 0.0;
        for c in 0..8 {
            if slots[c] >= 0 {
                raw += w[c] * dens[slots[c] as usize];
            }
        }
        if !(raw > 0.0) {
            return true;
        }
        let e = (-raw * delta).exp();
        let weight = tr * (1.0 - e);
        let mut acc = [[0.0f32; K]; 3];
        for c in 0..8 {
            if slots[c] >= 0 {
                let at = slots[c] as usize * 3 * K;
                let src = &shd[at..at + 3 * K];
                let wc = w[c];
                for ch in 0..3 {
                    for k in 0..K {
                        acc[ch][k] += wc * src[ch * K + k];
                    }
                }
            }
        }
        let mut cc = [0.0f32; 3];
        for ch in 0..3 {
            let mut x = 0.0;
            for k in 0..K {
                x += acc[ch][k] * basis[k];
            }
            cc[ch] = sigmoid(x);
            col[ch] += weight * cc[ch];
        }
        tr *= e;
        rec(SampleRec {
            slots: *slots,
            w: *w,
            weight,
            t_after: tr,
            sigma: raw,
            c: cc,
            t,
        });
        tr >= stop
    });
    for ch in 0..3 {
        col[ch] += tr * bg[ch];
    }
    (col, delta)
}

/// Where the backward pass puts its gradients.
pub(crate) trait Sink {
    /// Adds `w[c]·d_sigma` to the density gradient and `w[c]·d_sh` to the SH gradient of
    /// every allocated corner `c`.
    fn add<const K: usize>(
        &mut self,
        slots: &[i32; 8],
        w: &[f32; 8],
        d_sigma: f32,
        d_sh: &[[f32; K]; 3],
    );
}

/// The scatter shared by the sinks.
#[inline(always)]
pub(crate) fn scatter<const K: usize>(
    gd: &mut [f32],
    gsh: &mut [f32],
    slots: &[i32; 8],
    w: &[f32; 8],
    d_sigma: f32,
    d_sh: &[[f32; K]; 3],
) {
    for c in 0..8 {
        if slots[c] >= 0 {
            let s = slots[c] as usize;
            let wc = w[c];
            gd[s] += wc * d_sigma;
            let dst = &mut gsh[s * 3 * K..(s + 1) * 3 * K];
            for ch in 0..3 {
                for k in 0..K {
                    dst[ch * K + k] += wc * d_sh[ch][k];
                }
            }
        }
    }
}

impl Sink for Grads {
    #[inline(always)]
    fn add<const K: usize>(
        &mut self,
        slots: &[i32; 8],
        w: &[f32; 8],
        d_sigma: f32,
        d_sh: &[[f32; K]; 3],
    ) {
        scatter::<K>(&mut self.density, &mut self.sh, slots, w, d_sigma, d_sh);
    }
}

/// The backward pass over the samples `tape` of one ray (from [`forward`]) with total
/// color `color`, sample length `delta`, `g = ∂L/∂color`, and the weight `sparse` of the
/// Cauchy sparsity term `Σ_k Δ·ln(1 + 2σ_k²)` over the ray's marched samples.
#[inline(always)]
pub(crate) fn backward<const K: usize, S: Sink>(
    tape: &[SampleRec],
    basis: &[f32; 16],
    delta: f32,
    color: [f32; 3],
    g: [f32; 3],
    sparse: f32,
    sink: &mut S,
) {
    let mut prefix = [0.0f32; 3];
    for r in tape {
        let mut d_sigma = 0.0;
        let mut d_sh = [[0.0f32; K]; 3];
        for ch in 0..3 {
            prefix[ch] += r.weight * r.c[ch];
            let rest = color[ch] - prefix[ch];
            d_sigma += g[ch] * (r.t_after * r.c[ch] - rest);
            let d_pre = g[ch] * r.weight * r.c[ch] * (1.0 - r.c[ch]);
            for k in 0..K {
                d_sh[ch][k] = d_pre * basis[k];
            }
        }
        let d_sparse = sparse * 4.0 * r.sigma / (1.0 + 2.0 * r.sigma * r.sigma);
        sink.add::<K>(&r.slots, &r.w, (d_sigma + d_sparse) * delta, &d_sh);
    }
}

/// The gradient of the loss with respect to the ray itself, `(∂L/∂origin, ∂L/∂dir)`
/// in world axes (`dir` as given, its length not held fixed), for the samples `tape`
/// that [`forward`] recorded for `ray`, its color `color`, `g = ∂L/∂color`, and the
/// sparsity weight `sparse` as in [`backward`]. The samples move with the ray: their
/// positions `o + t_k·d` (through the trilinear weights of density and color), the box
/// entry `t₀` the `t_k` start from, and the spacing `Δ = step / |d ⊘ voxel_size|`; the
/// colors' SH basis depends on `dir` too. Exact where [`backward`] is, and also except
/// where a sample crosses the end of the box (the count of samples changes).
pub(crate) fn ray_gradient<const K: usize>(
    grid: &Grid,
    ray: &Ray,
    settings: &RenderSettings,
    tape: &[SampleRec],
    color: [f32; 3],
    g: [f32; 3],
    sparse: f32,
) -> (Vec3, Vec3) {
    let Some(s) = setup(grid, ray, settings) else {
        return (Vec3::ZERO, Vec3::ZERO);
    };
    if tape.is_empty() {
        return (Vec3::ZERO, Vec3::ZERO);
    }
    let r = grid.res() as f32;
    let last = grid.res() - 1;
    let basis = sh::basis(grid.degree(), ray.dir);
    let (dens, shd) = (grid.density(), grid.sh());
    let delta = s.dt;
    let mut prefix = [0.0f32; 3];
    // Gradients in grid space: origin, direction, entry parameter, spacing.
    let (mut g_o, mut g_d) = (Vec3::ZERO, Vec3::ZERO);
    let (mut g_t0, mut g_dt) = (0.0f32, 0.0f32);
    let mut g_basis = [0.0f32; K];
    for rec in tape {
        let mut through = 0.0;
        let mut d_pre = [0.0f32; 3];
        for ch in 0..3 {
            prefix[ch] += rec.weight * rec.c[ch];
            let rest = color[ch] - prefix[ch];
            through += g[ch] * (rec.t_after * rec.c[ch] - rest);
            d_pre[ch] = g[ch] * rec.weight * rec.c[ch] * (1.0 - rec.c[ch]);
        }
        // α = 1 − exp(−σΔ): σ and Δ enter as their product; the sparsity term is
        // Δ·ln(1 + 2σ²).
        let sig = rec.sigma;
        let d_sigma = delta * (through + sparse * 4.0 * sig / (1.0 + 2.0 * sig * sig));
        g_dt += sig * through + sparse * (1.0 + 2.0 * sig * sig).ln();
        let q = (s.o + s.d * rec.t).clamp(Vec3::ZERO, Vec3::splat(r));
        let cell = Vec3::new(
            (q.x as u32).min(last) as f32,
            (q.y as u32).min(last) as f32,
            (q.z as u32).min(last) as f32,
        );
        let gw = trilinear_gradient(q - cell);
        let mut g_q = Vec3::ZERO;
        for c in 0..8 {
            if rec.slots[c] < 0 {
                continue;
            }
            let at = rec.slots[c] as usize;
            let mut sc = dens[at] * d_sigma;
            for ch in 0..3 {
                let row = &shd[at * 3 * K + ch * K..at * 3 * K + (ch + 1) * K];
                let mut pre = 0.0;
                for k in 0..K {
                    pre += row[k] * basis[k];
                    g_basis[k] += d_pre[ch] * rec.w[c] * row[k];
                }
                sc += d_pre[ch] * pre;
            }
            g_q += gw[c] * sc;
        }
        // q = o + d·t_k, t_k = t₀ + (k + ½)·Δ.
        g_o += g_q;
        g_d += g_q * rec.t;
        let g_t = g_q.dot(s.d);
        g_t0 += g_t;
        let half_k = ((rec.t - s.t_start) / s.dt - 0.5).round() + 0.5;
        g_dt += g_t * half_k;
    }
    // Δ = step / |d|.
    g_d -= s.d * (g_dt * delta / s.d.length_squared());
    // t₀ is the near plane or the entry into the box through one axis' plane.
    let mut t0 = settings.t_min;
    let mut entry = None;
    for a in 0..3 {
        if s.d[a].abs() >= PARALLEL {
            let inv = 1.0 / s.d[a];
            let near = (-s.o[a] * inv).min((r - s.o[a]) * inv);
            if near > t0 {
                t0 = near;
                entry = Some(a);
            }
        }
    }
    if let Some(a) = entry {
        // t₀ = (plane − o_a) / d_a.
        g_o[a] -= g_t0 / s.d[a];
        g_d[a] -= g_t0 * t0 / s.d[a];
    }
    let gb = sh::basis_gradient(grid.degree(), ray.dir);
    let mut g_dir = Vec3::ZERO;
    for k in 0..K {
        g_dir += gb[k] * g_basis[k];
    }
    let inv_vs = Vec3::splat(r) / (grid.max() - grid.min());
    (g_o * inv_vs, g_dir + g_d * inv_vs)
}

/// `∂wᵢ/∂(fx, fy, fz)` of [`trilinear`]'s weights.
#[inline(always)]
fn trilinear_gradient(f: Vec3) -> [Vec3; 8] {
    std::array::from_fn(|c| {
        let pick = |bit: usize, v: f32| {
            if c & bit != 0 {
                (v, 1.0)
            } else {
                (1.0 - v, -1.0)
            }
        };
        let ((wx, dx), (wy, dy), (wz, dz)) = (pick(1, f.x), pick(2, f.y), pick(4, f.z));
        Vec3::new(dx * wy * wz, wx * dy * wz, wx * wy * dz)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic pseudo-random value in `[0, 1)`.
    fn hash(i: usize) -> f32 {
        let mut z = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x5DEE_CE66;
        z = (z ^ (z >> 29)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        ((z >> 40) as f32) / (1u64 << 24) as f32
    }

    /// A 6³ grid over `[−1, 1]³` with positive densities (so the ReLU never clips) and
    /// varied SH coefficients of degree `degree`.
    fn test_grid(degree: u32) -> Grid {
        let mut g = Grid::dense(Vec3::splat(-1.0), Vec3::splat(1.0), 6, degree, 0.0);
        for (i, d) in g.density_mut().iter_mut().enumerate() {
            *d = 0.3 + 2.5 * hash(i);
        }
        for (i, c) in g.sh_mut().iter_mut().enumerate() {
            *c = 1.6 * hash(i + 7777) - 0.8;
        }
        g
    }

    fn oblique() -> Ray {
        Ray {
            origin: Vec3::new(-2.2, -1.3, 2.5),
            dir: Vec3::new(0.62, 0.31, -0.72).normalize(),
        }
    }

    const G: [f32; 3] = [0.7, -0.4, 1.1];

    /// Weight of the sparsity term in the gradient check.
    const SPARSE: f32 = 0.05;

    /// `Σ G·color + SPARSE·Σ_k Δ·ln(1 + 2σ_k²)` by the f64 reference march, with the grid
    /// values replaced by `dens`, `shv`.
    fn loss64(g: &Grid, dens: &[f64], shv: &[f64], ray: &Ray, s: &RenderSettings) -> f64 {
        let (c, sparse) = naive_with_sparsity(g, dens, shv, ray, s);
        (0..3).map(|i| G[i] as f64 * c[i]).sum::<f64>() + SPARSE as f64 * sparse
    }

    /// [`ray_backward`] against central differences of an independent f64 reference
    /// renderer ([`naive`]), for the density and three SH coefficients of every third slot
    /// the ray touches, plus slots it does not touch (whose gradient must be exactly 0).
    /// All densities are positive, so no sample sits at the ReLU kink, and early
    /// termination is off, so the set of samples is fixed: the rendering is smooth there.
    #[test]
    fn gradients_match_finite_differences() {
        for degree in [0, 2, 3] {
            let grid = test_grid(degree);
            let s = RenderSettings {
                early_stop: 0.0,
                background: [0.2, 0.9, 0.5],
                ..RenderSettings::default()
            };
            let ray = oblique();
            let mut grads = Grads::new(&grid);
            let c = ray_backward(&grid, &ray, &s, G, &mut grads);
            assert_eq!(c, render_ray(&grid, &ray, &s));
            // The same with the sparsity term, through the training entry points.
            let mut tape = Vec::new();
            let mut grads = Grads::new(&grid);
            with_k!(degree, K => {
                let (c2, delta) = forward::<K>(&grid, &ray, &s, |r| tape.push(r));
                assert_eq!(c2, c);
                backward::<K, _>(&tape, &sh::basis(degree, ray.dir), delta, c, G, SPARSE, &mut grads);
            });
            let reference = naive(&grid, &to64(grid.density()), &to64(grid.sh()), &ray, &s);
            for ch in 0..3 {
                assert!(
                    (c[ch] as f64 - reference[ch]).abs() < 1e-5,
                    "forward {c:?} vs {reference:?}"
                );
            }
            let touched: Vec<usize> = (0..grid.allocated())
                .filter(|&i| grads.density[i] != 0.0)
                .collect();
            assert!(touched.len() > 20, "the ray crosses the grid");
            let scale = grads
                .density
                .iter()
                .chain(&grads.sh)
                .fold(0.0f32, |m, g| m.max(g.abs()));
            let stride = grid.sh_stride();
            let (d0, s0) = (to64(grid.density()), to64(grid.sh()));
            let mut checked = 0;
            let untouched = (0..grid.allocated())
                .filter(|s| !touched.contains(s))
                .take(2);
            for slot in touched.iter().copied().step_by(3).chain(untouched) {
                let mut params = vec![(true, slot)];
                for j in [0, stride / 2, stride - 1] {
                    params.push((false, slot * stride + j));
                }
                for (is_density, at) in params {
                    let h = 1e-6;
                    let (mut dp, mut dm, mut sp, mut sm) =
                        (d0.clone(), d0.clone(), s0.clone(), s0.clone());
                    if is_density {
                        dp[at] += h;
                        dm[at] -= h;
                    } else {
                        sp[at] += h;
                        sm[at] -= h;
                    }
                    let fd = (loss64(&grid, &dp, &sp, &ray, &s)
                        - loss64(&grid, &dm, &sm, &ray, &s))
                        / (2.0 * h);
                    let an = if is_density {
                        grads.density[at]
                    } else {
                        grads.sh[at]
                    } as f64;
                    let tol = 1e-5 * scale as f64 + 1e-4 * an.abs();
                    assert!(
                        (fd - an).abs() <= tol,
                        "degree {degree}, {} {at}: analytic {an}, central difference {fd}",
                        if is_density {
                            "density of slot"
                        } else {
                            "SH entry"
                        }
                    );
                    checked += 1;
                }
            }
            assert!(checked > 40);
        }
    }

    /// [`ray_gradient`] against central differences of the f32 renderer, for a ray that
    /// enters the box (the entry point moves with it) and one that starts inside (at the
    /// near plane), with the sparsity term; the perturbations keep the count of samples.
    #[test]
    fn ray_gradient_matches_central_differences() {
        for degree in [0, 2] {
            let grid = test_grid(degree);
            let s = RenderSettings {
                early_stop: 0.0,
                background: [0.2, 0.9, 0.5],
                t_min: 0.05,
                ..RenderSettings::default()
            };
            let inside = Ray {
                origin: Vec3::new(0.1, -0.2, 0.3),
                dir: Vec3::new(-0.4, 0.7, 0.2).normalize(),
            };
            for ray in [oblique(), inside] {
                let run = |ray: &Ray| {
                    let mut tape = Vec::new();
                    let (c, _) =
                        with_k!(degree, K => forward::<K>(&grid, ray, &s, |r| tape.push(r)));
                    (c, tape)
                };
                let loss = |ray: &Ray| -> (f64, usize) {
                    let (c, tape) = run(ray);
                    let sparse: f64 = tape
                        .iter()
                        .map(|r| (1.0 + 2.0 * (r.sigma as f64).powi(2)).ln())
                        .sum::<f64>();
                    let delta = setup(&grid, ray, &s).unwrap().dt as f64;
                    let v = (0..3).map(|i| G[i] as f64 * c[i] as f64).sum::<f64>()
                        + SPARSE as f64 * delta * sparse;
                    (v, tape.len())
                };
                let (c, tape) = run(&ray);
                let (g_o, g_d) = with_k!(degree, K => ray_gradient::<K>(
                    &grid, &ray, &s, &tape, c, G, SPARSE
                ));
                let analytic = [g_o.x, g_o.y, g_o.z, g_d.x, g_d.y, g_d.z];
                let largest = analytic.iter().fold(0.0f32, |m, v| m.max(v.abs())) as f64;
                assert!(largest > 1e-2, "{analytic:?}");
                // Small steps: a sample near a cell face has a kink (trilinear weights).
                let h = 3e-4f32;
                for j in 0..6 {
                    let (mut plus, mut minus) = (ray, ray);
                    let (p, m) = if j < 3 {
                        (&mut plus.origin, &mut minus.origin)
                    } else {
                        (&mut plus.dir, &mut minus.dir)
                    };
                    p[j % 3] += h;
                    m[j % 3] -= h;
                    let ((lp, np), (lm, nm)) = (loss(&plus), loss(&minus));
                    assert_eq!((np, nm), (tape.len(), tape.len()), "sample count changed");
                    let fd = (lp - lm) / (2.0 * h as f64);
                    let an = analytic[j] as f64;
                    assert!(
                        (fd - an).abs() <= 0.01 * largest + 0.01 * fd.abs(),
                        "degree {degree}, ray {ray:?}, {}[{}]: analytic {an} vs {fd}",
                        if j < 3 { "origin" } else { "dir" },
                        j % 3
                    );
                }
            }
        }
    }

    fn to64(v: &[f32]) -> Vec<f64> {
        v.iter().map(|&x| x as f64).collect()
    }

    /// Rendering with skipping equals a brute-force march that samples every `t_k`
    /// without looking at the allocation.
    /// Allocated vertices with raw density ≤ 0 (a shell around the ball) count as empty
    /// space for skipping, exactly.
    #[test]
    fn skipping_matches_a_naive_march() {
        let mut g = Grid::from_fn(Vec3::splat(-1.0), Vec3::splat(1.0), 32, 1, |p| {
            let d = (p - Vec3::new(0.3, -0.2, 0.1)).length();
            (d < 0.7).then_some(if d < 0.35 { 8.0 } else { d - 0.9 })
        });
        let skip = g.skip();
        assert!(skip.dist.iter().filter(|&&d| d > 0).count() > skip.dist.len() / 2);
        for (i, c) in g.sh_mut().iter_mut().enumerate() {
            *c = hash(i) - 0.5;
        }
        let s = RenderSettings::default();
        for i in 0..200 {
            let origin = Vec3::new(hash(3 * i) - 0.5, hash(3 * i + 1) - 0.5, 3.0);
            let target = Vec3::new(0.3, -0.2, 0.1)
                + 0.4
                    * Vec3::new(
                        hash(7 * i) - 0.5,
                        hash(7 * i + 1) - 0.5,
                        hash(7 * i + 2) - 0.5,
                    );
            let ray = Ray {
                origin,
                dir: (target - origin).normalize(),
            };
            let fast = render_ray(&g, &ray, &s);
            let slow = naive(&g, &to64(g.density()), &to64(g.sh()), &ray, &s);
            for ch in 0..3 {
                assert!(
                    (fast[ch] as f64 - slow[ch]).abs() < 1e-5,
                    "ray {i}: {fast:?} vs {slow:?}"
                );
            }
        }
    }

    /// Samples every `t_k` with [`Grid::corners`] (sample positions and trilinear weights
    /// in f32 as the renderer has them, everything else in f64), using the values `dens`
    /// and `shv` in place of the grid's.
    fn naive(g: &Grid, dens: &[f64], shv: &[f64], ray: &Ray, s: &RenderSettings) -> [f64; 3] {
        naive_with_sparsity(g, dens, shv, ray, s).0
    }

    /// [`naive`] and the sparsity sum `Σ_k Δ·ln(1 + 2σ_k²)` of the marched samples.
    fn naive_with_sparsity(
        g: &Grid,
        dens: &[f64],
        shv: &[f64],
        ray: &Ray,
        s: &RenderSettings,
    ) -> ([f64; 3], f64) {
        let Some(su) = setup(g, ray, s) else {
            return (s.background.map(|c| c as f64), 0.0);
        };
        let mut sparse = 0.0;
        let b = sh::basis(g.degree(), ray.dir);
        let k = g.coeffs();
        let (mut tr, mut col) = (1.0f64, [0.0f64; 3]);
        let mut i = 0;
        loop {
            let t = su.t_start + (i as f32 + 0.5) * su.dt;
            if t >= su.t_end || tr < s.early_stop as f64 {
                break;
            }
            i += 1;
            let (slots, w) = g.corners(su.o + su.d * t);
            let mut raw = 0.0f64;
            let mut pre = [0.0f64; 3];
            for c in 0..8 {
                if slots[c] >= 0 {
                    let sl = slots[c] as usize;
                    raw += w[c] as f64 * dens[sl];
                    for ch in 0..3 {
                        for j in 0..k {
                            pre[ch] += w[c] as f64 * shv[sl * 3 * k + ch * k + j] * b[j] as f64;
                        }
                    }
                }
            }
            let sigma = raw.max(0.0);
            sparse += su.dt as f64 * (1.0 + 2.0 * sigma * sigma).ln();
            let e = (-sigma * su.dt as f64).exp();
            for ch in 0..3 {
                col[ch] += tr * (1.0 - e) / (1.0 + (-pre[ch]).exp());
            }
            tr *= e;
        }
        (
            [0, 1, 2].map(|ch| col[ch] + tr * s.background[ch] as f64),
            sparse,
        )
    }

    #[test]
    fn max_weights_see_only_what_rays_reach() {
        let g = test_grid(1);
        let ray = oblique();
        let w = max_weights(&g, &[ray], &RenderSettings::default());
        let mut grads = Grads::new(&g);
        ray_backward(&g, &ray, &RenderSettings::default(), [1.0; 3], &mut grads);
        for s in 0..g.allocated() {
            assert!((0.0..=1.0).contains(&w[s]));
            if grads.density[s] == 0.0 {
                assert_eq!(w[s], 0.0, "slot {s} gets weight without being sampled");
            }
        }
        assert!(w.iter().any(|&v| v > 0.01));
    }

    /// A camera looking down −z at a slab of dense voxels from 1.5 to 2.5 units away,
    /// behind a faint haze: the median depth is where half the light is gone inside the
    /// slab, the expected depth lies between the haze and the slab, the opacity is 1,
    /// and depths are along the viewing axis (the same for oblique pixels).
    #[test]
    fn depth_of_a_slab() {
        let mut g = Grid::dense(Vec3::splat(-2.0), Vec3::splat(2.0), 40, 0, 0.0);
        let n = 41;
        for (slot, d) in g.density_mut().iter_mut().enumerate() {
            let z = -2.0 + 0.1 * (slot / (n * n)) as f32;
            *d = if (-0.5..=0.5).contains(&z) { 60.0 } else { 0.0 };
        }
        let pose = glam::Affine3A::from_translation(Vec3::new(0.0, 0.0, 2.0));
        let cam = crate::volume::camera::Camera::from_fov_x(9, 7, 0.6, pose).unwrap();
        let s = RenderSettings {
            early_stop: 0.0,
            ..RenderSettings::default()
        };
        let d = render_depth(&g, &cam, &s);
        assert_eq!((d.width, d.height, d.expected.len()), (9, 7, 63));
        // Density 60 per unit: half the light is gone ln 2 / 60 ≈ 0.012 units into the
        // slab (which the trilinear ramp starts 0.1 units earlier, at depth 1.4).
        for i in 0..63 {
            assert!(d.opacity[i] > 0.999, "{}", d.opacity[i]);
            assert!((1.38..1.55).contains(&d.median[i]), "{}", d.median[i]);
            assert!((1.38..1.6).contains(&d.expected[i]), "{}", d.expected[i]);
        }
        let center = 3 * 9 + 4;
        assert!((d.median[0] - d.median[center]).abs() < 0.06);
        // Nothing to see: zeros.
        let empty = Grid::dense(Vec3::splat(-2.0), Vec3::splat(2.0), 8, 0, 0.0);
        let d = render_depth(&empty, &cam, &s);
        assert!(
            d.expected
                .iter()
                .chain(&d.median)
                .chain(&d.opacity)
                .all(|&v| v == 0.0)
        );
    }

    #[test]
    fn invalid_settings_are_named() {
        let bad = RenderSettings {
            step: 0.0,
            ..RenderSettings::default()
        };
        assert!(bad.validate().unwrap_err().contains("step 0"));
        let bad = RenderSettings {
            early_stop: 1.5,
            ..RenderSettings::default()
        };
        assert!(bad.validate().unwrap_err().contains("early_stop"));
    }
}

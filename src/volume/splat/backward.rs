//! The backward pass of [`render`](super::render()): the exact gradient of a loss with
//! respect to every parameter of every Gaussian, given the gradient of the loss with
//! respect to the rendered image.
//!
//! It runs the forward's steps in reverse:
//!
//! 1. **Pixels, back to front.** Each pixel walks the entries of its tile's list that
//!    blending visited, from the last to the first, recovering each transmittance from the
//!    final one (`Tᵢ = Tᵢ₊₁ / (1 − αᵢ)`, as the reference code does) and the color behind
//!    each splat, so nothing per pixel and splat is stored by the forward. Each splat's
//!    share goes into its tile's buffer: the gradients of its projected center, conic,
//!    opacity and color.
//! 2. **Tiles, in order.** The buffers are added per Gaussian in tile order (tiles run in
//!    parallel, in chunks that bound the memory), so the sums, and every bit of the result,
//!    do not depend on the number of threads.
//! 3. **Projection, per Gaussian.** Conic → 2D covariance → camera covariance and the
//!    perspective Jacobian → mean, rotation (through the quaternion's normalization) and
//!    log-scales; opacity through the sigmoid; color through the clamp at 0 to the SH
//!    coefficients and, through the view direction, to the mean.
//!
//! The gradient is that of the function the forward computes, thresholds included: a
//! splat's opacity clamped at 0.99 passes no gradient to its opacity or shape at that
//! pixel, skipped contributions (below 1/255, or past the early stop) pass none, and the
//! Jacobian's frustum clamp passes none to the clamped coordinate, as in exact
//! differentiation of those branches.

use glam::{Mat2, Mat3, Vec2, Vec3};
use rayon::prelude::*;

use wide::{f32x8, i32x8};

use super::Gaussians;
use super::kernel::{GradRow, HALVES, grad_row, lane_sum, set_lane};
use super::render::{Pinhole, Projected, RenderSettings, Rendered, TILE, splat_rows, tile_pixels};
use crate::volume::camera::Camera;
use crate::volume::sh;

/// Most (tile, Gaussian) pairs whose per-pair gradients are held at once; tiles are
/// processed in chunks of at most this many (or one tile, if larger).
const CHUNK_PAIRS: usize = 1 << 21;

/// Per (tile, splat) pair: ∂L/∂ of the projected center (x, y), of the conic `[a, b, c]`,
/// of the opacity after its sigmoid and of the color (r, g, b).
type PairGrad = [f32; 9];

/// Gradients of a loss with respect to every parameter of a [`Gaussians`], in its
/// layout (parameters before activation, SH channel-major), plus what densification
/// reads.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gradients {
    /// ∂L/∂mean, per world unit.
    pub means: Vec<[f32; 3]>,
    /// ∂L/∂log-scale.
    pub log_scales: Vec<[f32; 3]>,
    /// ∂L/∂quaternion `[w, x, y, z]` as stored (before normalization).
    pub rotations: Vec<[f32; 4]>,
    /// ∂L/∂logit opacity.
    pub logit_opacities: Vec<f32>,
    /// ∂L/∂SH coefficient, channel-major like [`Gaussians::sh`].
    pub sh: Vec<f32>,
    /// ∂L/∂(projected center), per pixel: the view-space gradient that adaptive density
    /// control accumulates. Zero for Gaussians not drawn.
    pub mean2d: Vec<[f32; 2]>,
    /// Whether each Gaussian survived culling in the view (it was projected and binned).
    pub visible: Vec<bool>,
    /// ∂L/∂(a pose correction `[ε, u]` of the camera, at zero; see
    /// [`crate::volume::pose`]): turning the camera about its center by `exp([ε]×)` and
    /// moving it by `u`, world axes (radians, world units).
    pub pose: [f64; 6],
}

impl Gradients {
    /// All-zero gradients shaped for `gaussians`.
    pub fn zeros(gaussians: &Gaussians) -> Gradients {
        let mut g = Gradients::default();
        g.reset(gaussians);
        g
    }

    /// Resizes to `gaussians` and sets every entry to zero (reusing the buffers).
    pub fn reset(&mut self, gaussians: &Gaussians) {
        let n = gaussians.len();
        let k3 = 3 * gaussians.coeffs_per_channel();
        fn zero<T: Copy + Send>(v: &mut Vec<T>, n: usize, z: T) {
            v.clear();
            v.resize(n, z);
        }
        zero(&mut self.means, n, [0.0; 3]);
        zero(&mut self.log_scales, n, [0.0; 3]);
        zero(&mut self.rotations, n, [0.0; 4]);
        zero(&mut self.logit_opacities, n, 0.0);
        zero(&mut self.sh, n * k3, 0.0);
        zero(&mut self.mean2d, n, [0.0; 2]);
        zero(&mut self.visible, n, false);
        self.pose = [0.0; 6];
    }
}

/// The gradient of a loss with respect to every parameter of `gaussians`, given
/// `d_rgb = ∂L/∂rendered.rgb` (same layout as [`Rendered::rgb`]), for the `rendered`
/// image that [`render`](super::render()) made of these Gaussians with this camera and
/// these settings. The background is a constant.
///
/// # Errors
/// If `d_rgb` is not one entry per pixel of `rendered`, or `rendered` does not come from
/// a model of this size seen by a camera of this size.
pub fn backward(
    gaussians: &Gaussians,
    camera: &Camera,
    settings: &RenderSettings,
    rendered: &Rendered,
    d_rgb: &[[f32; 3]],
) -> Result<Gradients, String> {
    let mut out = Gradients::default();
    backward_into(gaussians, camera, settings, rendered, d_rgb, &mut out)?;
    Ok(out)
}

/// [`backward`] into `out`, which is reset first (its buffers are reused: a training loop
/// allocates them once).
///
/// # Errors
/// As [`backward`].
pub fn backward_into(
    gaussians: &Gaussians,
    camera: &Camera,
    settings: &RenderSettings,
    rendered: &Rendered,
    d_rgb: &[[f32; 3]],
    out: &mut Gradients,
) -> Result<(), String> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    if (rendered.width, rendered.height) != (camera.width, camera.height) {
        return Err(format!(
            "backward: the rendering is {}×{} but the camera {}×{}",
            rendered.width, rendered.height, camera.width, camera.height
        ));
    }
    if d_rgb.len() != w * h {
        return Err(format!(
            "backward: {} image gradient entries for {}×{} pixels",
            d_rgb.len(),
            w,
            h
        ));
    }
    if rendered
        .projected
        .last()
        .is_some_and(|p| p.index as usize >= gaussians.len())
    {
        return Err("backward: the rendering comes from a larger model".into());
    }
    let per_splat = pixel_backward(rendered, d_rgb, settings, w, h);
    out.reset(gaussians);
    let cam = Pinhole::new(camera, settings);
    let k3 = 3 * gaussians.coeffs_per_channel();
    let per_gaussian: Vec<Param> = rendered
        .projected
        .par_iter()
        .zip(&per_splat)
        .map(|(p, g)| projection_backward(gaussians, &cam, p, g))
        .collect();
    for (p, (g, acc)) in rendered
        .projected
        .iter()
        .zip(per_gaussian.into_iter().zip(&per_splat))
    {
        let i = p.index as usize;
        out.means[i] = g.mean.to_array();
        out.log_scales[i] = g.log_scale.to_array();
        out.rotations[i] = g.rotation;
        out.logit_opacities[i] = g.logit;
        out.sh[i * k3..(i + 1) * k3].copy_from_slice(&g.sh[..k3]);
        out.mean2d[i] = [acc[0], acc[1]];
        out.visible[i] = true;
        for (acc, v) in out.pose.iter_mut().zip(g.pose) {
            *acc += v as f64;
        }
    }
    Ok(())
}

/// Steps 1 and 2: per projected splat, the summed [`PairGrad`] over every pixel.
fn pixel_backward(
    rendered: &Rendered,
    d_rgb: &[[f32; 3]],
    settings: &RenderSettings,
    w: usize,
    h: usize,
) -> Vec<PairGrad> {
    let bins = &rendered.bins;
    let projected = &rendered.projected;
    let bg = Vec3::from_array(settings.background);
    let n_tiles = bins.tiles_x as usize * bins.tiles_y as usize;
    let mut sums = vec![[0.0f32; 9]; projected.len()];
    let mut start = 0;
    while start < n_tiles {
        // The next chunk: tiles until CHUNK_PAIRS pairs (at least one tile).
        let mut end = start + 1;
        while end < n_tiles && bins.offsets[end + 1] - bins.offsets[start] <= CHUNK_PAIRS {
            end += 1;
        }
        let chunk: Vec<Vec<PairGrad>> = (start..end)
            .into_par_iter()
            .map(|t| {
                let list = &bins.ids[bins.offsets[t]..bins.offsets[t + 1]];
                tile_backward(rendered, d_rgb, bg, list, tile_pixels(t, bins, w, h), w)
            })
            .collect();
        for (t, grads) in (start..end).zip(chunk) {
            let list = &bins.ids[bins.offsets[t]..bins.offsets[t + 1]];
            for (&id, g) in list.iter().zip(&grads) {
                let s = &mut sums[id as usize];
                for k in 0..9 {
                    s[k] += g[k];
                }
            }
        }
        start = end;
    }
    sums
}

/// The back-to-front pass over one tile's pixels: per entry of `list`, the sum over the
/// tile's pixels of that splat's [`PairGrad`]. Splat by splat, like the forward
/// ([`blend_tile`](super::render)), with per-pixel state and branch-free loops over rows of
/// [`TILE`] pixels; sums over a splat's pixels are taken lane by lane and then in lane
/// order, so they do not depend on the thread count.
fn tile_backward(
    rendered: &Rendered,
    d_rgb: &[[f32; 3]],
    bg: Vec3,
    list: &[u32],
    (x0, x1, y0, y1): (usize, usize, usize, usize),
    w: usize,
) -> Vec<PairGrad> {
    const T: usize = TILE as usize;
    let mut acc = vec![[0.0f32; 9]; list.len()];
    let blank = GradRow {
        d: [[f32x8::ZERO; HALVES]; 3],
        t: [f32x8::ZERO; HALVES],
        behind: [[f32x8::ZERO; HALVES]; 3],
        end: [i32x8::ZERO; HALVES],
    };
    let mut state = [blank; T];
    let mut last = 0usize;
    for y in y0..y1 {
        let row = &mut state[y - y0];
        let mut end = [0i32; T];
        for x in x0..x1 {
            let (i, c) = (y * w + x, x - x0);
            let t = rendered.transmittance[i];
            set_lane(&mut row.t, c, t);
            for ch in 0..3 {
                set_lane(&mut row.d[ch], c, d_rgb[i][ch]);
                set_lane(&mut row.behind[ch], c, t * bg[ch]);
            }
            end[c] = rendered.ends[i] as i32;
            last = last.max(rendered.ends[i] as usize);
        }
        row.end = [0, 1].map(|h| i32x8::new(end[8 * h..8 * h + 8].try_into().unwrap()));
    }
    let rows = y1 - y0;
    for k in (0..last).rev() {
        let p: &Projected = &rendered.projected[list[k] as usize];
        let (r0, r1) = splat_rows(p, y0, rows);
        let left = p.mean2d.x - x0 as f32;
        let mut lanes = [[f32x8::ZERO; HALVES]; 9];
        for (r, row) in state.iter_mut().enumerate().take(r1).skip(r0) {
            let dy = (y0 + r) as f32 + 0.5 - p.mean2d.y;
            grad_row(row, &mut lanes, p, left, dy, k as i32);
        }
        acc[k] = lanes.map(|l| lane_sum(&l));
    }
    acc
}

/// One Gaussian's parameter gradients (SH padded to degree 3).
struct Param {
    mean: Vec3,
    log_scale: Vec3,
    rotation: [f32; 4],
    logit: f32,
    sh: [f32; 48],
    /// This Gaussian's share of [`Gradients::pose`].
    pose: [f32; 6],
}

/// Step 3 for one projected Gaussian, given its summed [`PairGrad`].
fn projection_backward(gaussians: &Gaussians, cam: &Pinhole, p: &Projected, g: &PairGrad) -> Param {
    let i = p.index as usize;
    let geo = cam
        .geometry(gaussians, i)
        .expect("a projected Gaussian projects again the same way");
    let mean = Vec3::from_array(gaussians.means[i]);
    let mut d_mean = Vec3::ZERO;

    // Color: c = max(0, Σ_k sh_k·Y_k(dir) + 0.5) per channel, dir = normalize(mean − eye).
    let k = gaussians.coeffs_per_channel();
    let coeffs = &gaussians.sh[3 * k * i..3 * k * (i + 1)];
    let view = mean - cam.origin;
    let len = view.length();
    let dir = view / len;
    let basis = sh::basis(gaussians.sh_degree, dir);
    let mut sh_grad = [0.0f32; 48];
    let mut d_dir = Vec3::ZERO;
    let grad_basis = sh::basis_gradient(gaussians.sh_degree, dir);
    for c in 0..3 {
        let ch = &coeffs[c * k..(c + 1) * k];
        let raw: f32 = ch.iter().zip(&basis).map(|(a, b)| a * b).sum::<f32>() + 0.5;
        if raw <= 0.0 {
            continue;
        }
        let dc = g[6 + c];
        for j in 0..k {
            sh_grad[c * k + j] = dc * basis[j];
            d_dir += (dc * ch[j]) * grad_basis[j];
        }
    }
    // dir = v/|v|: ∂dir/∂v = (I − dir·dirᵀ)/|v|.
    d_mean += (d_dir - dir * dir.dot(d_dir)) / len;

    // Opacity through the sigmoid (and the anti-aliasing factor, 1 when off).
    let o = gaussians.opacity(i);
    let comp = p.compensation;
    let logit = g[5] * comp * o * (1.0 - o);

    // Conic Q = Σ'⁻¹ → Σ' (matrix gradients with independent entries; the stored b is
    // both off-diagonal entries).
    let [qa, qb, qc] = p.conic;
    let q = Mat2::from_cols_array(&[qa, qb, qb, qc]);
    let gq = Mat2::from_cols_array(&[g[2], 0.5 * g[3], 0.5 * g[3], g[4]]);
    let gs = -(q * gq * q);
    let (mut da, mut db, mut dc) = (gs.x_axis.x, gs.y_axis.x + gs.x_axis.y, gs.y_axis.y);
    // The anti-aliasing factor k = √(det₀/det), det₀ of the covariance before the
    // dilation s and det after it: ∂ln k/∂a = ½(c₀/det₀ − c/det), ∂ln k/∂c =
    // ½(a₀/det₀ − a/det), ∂ln k/∂b = b·(1/det − 1/det₀) (a₀ = a − s, c₀ = c − s).
    if gaussians.antialiased && comp > 0.0 {
        let [a, b, c] = geo.abc;
        let (a0, c0) = (a - cam.dilation, c - cam.dilation);
        let (det, det0) = (a * c - b * b, a0 * c0 - b * b);
        let d_log = g[5] * o * comp;
        da += 0.5 * d_log * (c0 / det0 - c / det);
        dc += 0.5 * d_log * (a0 / det0 - a / det);
        db += d_log * b * (1.0 / det - 1.0 / det0);
    }
    // a = j0ᵀCj0, b = j0ᵀCj1, c = j1ᵀCj1 (C symmetric).
    let (j0, j1, cov) = (geo.j0, geo.j1, geo.cov);
    let g_cov = outer(j0, j0) * da + outer(j0, j1) * db + outer(j1, j1) * dc;
    let d_j0 = cov * j0 * (2.0 * da) + cov * j1 * db;
    let d_j1 = cov * j1 * (2.0 * dc) + cov * j0 * db;

    // The Jacobian j0 = (fx/z, 0, −fx·ux/z), j1 = (0, fy/z, −fy·uy/z), u = clamped p.xy/z.
    let pc = geo.p;
    let z = pc.z;
    let (fx, fy) = (cam.fx, cam.fy);
    let mut d_p = Vec3::ZERO;
    d_p.z += -d_j0.x * fx / (z * z) + d_j0.z * fx * geo.u.x / (z * z);
    d_p.z += -d_j1.y * fy / (z * z) + d_j1.z * fy * geo.u.y / (z * z);
    let du = Vec2::new(-d_j0.z * fx / z, -d_j1.z * fy / z);
    if geo.inside.0 {
        d_p.x += du.x / z;
        d_p.z -= du.x * pc.x / (z * z);
    }
    if geo.inside.1 {
        d_p.y += du.y / z;
        d_p.z -= du.y * pc.y / (z * z);
    }
    // The projected center (fx·x/z + cx, fy·y/z + cy).
    let (dmx, dmy) = (g[0], g[1]);
    d_p.x += dmx * fx / z;
    d_p.y += dmy * fy / z;
    d_p.z -= (dmx * fx * pc.x + dmy * fy * pc.y) / (z * z);
    // p = W·mean + t.
    let d_projected = cam.rot.transpose() * d_p;
    d_mean += d_projected;

    // C = W·Σ·Wᵀ, Σ = M·Mᵀ, M = R·diag(s).
    let g_sigma = cam.rot.transpose() * g_cov * cam.rot;
    // The camera turned by exp([ε]×) about its center sees the world turned by
    // exp(−[ε]×) about it: r = mean − origin moves by −ε × r, Σ by Σ[ε]× − [ε]×Σ (the
    // view direction of the colors does not change). Moving it by u moves every mean
    // by −u relative to it, the colors' view direction included.
    let sigma = geo.m * geo.m.transpose();
    let r = mean - cam.origin;
    let mut d_eps = d_projected.cross(r);
    for a in 0..3 {
        let e = crate::volume::pose::skew(Vec3::AXES[a]);
        d_eps[a] += frobenius(g_sigma, sigma * e - e * sigma);
    }
    let pose = [d_eps.x, d_eps.y, d_eps.z, -d_mean.x, -d_mean.y, -d_mean.z];
    let g_m = (g_sigma + g_sigma.transpose()) * geo.m;
    let scale = gaussians.scale(i);
    let r = Mat3::from_quat(gaussians.rotation(i));
    let g_r = Mat3::from_cols(
        g_m.x_axis * scale.x,
        g_m.y_axis * scale.y,
        g_m.z_axis * scale.z,
    );
    let log_scale = Vec3::new(
        r.x_axis.dot(g_m.x_axis) * scale.x,
        r.y_axis.dot(g_m.y_axis) * scale.y,
        r.z_axis.dot(g_m.z_axis) * scale.z,
    );
    Param {
        mean: d_mean,
        log_scale,
        rotation: quaternion_backward(gaussians.rotations[i], g_r),
        logit,
        sh: sh_grad,
        pose,
    }
}

/// `Σ_ij a_ij·b_ij`.
fn frobenius(a: Mat3, b: Mat3) -> f32 {
    a.x_axis.dot(b.x_axis) + a.y_axis.dot(b.y_axis) + a.z_axis.dot(b.z_axis)
}

/// `a·bᵀ`.
fn outer(a: Vec3, b: Vec3) -> Mat3 {
    Mat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// ∂L/∂(stored quaternion `[w, x, y, z]`) from `g_r = ∂L/∂R` (entry `(row i, column j)`
/// at `g_r.col(j)[i]`), where `R` is the rotation of the normalized quaternion.
fn quaternion_backward(stored: [f32; 4], g_r: Mat3) -> [f32; 4] {
    let v = glam::Vec4::from_array(stored);
    let len = v.length();
    let [w, x, y, z] = (v / len).to_array();
    let e = |i: usize, j: usize| g_r.col(j)[i];
    let dw =
        2.0 * (-z * e(0, 1) + y * e(0, 2) + z * e(1, 0) - x * e(1, 2) - y * e(2, 0) + x * e(2, 1));
    let dx = 2.0
        * (y * e(0, 1) + z * e(0, 2) + y * e(1, 0) - 2.0 * x * e(1, 1) - w * e(1, 2)
            + z * e(2, 0)
            + w * e(2, 1)
            - 2.0 * x * e(2, 2));
    let dy = 2.0
        * (-2.0 * y * e(0, 0) + x * e(0, 1) + w * e(0, 2) + x * e(1, 0) + z * e(1, 2)
            - w * e(2, 0)
            + z * e(2, 1)
            - 2.0 * y * e(2, 2));
    let dz = 2.0
        * (-2.0 * z * e(0, 0) - w * e(0, 1) + x * e(0, 2) + w * e(1, 0) - 2.0 * z * e(1, 1)
            + y * e(1, 2)
            + x * e(2, 0)
            + y * e(2, 1));
    // Through q/|q|: (I − q̂q̂ᵀ)/|q|.
    let dn = glam::Vec4::new(dw, dx, dy, dz);
    let qn = v / len;
    ((dn - qn * qn.dot(dn)) / len).to_array()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::splat::render;
    use glam::Affine3A;

    /// A small camera with a narrow field, so Gaussians of world size ~1 cover it
    /// smoothly (no 1/255 cut-off inside the image, which finite differences would step
    /// across).
    fn camera() -> Camera {
        Camera::new(24, 20, 40.0, 40.0, 12.0, 10.0, Affine3A::IDENTITY).unwrap()
    }

    /// A deterministic stream in [0, 1).
    fn stream(seed: u64) -> impl FnMut() -> f32 {
        let mut s = seed | 1;
        move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// Three overlapping, anisotropic, rotated, half-transparent Gaussians of degree 3
    /// that cover the image (opacity below 0.99 and transmittance above 1e-4 everywhere).
    fn smooth_scene() -> Gaussians {
        let mut next = stream(7);
        let mut g = Gaussians::new(3);
        for k in 0..3 {
            let mean = [0.3 * k as f32 - 0.3, 0.2 - 0.15 * k as f32, -5.0 - k as f32];
            let ls = [0.9f32, 1.3, 1.6].map(|s| (s * (0.8 + 0.3 * next())).ln());
            let rot = [0.8 + next(), next() - 0.5, next() - 0.5, next() - 0.5];
            let sh: Vec<f32> = (0..48)
                .map(|j| {
                    if j % 16 == 0 {
                        0.6
                    } else {
                        0.2 * (next() - 0.5)
                    }
                })
                .collect();
            g.push(mean, ls, rot, -0.5 + 0.4 * k as f32, &sh);
        }
        g
    }

    /// `L = Σ wᵢ·rgbᵢ` in f64 with fixed weights, and those weights as `∂L/∂rgb`.
    fn weights(n: usize) -> Vec<[f32; 3]> {
        let mut next = stream(3);
        (0..n)
            .map(|_| [0.0; 3].map(|_: f32| next() - 0.5))
            .collect()
    }

    fn loss(g: &Gaussians, cam: &Camera, s: &RenderSettings, w: &[[f32; 3]]) -> f64 {
        let out = render(g, cam, s).unwrap();
        out.rgb
            .iter()
            .zip(w)
            .map(|(p, q)| (0..3).map(|c| p[c] as f64 * q[c] as f64).sum::<f64>())
            .sum()
    }

    /// Compares the analytic gradient of every parameter with central differences of the
    /// f32 forward (step `h`): relative error below 2 % of the group's largest gradient.
    #[test]
    fn every_parameter_group_matches_central_differences() {
        check_central_differences(smooth_scene());
    }

    /// A large Gaussian centered left of the frustum clamp (x/z beyond 1.3 half-fields)
    /// still reaches into the image; the clamped Jacobian's gradient is exact too.
    #[test]
    fn clamped_jacobian_matches_central_differences() {
        let mut g = smooth_scene();
        let sh: Vec<f32> = (0..48)
            .map(|j| if j % 16 == 0 { 0.3 } else { 0.0 })
            .collect();
        g.push(
            [-5.0, 0.1, -4.0],
            [1.4, 0.9, 1.2],
            [0.9, 0.2, 0.1, -0.3],
            -0.2,
            &sh,
        );
        let cam = camera();
        let p = Pinhole::new(&cam, &RenderSettings::default());
        let geo = p.geometry(&g, 3).unwrap();
        assert_eq!(
            geo.inside,
            (false, true),
            "the new Gaussian is clamped in x"
        );
        check_central_differences(g);
    }

    /// The same with anti-aliased splats: the gradient through the opacity factor
    /// `√(det Σ / det(Σ + s·I))` to the shape, the mean and the opacity. A large dilation
    /// (60 px² on splats of about 60 to 170 px² of variance) keeps the scene smooth for
    /// finite differences while the factor is far from 1.
    #[test]
    fn antialiased_splats_match_central_differences() {
        let mut g = smooth_scene();
        g.antialiased = true;
        let s = RenderSettings {
            dilation: 60.0,
            ..Default::default()
        };
        let out = render(&g, &camera(), &s).unwrap();
        let comps: Vec<f32> = out.projected.iter().map(|p| p.compensation).collect();
        assert!(
            comps.iter().all(|&k| k > 0.2 && k < 0.9),
            "factors {comps:?}"
        );
        check_central_differences_with(g, 60.0);
    }

    fn check_central_differences(g0: Gaussians) {
        check_central_differences_with(g0, RenderSettings::default().dilation);
    }

    fn check_central_differences_with(g0: Gaussians, dilation: f32) {
        let cam = camera();
        let s = RenderSettings {
            background: [0.2, 0.5, 0.9],
            dilation,
            ..Default::default()
        };
        let out = render(&g0, &cam, &s).unwrap();
        let (lo, hi) = out
            .transmittance
            .iter()
            .fold((1f32, 0f32), |(a, b), &t| (a.min(t), b.max(t)));
        assert!(lo > 0.05 && hi < 0.95, "transmittance in [{lo}, {hi}]");
        let w = weights(out.rgb.len());
        let grads = backward(&g0, &cam, &s, &out, &w).unwrap();
        assert!(grads.visible.iter().all(|&v| v));
        let h = 2e-3f32;
        type Getter = fn(&mut Gaussians) -> &mut [f32];
        let groups: [(&str, Getter, &[f32]); 5] = [
            (
                "means",
                |g| g.means.as_flattened_mut(),
                grads.means.as_flattened(),
            ),
            (
                "log_scales",
                |g| g.log_scales.as_flattened_mut(),
                grads.log_scales.as_flattened(),
            ),
            (
                "rotations",
                |g| g.rotations.as_flattened_mut(),
                grads.rotations.as_flattened(),
            ),
            (
                "logit_opacities",
                |g| &mut g.logit_opacities[..],
                &grads.logit_opacities,
            ),
            ("sh", |g| &mut g.sh[..], &grads.sh),
        ];
        for (name, get, analytic) in groups {
            let largest = analytic.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            assert!(largest > 1e-3, "{name}: gradient vanishes");
            let mut worst = 0.0f64;
            for j in 0..analytic.len() {
                let (mut plus, mut minus) = (g0.clone(), g0.clone());
                get(&mut plus)[j] += h;
                get(&mut minus)[j] -= h;
                let fd =
                    (loss(&plus, &cam, &s, &w) - loss(&minus, &cam, &s, &w)) / (2.0 * h as f64);
                let err = (fd - analytic[j] as f64).abs();
                worst = worst.max(err / largest as f64);
                assert!(
                    err <= 0.01 * largest as f64 + 1e-3 * fd.abs(),
                    "{name}[{j}]: analytic {} vs central difference {fd}",
                    analytic[j]
                );
            }
            eprintln!("{name}: largest |gradient| {largest:.4}, worst error {worst:.2e} of it");
        }
        check_pose_gradient(&g0, &cam, &s, &w, &grads);
    }

    /// [`Gradients::pose`] against central differences of the rendering by the camera
    /// with a small correction ([`crate::volume::pose::apply`]).
    fn check_pose_gradient(
        g: &Gaussians,
        cam: &Camera,
        s: &RenderSettings,
        w: &[[f32; 3]],
        grads: &Gradients,
    ) {
        let largest = grads.pose.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(largest > 1e-2, "pose gradient vanishes: {:?}", grads.pose);
        let h = 1e-3f32;
        for k in 0..6 {
            let (mut plus, mut minus) = ([0.0f32; 6], [0.0f32; 6]);
            plus[k] = h;
            minus[k] = -h;
            let fd = (loss(g, &crate::volume::pose::apply(cam, &plus), s, w)
                - loss(g, &crate::volume::pose::apply(cam, &minus), s, w))
                / (2.0 * h as f64);
            let an = grads.pose[k];
            assert!(
                (fd - an).abs() <= 0.01 * largest + 1e-3 * fd.abs(),
                "pose[{k}]: analytic {an} vs central difference {fd}"
            );
        }
    }

    /// The view-space gradient: moving a projected center by central differences (same
    /// tile lists) matches [`Gradients::mean2d`].
    #[test]
    fn projected_center_gradient_matches_central_differences() {
        let cam = camera();
        let s = RenderSettings::default();
        let g = smooth_scene();
        let out = render(&g, &cam, &s).unwrap();
        let w = weights(out.rgb.len());
        let grads = backward(&g, &cam, &s, &out, &w).unwrap();
        let h = 1e-2f32;
        let value = |projected: &[Projected]| -> f64 {
            let b = super::super::render::rasterize_for_tests(projected, &out.bins, &cam, &s);
            b.iter()
                .zip(&w)
                .map(|(p, q)| (0..3).map(|c| p[c] as f64 * q[c] as f64).sum::<f64>())
                .sum()
        };
        for k in 0..out.projected.len() {
            for axis in 0..2 {
                let (mut plus, mut minus) = (out.projected.clone(), out.projected.clone());
                plus[k].mean2d[axis] += h;
                minus[k].mean2d[axis] -= h;
                let fd = (value(&plus) - value(&minus)) / (2.0 * h as f64);
                let an = grads.mean2d[out.projected[k].index as usize][axis] as f64;
                assert!(
                    (fd - an).abs() < 0.02 * an.abs().max(1e-2),
                    "splat {k} axis {axis}: {an} vs {fd}"
                );
            }
        }
    }

    #[test]
    fn same_bits_for_any_thread_count() {
        let mut next = stream(11);
        let mut g = Gaussians::new(1);
        for _ in 0..400 {
            let mean = [next() * 2.0 - 1.0, next() * 2.0 - 1.0, -3.0 - 3.0 * next()];
            let ls = [0.0; 3].map(|_: f32| -3.0 + 1.5 * next());
            let rot = [next() + 0.1, next() - 0.5, next() - 0.5, next() - 0.5];
            let sh: Vec<f32> = (0..12).map(|_| next() - 0.5).collect();
            g.push(mean, ls, rot, 4.0 * next() - 1.0, &sh);
        }
        let cam = Camera::new(70, 50, 60.0, 60.0, 35.0, 25.0, Affine3A::IDENTITY).unwrap();
        let s = RenderSettings::default();
        let w = weights(70 * 50);
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let out = render(&g, &cam, &s).unwrap();
                backward(&g, &cam, &s, &out, &w).unwrap()
            })
        };
        let (one, two, three) = (run(1), run(2), run(3));
        let bits = |r: &Gradients| -> Vec<u32> {
            r.means
                .as_flattened()
                .iter()
                .chain(r.log_scales.as_flattened())
                .chain(r.rotations.as_flattened())
                .chain(&r.logit_opacities)
                .chain(&r.sh)
                .chain(r.mean2d.as_flattened())
                .map(|v| v.to_bits())
                .collect()
        };
        assert_eq!(bits(&one), bits(&two));
        assert_eq!(bits(&one), bits(&three));
        assert!(one.visible.iter().filter(|&&v| v).count() > 300);
        assert!(one.means.as_flattened().iter().any(|&v| v != 0.0));
    }

    #[test]
    fn mismatched_inputs_are_refused() {
        let cam = camera();
        let s = RenderSettings::default();
        let g = smooth_scene();
        let out = render(&g, &cam, &s).unwrap();
        let err = backward(&g, &cam, &s, &out, &weights(5)).unwrap_err();
        assert!(err.contains("5 image gradient entries"), "{err}");
        let small = Gaussians::new(3);
        assert!(backward(&small, &cam, &s, &out, &weights(480)).is_err());
    }
}

//! The photometric training loss of 3D Gaussian splatting and its exact gradient with
//! respect to the rendered image, as the reference training code computes it
//! (`utils/loss_utils.py` of Kerbl et al. 2023):
//!
//! `loss = (1 − λ)·L1 + λ·(1 − SSIM)`, with `λ = 0.2` in the reference.
//!
//! * **L1** is the mean of `|render − target|` over all pixels and the three channels;
//!   its gradient uses `sign`, which is `0` where the two are equal.
//! * **SSIM** is the *training* variant, which differs from the evaluation metric
//!   [`crate::volume::metrics::ssim`]: per channel, the 11 × 11 Gaussian window
//!   (σ = 1.5 pixels, separable, normalized) is applied with **"same" output size and
//!   zero padding** (PyTorch's `conv2d(…, padding = 5)`: pixels outside the image count
//!   as 0 in all five filtered maps `μx, μy, E[x²], E[y²], E[xy]`), the variances
//!   `σx² = E[x²] − μx²` and the covariance `σxy = E[xy] − μx·μy` are **not** clamped,
//!   and the map
//!   `((2μxμy + C1)(2σxy + C2)) / ((μx² + μy² + C1)(σx² + σy² + C2))`,
//!   `C1 = 0.01²`, `C2 = 0.03²`, is averaged over every pixel (borders included) and
//!   channel. Images smaller than the window keep the full 11 × 11 window.
//!
//! Images are `width × height` linear RGB, row-major with y down, values nominally in
//! `[0, 1]` and never clamped. Everything is computed in `f64`; the gradient is the
//! derivative of the `f64` value, rounded once to `f32` on output.
//!
//! **Cost and determinism.** The ten Gaussian filterings per channel (five forward, three
//! for the gradient, each a row pass then a column pass) run in parallel over image rows;
//! every output value is computed by exactly one job in a fixed order, and the sums
//! behind the reported values are taken per row, then over rows in order, so the result
//! is the same bits for any number of threads.

use rayon::prelude::*;

use crate::volume::metrics::{SSIM_C1, SSIM_C2, SSIM_SIGMA, SSIM_WINDOW, gaussian_kernel};

/// Half-width of the SSIM window, pixels (the zero padding on each side).
const RADIUS: usize = SSIM_WINDOW / 2;

/// Value of the training loss and its parts.
///
/// `value = (1 − λ)·l1 + λ·(1 − ssim)` for the `λ` it was computed with; `l1` is the mean
/// absolute error per channel (image units, `[0, 1]` for images in `[0, 1]`), `ssim` the
/// training SSIM (`1` for identical images, no units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PhotoLoss {
    pub value: f64,
    pub l1: f64,
    pub ssim: f64,
}

/// The 3DGS training loss `(1 − λ)·L1 + λ·(1 − SSIM)` of `render` against `target`, with
/// `λ = ssim_weight` (the reference uses 0.2), and its gradient (module doc for the exact
/// definitions).
///
/// `render` and `target` are `width × height` RGB images, row-major, y down, values
/// nominally in `[0, 1]` (not clamped). `grad` receives `∂loss/∂render` in the same
/// layout; it is overwritten, every entry. Only `render` is differentiated; `target` is a
/// constant. Empty images give `l1 = 0`, `ssim = 1`, `value = 0`.
///
/// Panics if a slice's length is not `width · height`.
pub(crate) fn photometric_loss(
    render: &[[f32; 3]],
    target: &[[f32; 3]],
    width: usize,
    height: usize,
    ssim_weight: f32,
    grad: &mut [[f32; 3]],
) -> PhotoLoss {
    loss_and_grad(render, target, width, height, ssim_weight as f64, grad)
}

/// A channel value the loss reads and whose gradient it writes: `f32` for the API, `f64`
/// for the tests' finite differences.
trait Sample: Copy + Send + Sync {
    fn to_f64(self) -> f64;
    fn from_f64(v: f64) -> Self;
}

impl Sample for f32 {
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn from_f64(v: f64) -> Self {
        v as f32
    }
}

impl Sample for f64 {
    fn to_f64(self) -> f64 {
        self
    }
    fn from_f64(v: f64) -> Self {
        v
    }
}

/// [`photometric_loss`] for any [`Sample`] type, with `λ` in `f64`.
fn loss_and_grad<T: Sample>(
    render: &[[T; 3]],
    target: &[[T; 3]],
    w: usize,
    h: usize,
    lambda: f64,
    grad: &mut [[T; 3]],
) -> PhotoLoss {
    let n = w * h;
    assert_eq!(render.len(), n, "render is not width × height");
    assert_eq!(target.len(), n, "target is not width × height");
    assert_eq!(grad.len(), n, "grad is not width × height");
    if n == 0 {
        return PhotoLoss {
            value: 0.0,
            l1: 0.0,
            ssim: 1.0,
        };
    }
    let kernel = gaussian_kernel(SSIM_WINDOW, SSIM_SIGMA);
    // Every mean is over the 3n channel values.
    let inv = 1.0 / (3 * n) as f64;
    let l1_scale = (1.0 - lambda) * inv;
    // ∂loss/∂ssim_map(pixel) for every pixel and channel.
    let map_scale = -lambda * inv;

    // Row-interleaved buffers: row y holds its maps one after the other, each `w` long.
    // Forward: the five row-filtered maps x, y, x², y², xy; backward: the three
    // row-filtered gradient maps (the first 3n entries).
    let mut rows = vec![0.0f64; 5 * n];
    // Per-pixel ∂loss/∂μx, ∂loss/∂E[x²], ∂loss/∂E[xy].
    let mut dmaps = vec![0.0f64; 3 * n];
    let mut ssim_sum = 0.0;
    let mut l1_sum = 0.0;

    for c in 0..3 {
        // 1. Row pass of the five forward maps.
        rows.par_chunks_mut(5 * w).enumerate().for_each_init(
            || vec![0.0f64; w + 2 * RADIUS],
            |pad, (y, out)| {
                let xs = &render[y * w..(y + 1) * w];
                let ys = &target[y * w..(y + 1) * w];
                for (m, out) in out.chunks_exact_mut(w).enumerate() {
                    for (p, (a, b)) in pad[RADIUS..RADIUS + w].iter_mut().zip(xs.iter().zip(ys)) {
                        let (x, t) = (a[c].to_f64(), b[c].to_f64());
                        *p = match m {
                            0 => x,
                            1 => t,
                            2 => x * x,
                            3 => t * t,
                            _ => x * t,
                        };
                    }
                    row_filter(pad, &kernel, out);
                }
            },
        );

        // 2. Column pass, the SSIM map and its derivatives, row by row.
        let forward = &rows;
        let ssim_rows: Vec<f64> = dmaps
            .par_chunks_mut(3 * w)
            .enumerate()
            .map_init(
                || (vec![0.0f64; 5 * w], vec![0.0f64; 5 * w]),
                |(acc, zero), (y, d)| {
                    column_filter(forward, 5, w, h, y, &kernel, zero, acc);
                    let (mu_x, rest) = acc.split_at(w);
                    let (mu_y, rest) = rest.split_at(w);
                    let (e_xx, rest) = rest.split_at(w);
                    let (e_yy, e_xy) = rest.split_at(w);
                    let (d_mu, rest) = d.split_at_mut(w);
                    let (d_xx, d_xy) = rest.split_at_mut(w);
                    let mut sum = 0.0;
                    for i in 0..w {
                        let (mx, my) = (mu_x[i], mu_y[i]);
                        let var_x = e_xx[i] - mx * mx;
                        let var_y = e_yy[i] - my * my;
                        let cov = e_xy[i] - mx * my;
                        let a1 = 2.0 * mx * my + SSIM_C1;
                        let a2 = 2.0 * cov + SSIM_C2;
                        let b1 = mx * mx + my * my + SSIM_C1;
                        let b2 = var_x + var_y + SSIM_C2;
                        let inv_den = 1.0 / (b1 * b2);
                        let s = a1 * a2 * inv_den;
                        sum += s;
                        // ∂s/∂μx through a1 (2μy), a2 (−2μy), b1 (2μx) and b2 (−2μx);
                        // ∂s/∂E[x²] through b2; ∂s/∂E[xy] through a2.
                        let ds_mu =
                            2.0 * my * (a2 - a1) * inv_den - 2.0 * mx * s * (1.0 / b1 - 1.0 / b2);
                        let ds_xx = -s / b2;
                        let ds_xy = 2.0 * a1 * inv_den;
                        d_mu[i] = map_scale * ds_mu;
                        d_xx[i] = map_scale * ds_xx;
                        d_xy[i] = map_scale * ds_xy;
                    }
                    sum
                },
            )
            .collect();
        ssim_sum += ssim_rows.iter().fold(0.0, |a, b| a + b);

        // 3. Row pass of the three gradient maps (the filter is its own transpose: a
        //    symmetric kernel with the same zero padding).
        let backward = &mut rows[..3 * n];
        backward
            .par_chunks_mut(3 * w)
            .zip(dmaps.par_chunks(3 * w))
            .for_each_init(
                || vec![0.0f64; w + 2 * RADIUS],
                |pad, (out, d)| {
                    for (out, d) in out.chunks_exact_mut(w).zip(d.chunks_exact(w)) {
                        pad[RADIUS..RADIUS + w].copy_from_slice(d);
                        row_filter(pad, &kernel, out);
                    }
                },
            );

        // 4. Column pass, then ∂loss/∂x = F(dμ) + 2x·F(dxx) + y·F(dxy) plus the L1 term.
        let backward = &rows[..3 * n];
        let l1_rows: Vec<f64> = grad
            .par_chunks_mut(w)
            .enumerate()
            .map_init(
                || (vec![0.0f64; 3 * w], vec![0.0f64; 3 * w]),
                |(acc, zero), (y, g)| {
                    column_filter(backward, 3, w, h, y, &kernel, zero, acc);
                    let (f_mu, rest) = acc.split_at(w);
                    let (f_xx, f_xy) = rest.split_at(w);
                    let xs = &render[y * w..(y + 1) * w];
                    let ys = &target[y * w..(y + 1) * w];
                    let mut sum = 0.0;
                    for i in 0..w {
                        let (x, t) = (xs[i][c].to_f64(), ys[i][c].to_f64());
                        let diff = x - t;
                        sum += diff.abs();
                        let sign = if diff > 0.0 {
                            1.0
                        } else if diff < 0.0 {
                            -1.0
                        } else {
                            0.0
                        };
                        let v = l1_scale * sign + f_mu[i] + 2.0 * x * f_xx[i] + t * f_xy[i];
                        g[i][c] = T::from_f64(v);
                    }
                    sum
                },
            )
            .collect();
        l1_sum += l1_rows.iter().fold(0.0, |a, b| a + b);
    }

    let l1 = l1_sum * inv;
    let ssim = ssim_sum * inv;
    PhotoLoss {
        value: (1.0 - lambda) * l1 + lambda * (1.0 - ssim),
        l1,
        ssim,
    }
}

/// One row of the horizontal "same" correlation with `kernel`: `pad` is the row with
/// `RADIUS` zeros on each side (`out.len() + 2·RADIUS` long), `out` is overwritten.
///
/// The kernel is symmetric, so taps at `±d` are added before the multiplication:
/// `k[R]·p[0] + Σ_{d = R..1} k[R − d]·(p[−d] + p[+d])`, in that fixed order.
fn row_filter(pad: &[f64], kernel: &[f64], out: &mut [f64]) {
    let k: &[f64; SSIM_WINDOW] = kernel.try_into().expect("kernel of SSIM_WINDOW taps");
    for (o, win) in out.iter_mut().zip(pad.windows(SSIM_WINDOW)) {
        let mut s = k[RADIUS] * win[RADIUS];
        for j in 0..RADIUS {
            s += k[j] * (win[j] + win[SSIM_WINDOW - 1 - j]);
        }
        *o = s;
    }
}

/// Row `y` of the vertical "same" correlation with `kernel`, zero padded, of `maps`
/// row-interleaved maps (`src` row `r` is `src[r·maps·w .. (r + 1)·maps·w]`, image
/// height `h`), into `acc` (`maps · w`, overwritten). `zero` is a row of zeros
/// (`maps · w` long) standing in for rows outside the image. Same tap order as
/// [`row_filter`].
#[allow(clippy::too_many_arguments)]
fn column_filter(
    src: &[f64],
    maps: usize,
    w: usize,
    h: usize,
    y: usize,
    kernel: &[f64],
    zero: &[f64],
    acc: &mut [f64],
) {
    let stride = maps * w;
    // Source row y + j − RADIUS, or zeros outside [0, h).
    let row = |j: usize| match (y + j).checked_sub(RADIUS) {
        Some(r) if r < h => &src[r * stride..(r + 1) * stride],
        _ => zero,
    };
    let k: &[f64; SSIM_WINDOW] = kernel.try_into().expect("kernel of SSIM_WINDOW taps");
    for (a, &c) in acc.iter_mut().zip(row(RADIUS)) {
        *a = k[RADIUS] * c;
    }
    for j in 0..RADIUS {
        let (lo, hi) = (row(j), row(SSIM_WINDOW - 1 - j));
        for ((a, &l), &u) in acc.iter_mut().zip(lo).zip(hi) {
            *a += k[j] * (l + u);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values in `[0, 1)` from the crate's one seeded generator.
    fn noise(seed: u64) -> impl FnMut() -> f64 {
        let mut rng = crate::rng::Rng::new(seed);
        move || (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A random image pair whose channels differ by at least 0.05 everywhere, so that
    /// finite differences never cross the L1 kink.
    fn pair(w: usize, h: usize, seed: u64) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let mut rng = noise(seed);
        let render: Vec<[f64; 3]> = (0..w * h).map(|_| [rng(), rng(), rng()]).collect();
        let target: Vec<[f64; 3]> = render
            .iter()
            .map(|p| {
                p.map(|v| {
                    let t = rng();
                    if (t - v).abs() < 0.05 {
                        if v < 0.5 {
                            v + 0.05 + 0.2 * rng()
                        } else {
                            v - 0.05 - 0.2 * rng()
                        }
                    } else {
                        t
                    }
                })
            })
            .collect();
        (render, target)
    }

    fn to_f32(img: &[[f64; 3]]) -> Vec<[f32; 3]> {
        img.iter().map(|p| p.map(|v| v as f32)).collect()
    }

    /// Pixels (x, y, channel) to check: the four corners, points on each edge, points one
    /// pixel in and interior ones.
    fn samples(w: usize, h: usize) -> Vec<(usize, usize, usize)> {
        let mut s = vec![
            (0, 0, 0),
            (w - 1, 0, 1),
            (0, h - 1, 2),
            (w - 1, h - 1, 0),
            (w / 2, 0, 2),
            (0, h / 2, 1),
            (w - 1, h / 3, 2),
            (w / 3, h - 1, 0),
            (1, 1, 1),
            (w.saturating_sub(2), h.saturating_sub(2), 2),
            (w / 2, h / 2, 0),
            (w / 2 + 1, (h / 2).saturating_sub(1), 1),
            (4, 5, 2),
        ];
        s.retain(|&(x, y, _)| x < w && y < h);
        s
    }

    /// The loss value alone, from the f64 core.
    fn value64(r: &[[f64; 3]], t: &[[f64; 3]], w: usize, h: usize, lambda: f64) -> f64 {
        let mut g = vec![[0.0; 3]; w * h];
        loss_and_grad(r, t, w, h, lambda, &mut g).value
    }

    /// The analytic gradient of the f32 API against central differences of its value,
    /// taken with the perturbed render stored in f32 (the actual step is the difference
    /// of the two f32 values).
    #[test]
    fn f32_gradient_matches_central_differences() {
        let (w, h) = (17, 13);
        let (r64, t64) = pair(w, h, 7);
        let (render, target) = (to_f32(&r64), to_f32(&t64));
        for lambda in [0.2f32, 1.0] {
            let mut grad = vec![[f32::NAN; 3]; w * h];
            let base = photometric_loss(&render, &target, w, h, lambda, &mut grad);
            assert!(base.value.is_finite());
            assert!(grad.iter().flatten().all(|g| g.is_finite()));
            let mut scratch = vec![[0.0f32; 3]; w * h];
            for (x, y, c) in samples(w, h) {
                let i = y * w + x;
                let v = render[i][c];
                let (vp, vm) = (v + 1e-3, v - 1e-3);
                let mut r = render.clone();
                r[i][c] = vp;
                let lp = photometric_loss(&r, &target, w, h, lambda, &mut scratch).value;
                r[i][c] = vm;
                let lm = photometric_loss(&r, &target, w, h, lambda, &mut scratch).value;
                let fd = (lp - lm) / (vp as f64 - vm as f64);
                let an = grad[i][c] as f64;
                let err = (fd - an).abs();
                assert!(
                    err <= 1e-6 * an.abs().max(1e-3),
                    "λ = {lambda}, pixel ({x}, {y}) channel {c}: analytic {an:e}, FD {fd:e}"
                );
            }
        }
    }

    /// The f64 core against central differences, to a much tighter tolerance; several
    /// sizes, including images smaller than the window.
    #[test]
    fn f64_gradient_matches_central_differences() {
        for (w, h, seed) in [(17, 13, 3), (4, 3, 5), (1, 1, 9), (12, 2, 11)] {
            let (render, target) = pair(w, h, seed);
            for lambda in [0.2, 1.0, 0.0] {
                let mut grad = vec![[f64::NAN; 3]; w * h];
                loss_and_grad(&render, &target, w, h, lambda, &mut grad);
                for (x, y, c) in samples(w, h) {
                    let i = y * w + x;
                    let step = 1e-5;
                    let mut r = render.clone();
                    r[i][c] += step;
                    let lp = value64(&r, &target, w, h, lambda);
                    r[i][c] = render[i][c] - step;
                    let lm = value64(&r, &target, w, h, lambda);
                    let fd = (lp - lm) / (2.0 * step);
                    let an = grad[i][c];
                    let scale = an.abs().max(1.0 / (3 * w * h) as f64);
                    assert!(
                        (fd - an).abs() <= 1e-7 * scale,
                        "{w}×{h}, λ = {lambda}, pixel ({x}, {y}) channel {c}: \
                         analytic {an:e}, FD {fd:e}"
                    );
                }
            }
        }
    }

    #[test]
    fn identical_images_give_zero_loss_and_zero_gradient() {
        let (w, h) = (23, 19);
        let (render, _) = pair(w, h, 21);
        let img = to_f32(&render);
        let mut grad = vec![[f32::NAN; 3]; w * h];
        let loss = photometric_loss(&img, &img, w, h, 0.2, &mut grad);
        assert!((loss.ssim - 1.0).abs() < 1e-12, "{loss:?}");
        assert_eq!(loss.l1, 0.0);
        assert!(loss.value.abs() < 1e-12, "{loss:?}");
        // SSIM is at its maximum (and sign(0) = 0), so the gradient vanishes.
        let worst = grad.iter().flatten().fold(0.0f32, |m, g| m.max(g.abs()));
        assert!(worst < 1e-9, "largest gradient entry {worst:e}");
    }

    /// With λ = 0 the gradient is the L1 one alone: ±1/(3n), exactly 0 where equal.
    #[test]
    fn l1_gradient_is_a_sign_with_zero_at_equality() {
        let (w, h) = (9, 7);
        let (render, target) = pair(w, h, 13);
        let (render, mut target) = (to_f32(&render), to_f32(&target));
        target[10][1] = render[10][1];
        let mut grad = vec![[f32::NAN; 3]; w * h];
        let loss = photometric_loss(&render, &target, w, h, 0.0, &mut grad);
        let unit = (1.0 / (3 * w * h) as f64) as f32;
        for (i, (g, (r, t))) in grad.iter().zip(render.iter().zip(&target)).enumerate() {
            for c in 0..3 {
                let expected = if r[c] > t[c] {
                    unit
                } else if r[c] < t[c] {
                    -unit
                } else {
                    0.0
                };
                assert_eq!(g[c], expected, "pixel {i} channel {c}");
            }
        }
        assert_eq!(grad[10][1], 0.0);
        assert_eq!(loss.value, loss.l1);
    }

    /// The training SSIM by a direct loop over each 11 × 11 window, pixels outside the
    /// image taken as 0.
    fn naive_training_ssim(a: &[[f32; 3]], b: &[[f32; 3]], w: usize, h: usize) -> f64 {
        let k = gaussian_kernel(SSIM_WINDOW, SSIM_SIGMA);
        let r = RADIUS as isize;
        let mut total = 0.0;
        for c in 0..3 {
            for py in 0..h as isize {
                for px in 0..w as isize {
                    let (mut mx, mut my, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
                    for dy in -r..=r {
                        for dx in -r..=r {
                            let (qx, qy) = (px + dx, py + dy);
                            let inside = qx >= 0 && qy >= 0 && qx < w as isize && qy < h as isize;
                            let (x, y) = if inside {
                                let q = qy as usize * w + qx as usize;
                                (a[q][c] as f64, b[q][c] as f64)
                            } else {
                                (0.0, 0.0)
                            };
                            let wt = k[(dx + r) as usize] * k[(dy + r) as usize];
                            mx += wt * x;
                            my += wt * y;
                            sxx += wt * x * x;
                            syy += wt * y * y;
                            sxy += wt * x * y;
                        }
                    }
                    let (vx, vy, cv) = (sxx - mx * mx, syy - my * my, sxy - mx * my);
                    total += ((2.0 * mx * my + SSIM_C1) * (2.0 * cv + SSIM_C2))
                        / ((mx * mx + my * my + SSIM_C1) * (vx + vy + SSIM_C2));
                }
            }
        }
        total / (3 * w * h) as f64
    }

    #[test]
    fn training_ssim_matches_a_naive_implementation() {
        for (w, h, seed) in [(16, 12, 1), (4, 3, 2), (30, 7, 3)] {
            let (render, target) = pair(w, h, seed);
            let (render, target) = (to_f32(&render), to_f32(&target));
            let mut grad = vec![[0.0f32; 3]; w * h];
            let loss = photometric_loss(&render, &target, w, h, 0.2, &mut grad);
            let naive = naive_training_ssim(&render, &target, w, h);
            let lambda = 0.2f32 as f64;
            assert!(
                (loss.ssim - naive).abs() < 1e-12,
                "{w}×{h}: {} vs naive {naive}",
                loss.ssim
            );
            let l1: f64 = render
                .iter()
                .zip(&target)
                .flat_map(|(p, q)| (0..3).map(move |c| (p[c] as f64 - q[c] as f64).abs()))
                .sum::<f64>()
                / (3 * w * h) as f64;
            assert!((loss.l1 - l1).abs() < 1e-12);
            assert!((loss.value - ((1.0 - lambda) * l1 + lambda * (1.0 - naive))).abs() < 1e-12);
        }
    }

    #[test]
    fn same_bits_for_any_thread_count() {
        let (w, h) = (61, 47);
        let (render, target) = pair(w, h, 17);
        let (render, target) = (to_f32(&render), to_f32(&target));
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let mut grad = vec![[0.0f32; 3]; w * h];
                let loss = photometric_loss(&render, &target, w, h, 0.2, &mut grad);
                let bits: Vec<u32> = grad.iter().flatten().map(|g| g.to_bits()).collect();
                ([loss.value, loss.l1, loss.ssim].map(f64::to_bits), bits)
            })
        };
        let one = run(1);
        assert_eq!(one, run(3));
        assert_eq!(one, run(2));
    }

    #[test]
    fn images_smaller_than_the_window_stay_finite() {
        for (w, h) in [(4, 3), (1, 1), (1, 5), (7, 1)] {
            let (render, target) = pair(w, h, 31);
            let (render, target) = (to_f32(&render), to_f32(&target));
            let mut grad = vec![[f32::NAN; 3]; w * h];
            let loss = photometric_loss(&render, &target, w, h, 0.2, &mut grad);
            assert!(loss.value.is_finite() && loss.l1.is_finite() && loss.ssim.is_finite());
            assert!(loss.ssim <= 1.0, "{w}×{h}: {loss:?}");
            assert!(grad.iter().flatten().all(|g| g.is_finite()), "{w}×{h}");
            let naive = naive_training_ssim(&render, &target, w, h);
            assert!((loss.ssim - naive).abs() < 1e-12, "{w}×{h}");
        }
    }

    #[test]
    fn empty_images() {
        let mut grad: Vec<[f32; 3]> = Vec::new();
        let loss = photometric_loss(&[], &[], 0, 5, 0.2, &mut grad);
        assert_eq!(
            loss,
            PhotoLoss {
                value: 0.0,
                l1: 0.0,
                ssim: 1.0
            }
        );
    }
}

//! Image quality metrics for novel-view evaluation: PSNR and SSIM on RGB images with
//! values in `[0, 1]`, row-major `[f32; 3]` pixels (as in [`super::dataset::View`]).
//!
//! Both follow the usual NeRF evaluation code (e.g. mip-NeRF's `compute_ssim`): values are
//! not clamped, sums are in `f64`.
//!
//! ```
//! use diffsvg::volume::metrics::{psnr, ssim};
//! let a = vec![[0.5f32; 3]; 16 * 16];
//! let mut b = a.clone();
//! b[0] = [0.6; 3];
//! assert!((psnr(&a, &b) - 10.0 * (256.0 / 0.01f64).log10()).abs() < 1e-3);
//! assert_eq!(ssim(&a, &a, 16, 16), 1.0);
//! assert!(ssim(&a, &b, 16, 16) < 1.0);
//! ```

use rayon::prelude::*;

use crate::metrics::psnr_from_mse;

/// Side of the SSIM Gaussian window, pixels.
pub(crate) const SSIM_WINDOW: usize = 11;
/// Standard deviation of the SSIM Gaussian window, pixels.
pub(crate) const SSIM_SIGMA: f64 = 1.5;
/// SSIM stabilizer `C1 = (0.01 · L)²` with dynamic range `L = 1`.
pub(crate) const SSIM_C1: f64 = 0.01 * 0.01;
/// SSIM stabilizer `C2 = (0.03 · L)²` with dynamic range `L = 1`.
pub(crate) const SSIM_C2: f64 = 0.03 * 0.03;

/// Mean squared error over all pixels and the three channels, in `[0, 1]²` units; `0` for
/// empty images. Panics if the lengths differ.
pub fn mse(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    assert_eq!(a.len(), b.len(), "images differ in size");
    if a.is_empty() {
        return 0.0;
    }
    let sum: f64 = a
        .par_iter()
        .zip(b)
        .map(|(p, q)| {
            (0..3)
                .map(|c| {
                    let d = p[c] as f64 - q[c] as f64;
                    d * d
                })
                .sum::<f64>()
        })
        .sum();
    sum / (a.len() * 3) as f64
}

/// Peak signal-to-noise ratio in dB with peak 1: `10 · log10(1 / MSE)` over all pixels and
/// channels. Identical (or empty) images give `f64::INFINITY`, not a cap; callers that
/// average PSNRs over views should average finite values or report the infinity. Panics
/// if the lengths differ.
pub fn psnr(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    psnr_from_mse(mse(a, b))
}

/// Structural similarity (Wang et al. 2004) of two `width × height` RGB images in
/// `[0, 1]`: an 11×11 Gaussian window with σ = 1.5, `C1 = 0.01²`, `C2 = 0.03²`, computed
/// per channel over the *valid* region only (window centers at least 5 pixels from each
/// edge, no padding) and averaged over the valid pixels and the three channels. Variances
/// are clamped at 0 and the covariance at `±√(σa² σb²)`, as in mip-NeRF's evaluation.
///
/// Images smaller than 11 pixels on a side use the largest odd window that fits (same σ,
/// renormalized). Identical images give exactly 1 up to rounding. Panics if a slice's
/// length is not `width · height`.
pub fn ssim(a: &[[f32; 3]], b: &[[f32; 3]], width: usize, height: usize) -> f64 {
    assert_eq!(a.len(), width * height, "first image is not width × height");
    assert_eq!(
        b.len(),
        width * height,
        "second image is not width × height"
    );
    if width == 0 || height == 0 {
        return 1.0;
    }
    // The largest odd size ≤ min(11, width, height) (≥ 1 here).
    let size = (SSIM_WINDOW.min(width).min(height) - 1) | 1;
    let kernel = gaussian_kernel(size, SSIM_SIGMA);
    let (ow, oh) = (width + 1 - size, height + 1 - size);
    let per_channel: Vec<f64> = (0..3)
        .into_par_iter()
        .map(|c| {
            let x: Vec<f64> = a.iter().map(|p| p[c] as f64).collect();
            let y: Vec<f64> = b.iter().map(|p| p[c] as f64).collect();
            let xx: Vec<f64> = x.iter().map(|v| v * v).collect();
            let yy: Vec<f64> = y.iter().map(|v| v * v).collect();
            let xy: Vec<f64> = x.iter().zip(&y).map(|(p, q)| p * q).collect();
            let [mx, my, sxx, syy, sxy] =
                [&x, &y, &xx, &yy, &xy].map(|m| filter_valid(m, width, height, &kernel));
            let mut total = 0.0;
            for i in 0..ow * oh {
                let (mu_x, mu_y) = (mx[i], my[i]);
                let var_x = (sxx[i] - mu_x * mu_x).max(0.0);
                let var_y = (syy[i] - mu_y * mu_y).max(0.0);
                let lim = (var_x * var_y).sqrt();
                let cov = (sxy[i] - mu_x * mu_y).clamp(-lim, lim);
                let num = (2.0 * mu_x * mu_y + SSIM_C1) * (2.0 * cov + SSIM_C2);
                let den = (mu_x * mu_x + mu_y * mu_y + SSIM_C1) * (var_x + var_y + SSIM_C2);
                total += num / den;
            }
            total / (ow * oh) as f64
        })
        .collect();
    per_channel.iter().sum::<f64>() / 3.0
}

/// The normalized 1D Gaussian of odd length `size` and standard deviation `sigma`,
/// centered on the middle tap.
pub(crate) fn gaussian_kernel(size: usize, sigma: f64) -> Vec<f64> {
    let half = (size / 2) as f64;
    let k: Vec<f64> = (0..size)
        .map(|i| {
            let d = i as f64 - half;
            (-0.5 * d * d / (sigma * sigma)).exp()
        })
        .collect();
    let s: f64 = k.iter().sum();
    k.into_iter().map(|v| v / s).collect()
}

/// Separable "valid" correlation of a `w × h` image with `kernel` along both axes:
/// output `(w − n + 1) × (h − n + 1)`, row-major.
fn filter_valid(img: &[f64], w: usize, h: usize, kernel: &[f64]) -> Vec<f64> {
    let n = kernel.len();
    let (ow, oh) = (w + 1 - n, h + 1 - n);
    // Rows first: h × ow.
    let mut rows = vec![0.0; h * ow];
    for y in 0..h {
        let src = &img[y * w..(y + 1) * w];
        let dst = &mut rows[y * ow..(y + 1) * ow];
        for (x, d) in dst.iter_mut().enumerate() {
            *d = kernel.iter().zip(&src[x..x + n]).map(|(k, v)| k * v).sum();
        }
    }
    // Then columns: oh × ow.
    let mut out = vec![0.0; oh * ow];
    for y in 0..oh {
        let dst = &mut out[y * ow..(y + 1) * ow];
        for (j, k) in kernel.iter().enumerate() {
            let src = &rows[(y + j) * ow..(y + j + 1) * ow];
            for (d, v) in dst.iter_mut().zip(src) {
                *d += k * v;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values in `[0, 1)` from the crate's one seeded generator.
    fn noise(seed: u64) -> impl FnMut() -> f32 {
        let mut rng = crate::rng::Rng::new(seed);
        move || rng.uniform()
    }

    fn smooth_image(w: usize, h: usize) -> Vec<[f32; 3]> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                [
                    0.5 + 0.4 * (x * 0.3).sin() * (y * 0.2).cos(),
                    (x + y) / (w + h) as f32,
                    0.25 + 0.2 * (y * 0.5).sin(),
                ]
            })
            .collect()
    }

    /// Straightforward SSIM: a direct 2D window sum at every valid center.
    fn naive_ssim(a: &[[f32; 3]], b: &[[f32; 3]], w: usize, h: usize) -> f64 {
        let g: Vec<f64> = (0..11)
            .map(|i| (-((i as f64 - 5.0).powi(2)) / (2.0 * 1.5 * 1.5)).exp())
            .collect();
        let norm: f64 = g.iter().sum::<f64>().powi(2);
        let mut total = 0.0;
        let mut count = 0;
        for c in 0..3 {
            for cy in 5..h - 5 {
                for cx in 5..w - 5 {
                    let (mut mx, mut my, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
                    for j in 0..11 {
                        for i in 0..11 {
                            let wgt = g[i] * g[j] / norm;
                            let k = (cy + j - 5) * w + (cx + i - 5);
                            let (p, q) = (a[k][c] as f64, b[k][c] as f64);
                            mx += wgt * p;
                            my += wgt * q;
                            sxx += wgt * p * p;
                            syy += wgt * q * q;
                            sxy += wgt * p * q;
                        }
                    }
                    let (vx, vy, cv) = (sxx - mx * mx, syy - my * my, sxy - mx * my);
                    total += ((2.0 * mx * my + SSIM_C1) * (2.0 * cv + SSIM_C2))
                        / ((mx * mx + my * my + SSIM_C1) * (vx + vy + SSIM_C2));
                    count += 1;
                }
            }
        }
        total / count as f64
    }

    #[test]
    fn identical_images_give_infinite_psnr_and_unit_ssim() {
        let img = smooth_image(32, 24);
        assert_eq!(psnr(&img, &img), f64::INFINITY);
        assert!((ssim(&img, &img, 32, 24) - 1.0).abs() < 1e-12);
        assert_eq!(psnr(&[], &[]), f64::INFINITY);
    }

    #[test]
    fn psnr_of_a_known_error() {
        // Every channel off by 0.1: MSE = 0.01 → 20 dB.
        let a = vec![[0.2f32, 0.5, 0.9]; 10];
        let b: Vec<[f32; 3]> = a.iter().map(|p| p.map(|v| v - 0.1)).collect();
        assert!((psnr(&a, &b) - 20.0).abs() < 1e-4);
        // One channel of one of two pixels off by 1: MSE = 1/6.
        let a = vec![[0.0f32; 3]; 2];
        let mut b = a.clone();
        b[1][2] = 1.0;
        assert!((psnr(&a, &b) - 10.0 * 6f64.log10()).abs() < 1e-9);
    }

    #[test]
    fn ssim_of_constant_images_by_hand() {
        // Constant images: no variance, so SSIM = (2 μa μb + C1) / (μa² + μb² + C1).
        let (w, h) = (16, 13);
        let a = vec![[0.2f32, 0.5, 0.8]; w * h];
        let b = vec![[0.3f32, 0.5, 0.6]; w * h];
        let want: f64 = [(0.2f64, 0.3f64), (0.5, 0.5), (0.8, 0.6)]
            .iter()
            .map(|&(p, q)| {
                // The f32 values, as the images hold them.
                let (p, q) = (p as f32 as f64, q as f32 as f64);
                (2.0 * p * q + SSIM_C1) / (p * p + q * q + SSIM_C1)
            })
            .sum::<f64>()
            / 3.0;
        let got = ssim(&a, &b, w, h);
        assert!((got - want).abs() < 1e-9, "{got} vs {want}");
    }

    #[test]
    fn ssim_matches_a_naive_implementation() {
        let (w, h) = (23, 17);
        let a = smooth_image(w, h);
        let mut r = noise(7);
        let b: Vec<[f32; 3]> = a.iter().map(|p| p.map(|v| v + 0.2 * (r() - 0.5))).collect();
        let got = ssim(&a, &b, w, h);
        let want = naive_ssim(&a, &b, w, h);
        assert!((got - want).abs() < 1e-9, "{got} vs {want}");
        assert!(got < 0.99 && got > 0.0);
    }

    #[test]
    fn noise_lowers_ssim_and_psnr() {
        let (w, h) = (40, 30);
        let clean = smooth_image(w, h);
        let mut last = (1.0f64, f64::INFINITY);
        for amp in [0.02f32, 0.1, 0.3] {
            let mut r = noise(11);
            let noisy: Vec<[f32; 3]> = clean
                .iter()
                .map(|p| p.map(|v| v + amp * (r() - 0.5)))
                .collect();
            let s = ssim(&clean, &noisy, w, h);
            let p = psnr(&clean, &noisy);
            assert!(s < last.0 && p < last.1, "amp {amp}: ssim {s}, psnr {p}");
            last = (s, p);
        }
        assert!(last.0 < 0.7);
    }

    #[test]
    fn ssim_on_tiny_images_uses_a_smaller_window() {
        let a = smooth_image(6, 4);
        assert!((ssim(&a, &a, 6, 4) - 1.0).abs() < 1e-12);
        let b: Vec<[f32; 3]> = a.iter().map(|p| p.map(|v| 1.0 - v)).collect();
        assert!(ssim(&a, &b, 6, 4) < 0.9);
    }
}

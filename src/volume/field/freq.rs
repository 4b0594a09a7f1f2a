//! NeRF's positional encoding (Mildenhall et al. 2020): a point `x ∈ [0, 1]³` of the
//! model's box is mapped to `p = 2x − 1 ∈ [−1, 1]³` and encoded as
//! `γ(p) = (p, sin(2⁰πp), cos(2⁰πp), …, sin(2^{K−1}πp), cos(2^{K−1}πp))`,
//! `3 + 6K` values: `p` first, then per octave `k` the three sines and the three cosines.
//! It has no parameters; its backward ([`backward`]) gives `∂L/∂x` from `∂L/∂γ`.

use glam::Vec3;

/// Most octaves `K` (NeRF uses 10 for positions).
pub(crate) const MAX_OCTAVES: u32 = 16;

/// Encoded values of a point with `octaves` octaves, `3 + 6K`.
pub(crate) fn dim(octaves: u32) -> usize {
    3 + 6 * octaves as usize
}

/// Writes `γ(2x − 1)` ([`dim`] values) into `out`.
#[inline]
pub(crate) fn encode(octaves: u32, x: Vec3, out: &mut [f32]) {
    let p = x * 2.0 - Vec3::ONE;
    out[..3].copy_from_slice(&p.to_array());
    let mut f = std::f32::consts::PI;
    for k in 0..octaves as usize {
        let o = 3 + 6 * k;
        for a in 0..3 {
            let (s, c) = (f * p[a]).sin_cos();
            out[o + a] = s;
            out[o + 3 + a] = c;
        }
        f *= 2.0;
    }
}

/// `∂L/∂x` given `d = ∂L/∂γ` at `x` (the chain rule through `p = 2x − 1`).
#[cfg_attr(not(test), allow(dead_code))]
pub(crate) fn backward(octaves: u32, x: Vec3, d: &[f32]) -> Vec3 {
    let p = x * 2.0 - Vec3::ONE;
    let mut g = Vec3::from_slice(&d[..3]);
    let mut f = std::f32::consts::PI;
    for k in 0..octaves as usize {
        let o = 3 + 6 * k;
        for a in 0..3 {
            let (s, c) = (f * p[a]).sin_cos();
            g[a] += f * (c * d[o + a] - s * d[o + 3 + a]);
        }
        f *= 2.0;
    }
    2.0 * g
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Σ w·γ(x)` and its gradient with respect to `x`, against central differences of
    /// an f64 re-implementation.
    #[test]
    fn backward_matches_finite_differences() {
        let k = 6;
        let n = dim(k);
        let w: Vec<f32> = (0..n).map(|i| ((i * 37 % 11) as f32 - 5.0) / 5.0).collect();
        let f64_loss = |x: [f64; 3]| -> f64 {
            let p = x.map(|v| 2.0 * v - 1.0);
            let mut s: f64 = (0..3).map(|a| w[a] as f64 * p[a]).sum();
            for o in 0..k as usize {
                let f = std::f64::consts::PI * (1u64 << o) as f64;
                for a in 0..3 {
                    s += w[3 + 6 * o + a] as f64 * (f * p[a]).sin();
                    s += w[3 + 6 * o + 3 + a] as f64 * (f * p[a]).cos();
                }
            }
            s
        };
        for x in [
            Vec3::new(0.3, 0.71, 0.05),
            Vec3::new(0.9, 0.5, 0.333),
            Vec3::ZERO,
        ] {
            let mut out = vec![0.0; n];
            encode(k, x, &mut out);
            let xd = x.to_array().map(|v| v as f64);
            let fwd: f64 = out.iter().zip(&w).map(|(a, b)| (a * b) as f64).sum();
            assert!(
                (fwd - f64_loss(xd)).abs() < 1e-4,
                "{fwd} vs {}",
                f64_loss(xd)
            );
            let g = backward(k, x, &w);
            let h = 1e-6;
            for a in 0..3 {
                let (mut xp, mut xm) = (xd, xd);
                xp[a] += h;
                xm[a] -= h;
                let fd = (f64_loss(xp) - f64_loss(xm)) / (2.0 * h);
                assert!(
                    (fd - g[a] as f64).abs() < 1e-3 * (1.0 + fd.abs()),
                    "axis {a} at {x}: analytic {}, central difference {fd}",
                    g[a]
                );
            }
        }
    }
}

//! Per-image exposure compensation: a learned affine color transform applied to each
//! training view's rendering before the loss (as in the reference code's exposure
//! option and Hierarchical 3DGS), so that photos taken with different exposure or white
//! balance do not each pull the Gaussians' colors their own way. Held-out views are
//! rendered without it.
//!
//! A transform is 12 numbers, a 3 × 4 matrix stored row by row: output channel `i` is
//! `m[4i]·r + m[4i+1]·g + m[4i+2]·b + m[4i+3]` of the rendered linear RGB `(r, g, b)`
//! (composited over the background). [`IDENTITY`] leaves colors as they are.

/// The transform that changes nothing.
pub const IDENTITY: [f32; 12] = [
    1.0, 0.0, 0.0, 0.0, //
    0.0, 1.0, 0.0, 0.0, //
    0.0, 0.0, 1.0, 0.0,
];

/// `out[p] = M·rgb[p] + bias` per pixel (module doc); `out` is resized to `rgb`.
pub(crate) fn apply(m: &[f32; 12], rgb: &[[f32; 3]], out: &mut Vec<[f32; 3]>) {
    out.clear();
    out.extend(rgb.iter().map(|c| {
        std::array::from_fn(|i| {
            m[4 * i] * c[0] + m[4 * i + 1] * c[1] + m[4 * i + 2] * c[2] + m[4 * i + 3]
        })
    }));
}

/// The backward pass of [`apply`]: given `d_out = ∂L/∂out`, overwrites `d_rgb` with
/// `∂L/∂rgb = Mᵀ·d_out` per pixel and returns `∂L/∂m` (summed over pixels in f64).
///
/// # Panics
/// If the three slices differ in length.
pub(crate) fn backward(
    m: &[f32; 12],
    rgb: &[[f32; 3]],
    d_out: &[[f32; 3]],
    d_rgb: &mut [[f32; 3]],
) -> [f32; 12] {
    assert!(rgb.len() == d_out.len() && d_rgb.len() == d_out.len());
    let mut dm = [0.0f64; 12];
    for ((c, d), dr) in rgb.iter().zip(d_out).zip(d_rgb.iter_mut()) {
        for i in 0..3 {
            let di = d[i] as f64;
            dm[4 * i] += di * c[0] as f64;
            dm[4 * i + 1] += di * c[1] as f64;
            dm[4 * i + 2] += di * c[2] as f64;
            dm[4 * i + 3] += di;
        }
        *dr = std::array::from_fn(|j| m[j] * d[0] + m[4 + j] * d[1] + m[8 + j] * d[2]);
    }
    dm.map(|v| v as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_changes_nothing() {
        let rgb = vec![[0.1, 0.5, 0.9], [1.2, -0.1, 0.0]];
        let mut out = Vec::new();
        apply(&IDENTITY, &rgb, &mut out);
        assert_eq!(out, rgb);
    }

    /// Both gradients against central differences of `L = Σ w·apply(m, rgb)` in f64.
    #[test]
    fn gradients_match_central_differences() {
        let m = [
            1.1, 0.05, -0.02, 0.03, //
            -0.04, 0.9, 0.1, -0.05, //
            0.02, 0.03, 1.2, 0.01,
        ];
        let rgb: Vec<[f32; 3]> = (0..7)
            .map(|p| std::array::from_fn(|c| ((p * 3 + c) as f32 * 0.37).sin() * 0.5 + 0.5))
            .collect();
        let w: Vec<[f32; 3]> = (0..7)
            .map(|p| std::array::from_fn(|c| ((p * 5 + c) as f32 * 0.71).cos()))
            .collect();
        let loss = |m: &[f32; 12], rgb: &[[f32; 3]]| -> f64 {
            let mut out = Vec::new();
            apply(m, rgb, &mut out);
            out.iter()
                .zip(&w)
                .map(|(o, q)| (0..3).map(|c| o[c] as f64 * q[c] as f64).sum::<f64>())
                .sum()
        };
        let mut d_rgb = vec![[0.0; 3]; 7];
        let dm = backward(&m, &rgb, &w, &mut d_rgb);
        let h = 1e-2f32;
        for j in 0..12 {
            let (mut p, mut q) = (m, m);
            p[j] += h;
            q[j] -= h;
            let fd = (loss(&p, &rgb) - loss(&q, &rgb)) / (2.0 * h as f64);
            assert!(
                (fd - dm[j] as f64).abs() < 1e-4 * (1.0 + fd.abs()),
                "m[{j}]: {} vs {fd}",
                dm[j]
            );
        }
        for px in 0..7 {
            for c in 0..3 {
                let (mut p, mut q) = (rgb.clone(), rgb.clone());
                p[px][c] += h;
                q[px][c] -= h;
                let fd = (loss(&m, &p) - loss(&m, &q)) / (2.0 * h as f64);
                let an = d_rgb[px][c] as f64;
                assert!(
                    (fd - an).abs() < 1e-4 * (1.0 + fd.abs()),
                    "rgb[{px}][{c}]: {an} vs {fd}"
                );
            }
        }
        assert!(dm.iter().all(|v| v.abs() > 1e-3), "{dm:?}");
    }
}

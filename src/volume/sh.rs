//! Real spherical harmonics up to degree 3, the view-dependent color basis of the voxel
//! grid.
//!
//! Conventions: the usual real, orthonormal basis of computer graphics (the constants of
//! Sloan's "Stupid SH tricks", used by Plenoxels and 3D Gaussian splatting), with the
//! Condon–Shortley phase folded in (the odd-`m` functions carry a minus sign). Index
//! `l² + l + m` holds `Y_l^m`, so degree `d` uses the first `(d + 1)²` entries:
//!
//! | index | function |
//! |---|---|
//! | 0 | `0.282095` |
//! | 1, 2, 3 | `−0.488603·y`, `0.488603·z`, `−0.488603·x` |
//! | 4 … 8 | `1.092548·xy`, `−1.092548·yz`, `0.315392·(2z² − x² − y²)`, `−1.092548·xz`, `0.546274·(x² − y²)` |
//! | 9 … 15 | the seven cubic terms of [`basis`] |
//!
//! `∫ Y_i Y_j dω = δ_ij` over the unit sphere. A color channel is `Σ_i c_i · Y_i(dir)`: it is
//! linear in the coefficients `c_i`, so its gradient with respect to them is the basis
//! itself ([`basis`]), and no separate backward function is needed.

use glam::Vec3;

/// The highest supported degree.
pub(crate) const MAX_DEGREE: u32 = 3;

/// Number of basis functions (coefficients per color channel) of degree `degree`:
/// `(degree + 1)²`, so 1, 4, 9 or 16.
///
/// # Panics
/// If `degree > MAX_DEGREE`.
pub(crate) const fn coeff_count(degree: u32) -> usize {
    assert!(degree <= MAX_DEGREE, "spherical harmonics degree above 3");
    ((degree + 1) * (degree + 1)) as usize
}

const C0: f32 = 0.282_094_8;
const C1: f32 = 0.488_602_5;
const C2: [f32; 5] = [
    1.092_548_4,
    -1.092_548_4,
    0.315_391_57,
    -1.092_548_4,
    0.546_274_2,
];
const C3: [f32; 7] = [
    -0.590_043_6,
    2.890_611_4,
    -0.457_045_8,
    0.373_176_33,
    -0.457_045_8,
    1.445_305_7,
    -0.590_043_6,
];

/// The real spherical-harmonic basis of degree `degree` (0 to 3) at the unit direction
/// `dir` (world axes; the caller normalizes). Entries `0 .. coeff_count(degree)` are filled
/// in the order of the module table; the rest are 0.
///
/// This is also the gradient of `Σ_i c_i · Y_i(dir)` with respect to the coefficients.
///
/// # Panics
/// If `degree > MAX_DEGREE`.
pub(crate) fn basis(degree: u32, dir: Vec3) -> [f32; 16] {
    assert!(degree <= MAX_DEGREE, "spherical harmonics degree above 3");
    let mut b = [0.0f32; 16];
    b[0] = C0;
    if degree == 0 {
        return b;
    }
    let (x, y, z) = (dir.x, dir.y, dir.z);
    b[1] = -C1 * y;
    b[2] = C1 * z;
    b[3] = -C1 * x;
    if degree == 1 {
        return b;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, yz, xz) = (x * y, y * z, x * z);
    b[4] = C2[0] * xy;
    b[5] = C2[1] * yz;
    b[6] = C2[2] * (2.0 * zz - xx - yy);
    b[7] = C2[3] * xz;
    b[8] = C2[4] * (xx - yy);
    if degree == 2 {
        return b;
    }
    b[9] = C3[0] * y * (3.0 * xx - yy);
    b[10] = C3[1] * xy * z;
    b[11] = C3[2] * y * (4.0 * zz - xx - yy);
    b[12] = C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
    b[13] = C3[4] * x * (4.0 * zz - xx - yy);
    b[14] = C3[5] * z * (xx - yy);
    b[15] = C3[6] * x * (xx - 3.0 * yy);
    b
}

/// The partial derivatives `∂Y_i/∂(x, y, z)` of the basis of degree `degree` (0 to 3),
/// with `x, y, z` treated as independent (the caller applies the chain rule through its
/// normalization of the direction). Entries past `coeff_count(degree)` are zero.
///
/// # Panics
/// If `degree > MAX_DEGREE`.
pub(crate) fn basis_gradient(degree: u32, dir: Vec3) -> [Vec3; 16] {
    assert!(degree <= MAX_DEGREE, "spherical harmonics degree above 3");
    let mut g = [Vec3::ZERO; 16];
    if degree == 0 {
        return g;
    }
    let (x, y, z) = (dir.x, dir.y, dir.z);
    g[1] = Vec3::new(0.0, -C1, 0.0);
    g[2] = Vec3::new(0.0, 0.0, C1);
    g[3] = Vec3::new(-C1, 0.0, 0.0);
    if degree == 1 {
        return g;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    g[4] = C2[0] * Vec3::new(y, x, 0.0);
    g[5] = C2[1] * Vec3::new(0.0, z, y);
    g[6] = C2[2] * Vec3::new(-2.0 * x, -2.0 * y, 4.0 * z);
    g[7] = C2[3] * Vec3::new(z, 0.0, x);
    g[8] = C2[4] * Vec3::new(2.0 * x, -2.0 * y, 0.0);
    if degree == 2 {
        return g;
    }
    g[9] = C3[0] * Vec3::new(6.0 * x * y, 3.0 * xx - 3.0 * yy, 0.0);
    g[10] = C3[1] * Vec3::new(y * z, x * z, x * y);
    g[11] = C3[2] * Vec3::new(-2.0 * x * y, 4.0 * zz - xx - 3.0 * yy, 8.0 * y * z);
    g[12] = C3[3] * Vec3::new(-6.0 * x * z, -6.0 * y * z, 6.0 * zz - 3.0 * xx - 3.0 * yy);
    g[13] = C3[4] * Vec3::new(4.0 * zz - 3.0 * xx - yy, -2.0 * x * y, 8.0 * x * z);
    g[14] = C3[5] * Vec3::new(2.0 * x * z, -2.0 * y * z, xx - yy);
    g[15] = C3[6] * Vec3::new(3.0 * xx - 3.0 * yy, -6.0 * x * y, 0.0);
    g
}

/// `Σ_i coeffs[i] · Y_i(dir)` for the first `coeffs.len()` basis functions of degree
/// `degree` (one color channel before any activation).
///
/// # Panics
/// If `coeffs.len() != coeff_count(degree)`.
#[cfg(test)]
pub(crate) fn eval(degree: u32, coeffs: &[f32], dir: Vec3) -> f32 {
    assert_eq!(coeffs.len(), coeff_count(degree), "coefficient count");
    let b = basis(degree, dir);
    coeffs.iter().zip(b.iter()).map(|(c, y)| c * y).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coefficient_counts() {
        assert_eq!(
            [0, 1, 2, 3].map(coeff_count),
            [1, 4, 9, 16],
            "(d + 1)² coefficients"
        );
    }

    /// `∫ Y_i Y_j dω` by the midpoint rule in `(z, φ)` (area-uniform: `dω = dz dφ`) is the
    /// identity to quadrature accuracy.
    #[test]
    fn orthonormal_on_the_sphere() {
        let (nz, nphi) = (400usize, 800usize);
        let mut gram = [[0.0f64; 16]; 16];
        for iz in 0..nz {
            let z = -1.0 + (iz as f64 + 0.5) * 2.0 / nz as f64;
            let r = (1.0 - z * z).sqrt();
            for ip in 0..nphi {
                let phi = (ip as f64 + 0.5) * std::f64::consts::TAU / nphi as f64;
                let d = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                let b = basis(3, d);
                for i in 0..16 {
                    for j in 0..16 {
                        gram[i][j] += b[i] as f64 * b[j] as f64;
                    }
                }
            }
        }
        let dw = 2.0 / nz as f64 * std::f64::consts::TAU / nphi as f64;
        for (i, row) in gram.iter().enumerate() {
            for (j, g) in row.iter().enumerate() {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((g * dw - want).abs() < 1e-4, "<Y{i}, Y{j}> = {}", g * dw);
            }
        }
    }

    #[test]
    fn values_at_axis_directions() {
        let b = basis(3, Vec3::Z);
        let want_z = [
            0.282_094_8,
            0.0,
            0.488_602_5,
            0.0,
            0.0,
            0.0,
            0.630_783_1,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.746_352_7,
            0.0,
            0.0,
            0.0,
        ];
        for i in 0..16 {
            assert!((b[i] - want_z[i]).abs() < 1e-6, "Y{i}(+z) = {}", b[i]);
        }
        let b = basis(3, Vec3::X);
        assert!((b[3] + 0.488_602_5).abs() < 1e-6);
        assert!((b[6] + 0.315_391_57).abs() < 1e-6);
        assert!((b[8] - 0.546_274_2).abs() < 1e-6);
        assert!((b[15] + 0.590_043_6).abs() < 1e-6);
        let b = basis(3, -Vec3::Y);
        assert!((b[1] - 0.488_602_5).abs() < 1e-6);
        assert!(
            (b[9] + 0.590_043_6).abs() < 1e-6,
            "Y9(−y) = C3₀·(−1)·(0 − 1)"
        );
        // Lower degrees leave the tail zero and agree on the head.
        let d = Vec3::new(0.3, -0.5, 0.8).normalize();
        let (b1, b3) = (basis(1, d), basis(3, d));
        assert_eq!(&b1[..4], &b3[..4]);
        assert!(b1[4..].iter().all(|&v| v == 0.0));
    }

    /// The color is linear in the coefficients: its central difference in each
    /// coefficient equals the basis.
    #[test]
    fn gradient_is_the_basis() {
        let d = Vec3::new(-0.2, 0.7, 0.4).normalize();
        let c: Vec<f32> = (0..9).map(|i| 0.1 * i as f32 - 0.3).collect();
        let b = basis(2, d);
        for i in 0..9 {
            let (mut p, mut m) = (c.clone(), c.clone());
            p[i] += 0.01;
            m[i] -= 0.01;
            let fd = (eval(2, &p, d) - eval(2, &m, d)) / 0.02;
            assert!(
                (fd - b[i]).abs() < 1e-3,
                "coefficient {i}: {fd} vs {}",
                b[i]
            );
        }
    }

    /// Central differences of every basis function in x, y and z (off the unit sphere:
    /// the functions are polynomials) match [`basis_gradient`].
    #[test]
    fn basis_gradient_matches_central_differences() {
        let p = Vec3::new(0.3, -0.55, 0.7);
        let g = basis_gradient(3, p);
        let h = 1e-2f32;
        for axis in 0..3 {
            let mut e = Vec3::ZERO;
            e[axis] = h;
            let (bp, bm) = (basis(3, p + e), basis(3, p - e));
            for i in 0..16 {
                let fd = (bp[i] - bm[i]) / (2.0 * h);
                assert!(
                    (fd - g[i][axis]).abs() < 2e-4,
                    "∂Y{i}/∂axis {axis}: {fd} vs {}",
                    g[i][axis]
                );
            }
        }
        assert!(basis_gradient(0, p).iter().all(|v| *v == Vec3::ZERO));
        assert_eq!(basis_gradient(1, p)[..4], g[..4]);
        assert!(basis_gradient(2, p)[9..].iter().all(|v| *v == Vec3::ZERO));
    }
}

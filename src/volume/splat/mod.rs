//! 3D Gaussian splatting (Kerbl et al. 2023): the model, its PLY file and the forward
//! renderer ([`render()`], the [`render`](mod@render) module).
//!
//! [`Gaussians`] holds a cloud of anisotropic 3D Gaussians as parallel arrays, with every
//! parameter stored **before** its activation, as the reference implementation trains
//! and saves them; [`save`] and [`load`] read and write the binary PLY layout that
//! common Gaussian-splatting viewers read ([`ply`] module doc).
//!
//! Conventions are those of the rest of [`crate::volume`]: positions and scales in world
//! units (the units of the dataset's poses), world axes as given (no y or z flip), view
//! directions pointing away from the camera, colors linear RGB.
//!
//! ```
//! use diffsvg::volume::splat::{Gaussians, load, save};
//! let mut g = Gaussians::new(1);
//! let sh = [0.5; 12]; // 3 channels × 4 coefficients, channel-major
//! g.push([0.0, 0.0, 0.0], [-2.0; 3], [1.0, 0.0, 0.0, 0.0], 0.0, &sh);
//! g.push([1.0, -0.5, 2.0], [-1.0, -3.0, -2.0], [0.0, 0.0, 1.0, 0.0], 3.0, &sh);
//! let path = std::env::temp_dir().join(format!("diffsvg-doc-{}.ply", std::process::id()));
//! save(&g, &path).unwrap();
//! let back = load(&path).unwrap();
//! std::fs::remove_file(&path).ok();
//! assert_eq!(back, g);
//! assert!((back.opacity(1) - 0.952_574).abs() < 1e-6); // sigmoid(3)
//! ```

pub mod backward;
pub mod exposure;
mod kernel;
pub(crate) mod loss;
pub mod ply;
pub(crate) mod points;
pub mod render;
pub mod spz;
pub mod train;

pub use backward::{Gradients, backward, backward_into};
pub use ply::{load, save};
pub use points::PointCloud;
pub use render::{Depth, RenderSettings, Rendered, render};
pub use spz::{load_spz, save_spz};
pub use train::{
    Densify, Mcmc, TrainOptions, TrainOutcome, TrainStep, find_point_cloud, from_point_cloud,
    from_points, mcmc_start, random_init, train,
};

use glam::{Quat, Vec3};

use crate::volume::sh;

/// A cloud of 3D Gaussians, structure-of-arrays: Gaussian `i` is entry `i` of every
/// array (and entries `i·3K .. (i+1)·3K` of [`sh`](Self::sh), `K = (sh_degree + 1)²`).
///
/// Parameters are stored before activation:
///
/// * **position**: [`means`](Self::means), world units;
/// * **size**: [`log_scales`](Self::log_scales), the natural log of the standard
///   deviation along each local axis in world units; the scale is `exp` of it
///   ([`scale`](Self::scale));
/// * **orientation**: [`rotations`](Self::rotations), a quaternion `[w, x, y, z]`
///   rotating local axes into world axes, normalized on use ([`rotation`](Self::rotation)),
///   so it need only be non-zero; the covariance is `R·diag(scale)²·Rᵀ`;
/// * **opacity**: [`logit_opacities`](Self::logit_opacities); the peak opacity is its
///   sigmoid ([`opacity`](Self::opacity));
/// * **color**: [`sh`](Self::sh), real spherical-harmonic coefficients in the basis of
///   the voxel grid (Sloan's constants, Condon–Shortley phase, index `l² + l + m`). The
///   color seen along the unit view direction `d` (from the camera toward the Gaussian)
///   is `max(0, Σ_k c_k·Y_k(d) + 0.5)` per channel, as in the reference code
///   ([`color`](Self::color)).
///
/// **SH layout: channel-major**, as in the voxel grid file: per Gaussian the `K` red
/// coefficients, then the `K` green, then the `K` blue, so coefficient `k` of channel
/// `c` (0 red, 1 green, 2 blue) of Gaussian `i` is `sh[i·3K + c·K + k]`; `k = 0` is the
/// constant term (the PLY file's `f_dc`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gaussians {
    /// Centers, world units.
    pub means: Vec<[f32; 3]>,
    /// Natural logs of the standard deviations along the local axes, world units.
    pub log_scales: Vec<[f32; 3]>,
    /// Orientations as quaternions `[w, x, y, z]`, normalized on use (non-zero).
    pub rotations: Vec<[f32; 4]>,
    /// Opacities before the sigmoid.
    pub logit_opacities: Vec<f32>,
    /// SH color coefficients, `3·(sh_degree + 1)²` per Gaussian, channel-major (see the
    /// type doc).
    pub sh: Vec<f32>,
    /// SH degree, 0 to 3.
    pub sh_degree: u32,
    /// Anti-aliased splats (Mip-Splatting's 2D filter, gsplat's `antialiased` mode):
    /// every splat's opacity is multiplied by `√(det Σ / det(Σ + s·I))`, with `Σ` its
    /// projected 2D covariance and `s` the [dilation](render::RenderSettings::dilation)
    /// (0.3 px²), so that a splat dilated to about a pixel keeps its total weight and a
    /// model renders alike at other resolutions. A property of the model, not of the
    /// view: a model trained with it must be rendered with it, so it is saved in the
    /// PLY file (a `comment diffsvg antialiased` header line, which other readers skip).
    pub antialiased: bool,
}

impl Gaussians {
    /// An empty cloud with SH of degree `sh_degree`.
    ///
    /// # Panics
    /// If `sh_degree > 3`.
    pub fn new(sh_degree: u32) -> Self {
        assert!(sh_degree <= sh::MAX_DEGREE, "SH degree above 3");
        Gaussians {
            sh_degree,
            ..Default::default()
        }
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// Whether there are no Gaussians.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// SH coefficients per color channel, `(sh_degree + 1)²`: 1, 4, 9 or 16.
    ///
    /// # Panics
    /// If `sh_degree > 3`.
    pub fn coeffs_per_channel(&self) -> usize {
        sh::coeff_count(self.sh_degree)
    }

    /// Appends one Gaussian; parameters as in the type doc, `sh` channel-major with
    /// `3·(sh_degree + 1)²` entries.
    ///
    /// # Panics
    /// If `sh` has the wrong length (or `sh_degree > 3`).
    pub fn push(
        &mut self,
        mean: [f32; 3],
        log_scale: [f32; 3],
        rotation: [f32; 4],
        logit_opacity: f32,
        sh: &[f32],
    ) {
        assert_eq!(
            sh.len(),
            3 * self.coeffs_per_channel(),
            "SH coefficients of one Gaussian"
        );
        self.means.push(mean);
        self.log_scales.push(log_scale);
        self.rotations.push(rotation);
        self.logit_opacities.push(logit_opacity);
        self.sh.extend_from_slice(sh);
    }

    /// Checks that the degree is at most 3, that every array holds [`len`](Self::len)
    /// entries (`sh` three times `(sh_degree + 1)²` as many), that every value is finite
    /// and that no quaternion is zero. The error says which Gaussian and value.
    pub fn validate(&self) -> Result<(), String> {
        if self.sh_degree > sh::MAX_DEGREE {
            return Err(format!("SH degree {} above 3", self.sh_degree));
        }
        let n = self.len();
        let k3 = 3 * self.coeffs_per_channel();
        for (name, len, want) in [
            ("log_scales", self.log_scales.len(), n),
            ("rotations", self.rotations.len(), n),
            ("logit_opacities", self.logit_opacities.len(), n),
            ("sh", self.sh.len(), n * k3),
        ] {
            if len != want {
                return Err(format!(
                    "{len} entries in {name} for {n} Gaussians (expected {want})"
                ));
            }
        }
        for i in 0..n {
            let bad = |what: &str, vals: &[f32]| {
                vals.iter()
                    .find(|v| !v.is_finite())
                    .map(|v| format!("Gaussian {i}: {what} is {v}"))
            };
            let err = bad("mean", &self.means[i])
                .or_else(|| bad("log scale", &self.log_scales[i]))
                .or_else(|| bad("rotation", &self.rotations[i]))
                .or_else(|| bad("logit opacity", &[self.logit_opacities[i]]))
                .or_else(|| bad("SH coefficient", &self.sh[i * k3..(i + 1) * k3]));
            if let Some(e) = err {
                return Err(e);
            }
            if self.rotations[i].iter().all(|&v| v == 0.0) {
                return Err(format!("Gaussian {i}: rotation quaternion is zero"));
            }
        }
        Ok(())
    }

    /// Standard deviations of Gaussian `i` along its local axes, `exp(log_scale)`, world
    /// units.
    ///
    /// # Panics
    /// If `i >= len()`.
    pub fn scale(&self, i: usize) -> Vec3 {
        Vec3::from_array(self.log_scales[i].map(f32::exp))
    }

    /// Peak opacity of Gaussian `i`, `sigmoid(logit_opacity)`, in `[0, 1]`.
    ///
    /// # Panics
    /// If `i >= len()`.
    pub fn opacity(&self, i: usize) -> f32 {
        1.0 / (1.0 + (-self.logit_opacities[i]).exp())
    }

    /// Orientation of Gaussian `i` as a unit quaternion (local to world axes).
    ///
    /// # Panics
    /// If `i >= len()`.
    pub fn rotation(&self, i: usize) -> Quat {
        let [w, x, y, z] = self.rotations[i];
        Quat::from_xyzw(x, y, z, w).normalize()
    }

    /// Linear RGB of Gaussian `i` seen along the unit direction `dir` (from the camera
    /// toward the Gaussian, world axes): `max(0, SH · basis(dir) + 0.5)` per channel, as
    /// in the reference code (no upper clamp).
    ///
    /// # Panics
    /// If `i >= len()` or `sh_degree > 3`.
    pub fn color(&self, i: usize, dir: Vec3) -> Vec3 {
        let k = self.coeffs_per_channel();
        let basis = sh::basis(self.sh_degree, dir);
        let coeffs = &self.sh[3 * k * i..3 * k * (i + 1)];
        let channel = |c: usize| {
            let s: f32 = coeffs[c * k..(c + 1) * k]
                .iter()
                .zip(&basis)
                .map(|(a, b)| a * b)
                .sum();
            (s + 0.5).max(0.0)
        };
        Vec3::new(channel(0), channel(1), channel(2))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(degree: u32) -> Gaussians {
        let mut g = Gaussians::new(degree);
        let k3 = 3 * g.coeffs_per_channel();
        g.push(
            [1.0, 2.0, 3.0],
            [0.0; 3],
            [2.0, 0.0, 0.0, 0.0],
            0.0,
            &vec![0.0; k3],
        );
        g
    }

    #[test]
    fn activations() {
        let mut g = one(1);
        assert_eq!(g.scale(0), Vec3::ONE);
        assert_eq!(g.opacity(0), 0.5);
        assert_eq!(g.rotation(0), Quat::IDENTITY);
        assert_eq!(g.color(0, Vec3::Z), Vec3::splat(0.5));
        // Red DC only: 0.5 + C0·c; blue with a strongly negative DC clamps at 0.
        g.sh[0] = 1.0;
        g.sh[8] = -10.0;
        let c = g.color(0, Vec3::Z);
        assert!((c.x - (0.5 + 0.282_094_8)).abs() < 1e-6, "{c}");
        assert_eq!((c.y, c.z), (0.5, 0.0));
    }

    #[test]
    fn validate_names_the_problem() {
        assert_eq!(one(3).validate(), Ok(()));
        let mut g = one(0);
        g.rotations[0] = [0.0; 4];
        assert!(g.validate().unwrap_err().contains("zero"));
        let mut g = one(0);
        g.log_scales[0][1] = f32::NAN;
        assert!(
            g.validate()
                .unwrap_err()
                .contains("Gaussian 0: log scale is NaN")
        );
        let mut g = one(0);
        g.sh.push(0.0);
        assert!(g.validate().unwrap_err().contains("sh"));
        let mut g = one(0);
        g.sh_degree = 4;
        assert!(g.validate().unwrap_err().contains("degree 4"));
    }
}

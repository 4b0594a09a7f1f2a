//! 3D reconstruction by differentiable volume rendering: cameras and posed-photo datasets,
//! undistortion of photos into pinhole photos, spherical harmonics, image metrics, a
//! sparse voxel grid (Plenoxels) fitted to photos, and 3D Gaussians (splatting) with their
//! PLY file.
//!
//! Conventions: world units are those of the dataset's poses; camera-to-world poses follow
//! OpenGL/Blender (camera +X right, +Y up, looking down −Z); images are row-major with
//! y down and pixel `(x, y)` centered at `(x + 0.5, y + 0.5)`; colors are linear-in-file
//! RGB in `[0, 1]` (no gamma handling), already composited over the background.
//!
//! ```
//! use diffsvg::volume::camera::Camera;
//! use diffsvg::glam::{Affine3A, Vec3};
//! // A 4 × 3 camera at z = 2 looking down −z, 90° across.
//! let pose = Affine3A::from_translation(Vec3::new(0.0, 0.0, 2.0));
//! let cam = Camera::from_fov_x(4, 3, std::f32::consts::FRAC_PI_2, pose).unwrap();
//! let rays = cam.rays(); // one per pixel, row-major, through pixel centers
//! assert_eq!(rays.len(), 12);
//! assert!(rays.iter().all(|r| r.dir.z < 0.0 && (r.dir.length() - 1.0).abs() < 1e-6));
//! ```

pub mod camera;
pub mod colmap;
pub mod dataset;
pub mod depth;
pub mod field;
pub mod ladder;
pub mod metrics;
pub mod pose;

use glam::Vec3;

pub mod recon;
pub(crate) mod sh;
pub mod splat;
pub mod undistort;
pub mod view;
pub mod voxel;

/// A ray `origin + t · dir`, `t ≥ 0`, with `dir` of unit length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Start point, world units.
    pub origin: Vec3,
    /// Unit direction.
    pub dir: Vec3,
}

/// Refuses training rays and colors of different or zero counts, or a color that is not
/// finite: the check every ray-batch trainer (voxels, neural fields) starts with.
pub(crate) fn check_rays_and_colors(rays: &[Ray], colors: &[[f32; 3]]) -> Result<(), String> {
    if rays.is_empty() || rays.len() != colors.len() {
        return Err(format!(
            "{} rays and {} colors (need the same positive number)",
            rays.len(),
            colors.len()
        ));
    }
    if let Some(i) = colors.iter().position(|c| !c.iter().all(|v| v.is_finite())) {
        return Err(format!("color {i} is not finite: {:?}", colors[i]));
    }
    Ok(())
}

impl Ray {
    /// The point at distance `t` along the ray.
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

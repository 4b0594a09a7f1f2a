//! 3D reconstruction by differentiable volume rendering: cameras and posed-photo datasets,
//! spherical harmonics, image metrics, and a sparse voxel grid (Plenoxels) fitted to
//! photos.
//!
//! Conventions: world units are those of the dataset's poses; camera-to-world poses follow
//! OpenGL/Blender (camera +X right, +Y up, looking down −Z); images are row-major with
//! y down and pixel `(x, y)` centered at `(x + 0.5, y + 0.5)`; colors are linear-in-file
//! RGB in `[0, 1]` (no gamma handling), already composited over the background.

pub mod camera;
pub mod dataset;
pub mod metrics;

pub use glam::Vec3;

pub(crate) mod sh;
pub mod voxel;

/// A ray `origin + t · dir`, `t ≥ 0`, with `dir` of unit length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Start point, world units.
    pub origin: Vec3,
    /// Unit direction.
    pub dir: Vec3,
}

impl Ray {
    /// The point at distance `t` along the ray.
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

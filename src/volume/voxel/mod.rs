//! A sparse voxel grid of density and spherical-harmonic color (Plenoxels, Fridovich-Keil
//! et al. 2022), rendered and trained on the CPU.
//!
//! * [`Grid`]: the data model — an axis-aligned box cut into `res³` cells, density and SH
//!   coefficients at allocated cell corners, trilinear interpolation, coarse-to-fine
//!   resampling ([`Grid::upsample`]) and pruning ([`Grid::prune_by_weight`]).
//! * [`render_ray`], [`render_rays`]: front-to-back volume rendering with early
//!   termination and empty-space skipping; [`ray_backward`]: its analytic gradient;
//!   [`max_weights`]: per-slot rendering weights for pruning. The sampling and compositing
//!   conventions are in the [`render`] module doc.
//! * [`train`]: mini-batch fitting to posed pixels (MSE, Adam or RMSProp per parameter
//!   group from [`crate::optim`], total variation, coarse-to-fine with pruning).
//! * [`save`], [`load`]: a versioned little-endian binary format ([`io`] module doc).
//!
//! Units: world units for the box and ray parameters, density in 1 / world units, colors
//! linear RGB in `[0, 1]`; ray directions are unit vectors pointing away from the camera.
//!
//! **Speed.** Everything is `f32` on the CPU: rayon over rays, one gradient buffer per
//! thread (no locks or atomics per sample), a lazy sparse optimizer update of the touched
//! slots only, early ray termination, and empty-space skipping over blocks of 4³ cells
//! that have no vertex with positive density (Chebyshev distance field, so a ray jumps
//! whole empty regions); SH degree is a compile-time constant in the inner loops.
//!
//! **A measured recipe** (NeRF-synthetic lego, 100 training views at 200×200 = 4 M rays,
//! box `[−1.5, 1.5]³`, 2 cores): [`Grid::dense`] at 64³ with SH degree 2 and density 0.1,
//! [`TrainOptions::default`] with `upsample: vec![(300, 128)]` reached a mean PSNR of
//! 30.2 dB over 25 test views after 3000 iterations in 789 s. Learning rates of the
//! density above about 1 (in these world units) diverge; density TV (`1e-6`) lowered
//! lego to 27.0 dB but helps pruning on simple scenes; pruning at 1e-3 keeps most of a
//! 128³ grid on lego (haze in front of the white background), so a 256³ stage needs a
//! stronger pruning rule or regularizer than the defaults.
//!
//! ```
//! use diffsvg::glam::Vec3;
//! use diffsvg::volume::Ray;
//! use diffsvg::volume::voxel::{Grid, RenderSettings, render_ray};
//! let mut grid = Grid::dense(Vec3::splat(-1.0), Vec3::splat(1.0), 16, 1, 0.0);
//! grid.density_mut().fill(50.0); // an opaque gray cube
//! let ray = Ray { origin: Vec3::new(0.0, 0.0, 3.0), dir: Vec3::NEG_Z };
//! let c = render_ray(&grid, &ray, &RenderSettings::default());
//! assert!((c[0] - 0.5).abs() < 1e-2);
//! ```

mod grid;
pub mod io;
pub mod render;
pub(crate) mod train;

pub use grid::{Grid, MAX_RES};
pub use io::{load, save};
pub use render::{
    Grads, RenderSettings, max_weights, ray_backward, render_depth, render_ray, render_rays,
};
pub use train::{TrainOptions, TrainOutcome, TrainStep, train, train_with_poses};

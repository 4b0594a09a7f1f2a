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
//!   group, total variation, coarse-to-fine with pruning).
//! * [`save`], [`load`]: a versioned little-endian binary format ([`io`] module doc).
//!
//! Units: world units for the box and ray parameters, density in 1 / world units, colors
//! linear RGB in `[0, 1]`; ray directions are unit vectors pointing away from the camera.
//!
//! ```
//! use diffsvg::volume::{Ray, Vec3};
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
mod train;

pub use grid::{Grid, MAX_RES};
pub use io::{load, save};
pub use render::{Grads, RenderSettings, max_weights, ray_backward, render_ray, render_rays};
pub use train::{Optimizer, TrainOptions, TrainOutcome, TrainStep, train};

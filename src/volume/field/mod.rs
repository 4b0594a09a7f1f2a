//! Neural fields on the CPU: Instant-NGP's multiresolution hash encoding with a tiny MLP
//! (Müller et al. 2022), rendered and trained by the voxel grid's ray-marching and
//! compositing conventions.
//!
//! * [`Ngp`]: the model — a [`HashGrid`] (or, for the NeRF rung, NeRF's positional
//!   encoding: [`FieldKind`]) over an axis-aligned box, a density network
//!   (encoding → ReLU layers of [`NgpShape::width`] → raw density and geometry
//!   features; `σ = exp(min(raw, 15))`), a color network (geometry features and degree-3
//!   spherical harmonics of the view direction → ReLU layers → sigmoid RGB) and an
//!   occupancy grid of the cells that may hold density.
//! * [`render_ray`], [`render_rays`]: front-to-back compositing with early termination,
//!   skipping empty occupancy cells ([`render`] module doc).
//! * [`train`]: mini-batch fitting to posed pixels (MSE, Adam from [`crate::optim`],
//!   lazily on the touched hash entries; the occupancy grid refreshed as nerfacc does),
//!   with the same model bits on any number of threads.
//! * [`save`], [`load`]: a versioned little-endian file ([`io`] module doc).
//!
//! Units: world units for the box and ray parameters, density in 1 / world units, colors
//! linear RGB in `[0, 1]`; ray directions are unit vectors pointing away from the camera.

mod freq;
mod hash;
pub mod io;
mod mlp;
mod model;
pub mod render;
mod train;

pub use hash::{HashGrid, HashShape};
pub use io::{load, save};
pub use model::{FieldKind, Ngp, NgpShape};
pub use render::{RenderSettings, render_ray, render_rays};
pub use train::{TrainOptions, TrainOutcome, TrainStep, train};

#[cfg(test)]
mod tests;

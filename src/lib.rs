//! **diffsvg** recovers scenes by differentiable rendering: vector drawings (SVG) from
//! pictures in 2D, and voxel grids from posed photos in 3D.
//!
//! # The 2D corridor
//!
//! SVG in → [`Scene`] → [`raster::render`] → [`loss`] → [`raster::render_backward`] →
//! [`optim`] → SVG out. [`fit::refine`] runs that loop; [`fit::vectorize`],
//! [`fit::digit`] and [`fit::glyph`] build scenes from pictures with it.
//!
//! ```
//! use diffsvg::{Scene, Sizing, loss::Loss, raster};
//! let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="20" height="20">
//!   <rect x="5" y="5" width="10" height="10" fill="red"/></svg>"#;
//! let scene = Scene::from_svg_str(svg, "inline.svg", Sizing::Natural)?;
//! let opts = raster::RenderOptions::default();
//! let img = raster::render(&scene, &opts);
//! assert_eq!(img.get(10, 10), [1.0, 0.0, 0.0, 1.0]);
//!
//! // The gradient of a loss against a target, in the layout of `scene.params()`.
//! let target = diffsvg::Image::filled(20, 20, [0.0, 0.0, 1.0, 1.0]);
//! let (loss, d_img) = Loss::Mse.grad(&img, &target);
//! let grad = raster::render_backward(&scene, &opts, &d_img);
//! assert_eq!(grad.len(), scene.params().len());
//! assert!(loss > 0.0 && grad.iter().all(|g| g.is_finite()));
//!
//! // A per-pixel objective renders, scores and differentiates each row band at once
//! // (the fit loops' path): the same bits as the three steps above.
//! let objective = diffsvg::fit::Objective::new(&target, Loss::Mse, None, 1);
//! let prepared = raster::Prepared::new(&scene, &opts);
//! let (_img, fused_loss, _mse, fused_grad) = objective.render_and_backward(&scene, &prepared);
//! assert_eq!((fused_loss, &fused_grad), (loss, &grad));
//! # Ok::<(), diffsvg::Error>(())
//! ```
//!
//! # Contract
//!
//! * **Space.** Scenes live in device pixels of their canvas: x right, **y down**, origin
//!   at the top-left corner. Pixel `(i, j)` covers `[i, i+1] × [j, j+1]`; coverage is its
//!   exact box-filtered area and paints are evaluated at its center `(i + ½, j + ½)`.
//!   SVG transforms and the viewBox are baked in at load ([`scene`] says what keeps a
//!   matrix).
//! * **Color.** Scene colors are straight (not premultiplied) sRGB values in `[0, 1]`;
//!   every [`Image`] is premultiplied RGBA `f32` in `[0, 1]`, row-major, y down.
//!   Compositing is source-over in sRGB values, as browsers and resvg do.
//! * **Parameters.** [`Scene::params`] flattens every number the optimizer may move into
//!   one `f64` vector in a documented order ([`scene::ParamLayout`]); gradients and
//!   learning rates use the same layout.
//! * **Exactness and determinism.** Gradients are the exact derivatives of the rendered
//!   image (no sampling), checked against finite differences ([`gradcheck`]). Rendering,
//!   gradients and fitting give the same bits for any number of threads: work is split
//!   into row bands (2D) or tiles and slot blocks (3D) whose partial results are reduced
//!   in a fixed order.
//! * **Errors.** Fallible calls return [`Result`]; an [`Error`] names the file (or input)
//!   and the problem. Input that could make diffsvg allocate without bound is refused
//!   before anything is allocated ([`limits`]). Nothing panics on user input; files are
//!   written to a temporary name and renamed, never left half-written.
//! * **Features.** `cli` (default) builds the `diffsvg` binary and its crates; `trace`
//!   (default, implied by `cli`) adds vtracer's tracing to [`fit::vectorize`]. The library
//!   alone is `diffsvg = { default-features = false }`.
//!
//! # 3D
//!
//! [`volume`] reads posed photos (NeRF-synthetic and instant-ngp folders) into cameras
//! and rays, and fits a sparse voxel grid of density and spherical-harmonic color
//! ([`volume::voxel`]) through its exact volume-rendering gradient, with the same
//! [`optim`] module as the 2D fitter. [`volume::splat`] fits 3D Gaussians, rasterized by
//! tiles with a hand-written backward pass, and reads and writes them as the PLY files of
//! Gaussian-splatting viewers.

#![warn(unreachable_pub)]
// The library never prints: it returns errors and reports progress through callbacks;
// the command line (src/main.rs, src/cli/) and tests print.
#![cfg_attr(not(test), deny(clippy::print_stdout, clippy::print_stderr))]

pub mod choice;
mod error;
pub mod fit;
pub mod gradcheck;
mod guard;
pub mod image_io;
pub mod limits;
pub mod loss;
pub mod mesh;
pub mod metrics;
pub mod mnist;
pub mod optim;
pub mod raster;
#[cfg(feature = "reference")]
pub mod reference;
pub mod rng;
pub mod scene;
pub mod volume;

pub use error::{Error, Result};
/// The vector math of the 3D API (`Vec3`, `Affine3A` in cameras and rays), re-exported so
/// callers use the same version.
pub use glam;
pub use image_io::Image;
pub use scene::Sizing;
pub use scene::{Node, Path, Scene};
/// The SVG tree of [`scene::parse_tree`] and [`scene::from_tree`], re-exported so callers
/// use the same version.
pub use usvg;

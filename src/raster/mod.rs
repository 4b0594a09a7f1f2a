//! The analytic-coverage rasterizer.
//!
//! A [`Scene`](crate::scene::Scene) is first prepared: every path is
//! flattened at a tolerance, strokes become filled outline rings (`stroke`), dashes are
//! cut (`dash`) and paints are readied for evaluation (`paint`, images in `image`). [`render`] then
//! accumulates exact-area coverage (`coverage`) row band by row band in parallel,
//! evaluates paints at pixel centers and composites source-over in premultiplied `f32`.
//! Bands are independent and each is processed in a fixed order, so the result has the
//! same bits for any number of threads.
//!
//! ```
//! use diffsvg::{Scene, Sizing, raster};
//! let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="16" height="16">
//!   <rect x="4" y="4" width="8" height="8" fill="crimson"/></svg>"#;
//! let scene = Scene::from_svg_str(svg, "square.svg", Sizing::Natural)?;
//! let opts = raster::RenderOptions::default();
//! let img = raster::render(&scene, &opts); // premultiplied RGBA f32, 16 × 16
//! assert_eq!(img.get(0, 0)[3], 0.0);       // outside: transparent
//! assert_eq!(img.get(8, 8)[3], 1.0);       // inside: opaque
//!
//! // Prepared once, rendered and differentiated many times: ∂L/∂params for a given
//! // ∂L/∂image, in the layout of `scene.params()`.
//! let p = raster::Prepared::new(&scene, &opts);
//! let d_img = diffsvg::Image::filled(16, 16, [0.0, 0.0, 0.0, 1.0]);
//! let (grad, _stats) = raster::backward_with_stats(&scene, &p, &d_img);
//! assert_eq!(grad.len(), scene.params().len());
//! # Ok::<(), diffsvg::Error>(())
//! ```

pub(crate) mod backward;
pub(crate) mod coverage;
pub(crate) mod dash;
pub(crate) mod filter;
pub(crate) mod flatten;
pub(crate) mod image;
pub(crate) mod jet;
pub(crate) mod layer;
pub(crate) mod overlap;
pub(crate) mod paint;
pub(crate) mod pixmap;
pub(crate) mod prepare;
pub(crate) mod render;
pub(crate) mod stroke;
pub(crate) mod sweep;

pub(crate) use backward::backward_prepared;
pub use backward::{
    BackwardStats, BandLoss, Fused, backward_with_stats, check_backward_memory,
    render_and_backward, render_and_backward_fused, render_backward, render_backward_checked,
};
pub use pixmap::{Alpha, render_rgba8};
pub(crate) use prepare::prepare;
pub use prepare::{Prepared, warnings};
pub use render::{RenderOptions, render, render_prepared};

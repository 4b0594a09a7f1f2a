//! The analytic-coverage rasterizer.
//!
//! A [`Scene`](crate::scene::Scene) is first [prepared](prepare::prepare): every path is
//! flattened at a tolerance, strokes become filled outline rings ([`stroke`]), dashes are
//! cut ([`dash`]) and paints are readied for evaluation ([`paint`]). [`render`] then
//! accumulates exact-area coverage ([`coverage`]) row band by row band in parallel,
//! evaluates paints at pixel centers and composites source-over in premultiplied `f32`.
//! Bands are independent and each is processed in a fixed order, so the result has the
//! same bits for any number of threads.

pub mod backward;
pub mod coverage;
pub mod dash;
pub mod flatten;
pub mod jet;
pub mod paint;
pub mod prepare;
pub mod render;
pub mod stroke;

pub use backward::{
    BackwardStats, backward_prepared, backward_with_stats, render_and_backward, render_backward,
};
pub use prepare::{Prepared, prepare, prepare_forward, warnings};
pub use render::{RenderOptions, render, render_prepared};

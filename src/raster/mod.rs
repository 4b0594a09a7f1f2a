//! The analytic-coverage rasterizer.
//!
//! A [`Scene`](crate::scene::Scene) is first prepared: every path is
//! flattened at a tolerance, strokes become filled outline rings (`stroke`), dashes are
//! cut (`dash`) and paints are readied for evaluation (`paint`). [`render`] then
//! accumulates exact-area coverage (`coverage`) row band by row band in parallel,
//! evaluates paints at pixel centers and composites source-over in premultiplied `f32`.
//! Bands are independent and each is processed in a fixed order, so the result has the
//! same bits for any number of threads.

pub(crate) mod backward;
pub(crate) mod coverage;
pub(crate) mod dash;
pub(crate) mod flatten;
pub(crate) mod jet;
pub(crate) mod paint;
pub(crate) mod prepare;
pub(crate) mod render;
pub(crate) mod stroke;

pub(crate) use backward::backward_prepared;
pub use backward::{BackwardStats, backward_with_stats, render_and_backward, render_backward};
pub(crate) use prepare::prepare;
pub use prepare::{Prepared, warnings};
pub use render::{RenderOptions, render, render_prepared};

//! Fitting scenes to images: refinement of an existing SVG, vectorization from nothing,
//! classical tracing as a starting point, and speed-vs-error reports.

pub mod digit;
pub mod glyph;
pub(crate) mod refine;
pub(crate) mod shapes;
pub(crate) mod trace;
pub mod vectorize;

pub use refine::{Control, FitOptions, FitOutcome, Step, StopReason, refine};
pub use shapes::{random_blobs, random_strokes};
pub use trace::trace;

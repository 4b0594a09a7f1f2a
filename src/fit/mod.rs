//! Fitting scenes to images: refinement of an existing SVG, vectorization from nothing,
//! classical tracing as a starting point, and speed-vs-error reports.

pub mod digit;
pub mod glyph;
pub mod refine;
pub mod shapes;
pub mod trace;
pub mod vectorize;

pub use refine::{Control, FitOptions, FitOutcome, Step, StopReason, refine};

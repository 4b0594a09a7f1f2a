//! Fitting scenes to images: refinement of an existing SVG, vectorization from nothing,
//! classical tracing as a starting point, and speed-vs-error reports.
//!
//! ```
//! use diffsvg::fit::{Control, FitOptions, refine};
//! use diffsvg::{Scene, Sizing, fit::Objective, loss::Loss, raster};
//! let draw = |x: f64| {
//!     let svg = format!(r#"<svg xmlns="http://www.w3.org/2000/svg" width="24" height="24">
//!       <rect x="{x}" y="6" width="10" height="10" fill="navy"/></svg>"#);
//!     Scene::from_svg_str(&svg, "box.svg", Sizing::Natural)
//! };
//! let target = raster::render(&draw(8.0)?, &Default::default());
//! let objective = Objective::new(&target, Loss::Mse, Some([1.0; 4]), 1);
//! let opts = FitOptions { iters: 60, ..FitOptions::default() };
//! let out = refine(draw(5.0)?, &objective, &opts, &mut |_, _| Control::Continue);
//! assert!(out.best_psnr > out.history[0].psnr + 10.0);
//! # Ok::<(), diffsvg::Error>(())
//! ```

mod adam;
pub mod digit;
pub mod glyph;
pub mod job;
mod objective;
pub(crate) mod refine;
pub(crate) mod shapes;
pub(crate) mod trace;
pub mod vectorize;

pub use adam::{Adam, AdamConfig, LearningRates};
pub use job::{ObjectiveOptions, load_target, load_target_with, rate_name};
pub use objective::Objective;
pub use refine::{Control, FitOptions, FitOutcome, Step, StopReason, refine};
pub use shapes::{random_blobs, random_strokes};
pub use trace::trace;

//! **diffsvg** recovers vector scenes by differentiable rendering.
//!
//! * [`scene`]: the 2D scene model (cubic Bézier paths with fills, strokes and paints in
//!   device pixels), SVG in and out, and the flat parameter vector the optimizer moves.
//! * [`raster`]: the analytic-coverage rasterizer.
//! * [`image_io`] and [`metrics`]: images in premultiplied `f32` and how to compare them.
//!
//! ```
//! use diffsvg::{Scene, Sizing, raster};
//! let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="20" height="20">
//!   <rect x="5" y="5" width="10" height="10" fill="red"/></svg>"#;
//! let scene = Scene::from_svg_str(svg, "inline.svg", Sizing::Natural).unwrap();
//! let img = raster::render(&scene, &raster::RenderOptions::default());
//! assert_eq!(img.get(10, 10), [1.0, 0.0, 0.0, 1.0]);
//! ```

pub mod error;
pub mod fit;
pub mod gradcheck;
pub mod image_io;
pub mod limits;
pub mod loss;
pub mod metrics;
pub mod mnist;
pub mod optim;
pub mod raster;
pub mod reference;
pub mod scene;
pub mod volume;

pub use error::{Error, Result};
pub use image_io::Image;
pub use scene::svg_in::Sizing;
pub use scene::{Node, Path, Scene};

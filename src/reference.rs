//! resvg as the reference renderer: the forward pixels diffsvg is measured against.

use std::path::Path;

use crate::error::{Error, Result};
use crate::image_io::Image;
use crate::scene::svg_in::{Sizing, canvas_size};

/// Renders a parsed tree with resvg onto a transparent canvas sized exactly as
/// [`Scene::load`](crate::Scene::load) would size it for `sizing`.
pub fn render_resvg(tree: &usvg::Tree, name: &Path, sizing: Sizing) -> Result<Image> {
    let (w, h, t) = canvas_size(tree, sizing, name)?;
    let mut pixmap = tiny_skia::Pixmap::new(w, h).ok_or_else(|| Error::InvalidValue {
        path: name.to_path_buf(),
        what: format!("cannot allocate a {w}x{h} canvas"),
    })?;
    let ts = tiny_skia::Transform::from_row(
        t[0] as f32,
        t[1] as f32,
        t[2] as f32,
        t[3] as f32,
        t[4] as f32,
        t[5] as f32,
    );
    resvg::render(tree, ts, &mut pixmap.as_mut());
    Ok(Image::from_premultiplied_rgba8(w, h, pixmap.data()))
}

/// Largest mean absolute difference (0–255 levels) for a file to count as matching resvg.
pub const PARITY_MAE: f64 = 0.5;
/// Smallest PSNR (dB) for a file to count as matching resvg.
pub const PARITY_PSNR: f64 = 40.0;

/// Both renderings of one SVG and how far apart they are.
#[derive(Clone, Debug)]
pub struct Parity {
    /// diffsvg's rendering (premultiplied `f32`).
    pub ours: Image,
    /// resvg's rendering.
    pub reference: Image,
    /// Our rendering rounded to 8 bits, compared with resvg's.
    pub comparison: crate::metrics::Comparison,
}

impl Parity {
    /// Whether the file meets [`PARITY_MAE`] and [`PARITY_PSNR`].
    pub fn passes(&self) -> bool {
        self.comparison.mae <= PARITY_MAE && self.comparison.psnr >= PARITY_PSNR
    }
}

/// Renders the SVG file at `path` with diffsvg and with resvg at the same size.
pub fn parity(path: &Path, sizing: Sizing, opts: &crate::raster::RenderOptions) -> Result<Parity> {
    let data = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let tree = crate::scene::svg_in::parse_tree(&data, path)?;
    let scene = crate::scene::svg_in::from_tree(&tree, path, sizing)?;
    let ours = crate::raster::render(&scene, opts);
    let reference = render_resvg(&tree, path, sizing)?;
    let comparison = crate::metrics::compare(&ours.quantized(), &reference);
    Ok(Parity {
        ours,
        reference,
        comparison,
    })
}

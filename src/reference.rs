//! resvg as the reference renderer: the forward pixels diffsvg is measured against.
//!
//! ```
//! use diffsvg::{Scene, Sizing, metrics, raster, reference, scene};
//! let svg = br#"<svg xmlns="http://www.w3.org/2000/svg" width="16" height="16">
//!   <circle cx="8" cy="8" r="5" fill="teal"/></svg>"#;
//! let name = std::path::Path::new("circle.svg");
//! let tree = scene::parse_tree(svg, name)?;
//! let theirs = reference::render_resvg(&tree, name, Sizing::Natural)?;
//! let ours = raster::render(&scene::from_tree(&tree, name, Sizing::Natural)?, &Default::default());
//! assert!(metrics::compare(&ours.quantized(), &theirs).mae < reference::PARITY_MAE);
//! # Ok::<(), diffsvg::Error>(())
//! ```

use std::path::Path;

use crate::error::{Error, Result};
use crate::image_io::Image;
use crate::scene::Fonts;
use crate::scene::svg_in::{Sizing, canvas_size};

/// Largest coordinate magnitude, in device pixels, of anything resvg is asked to draw.
///
/// tiny-skia's rasterizer works in fixed point: from about 2³¹ device pixels its scan
/// converter indexes out of its buffers and panics (`alpha_runs.rs`, `pipeline`). A tree
/// reaching past this bound (a thousand canvases of the largest size away) is not given
/// to resvg at all; [`render_resvg`] reports it as a file resvg cannot render.
pub(crate) const RESVG_MAX_DEVICE_COORDINATE: f64 = 1.6e7;

/// Renders a parsed tree with resvg onto a transparent canvas sized exactly as
/// [`Scene::load`](crate::Scene::load) would size it for `sizing`.
///
/// resvg is fed only what it accepts: a tree whose drawing reaches beyond
/// `RESVG_MAX_DEVICE_COORDINATE` device pixels is refused before rendering, and a panic
/// inside resvg or tiny-skia is caught (its message silenced) and returned as an
/// [`Error::Unsupported`] naming the file, "resvg cannot render this file: …".
pub fn render_resvg(tree: &usvg::Tree, name: &Path, sizing: Sizing) -> Result<Image> {
    let pixmap = render_resvg_pixmap(tree, name, sizing)?;
    Ok(Image::from_premultiplied_rgba8(
        pixmap.width(),
        pixmap.height(),
        pixmap.data(),
    ))
}

/// [`render_resvg`]'s canvas as resvg leaves it (8-bit premultiplied RGBA), without the
/// conversion to an [`Image`]: what `diffsvg bench` times as resvg's own work.
pub fn render_resvg_pixmap(
    tree: &usvg::Tree,
    name: &Path,
    sizing: Sizing,
) -> Result<tiny_skia::Pixmap> {
    let (w, h, t) = canvas_size(tree, sizing, name)?;
    render_transformed(tree, name, w, h, t)
}

/// resvg's rendering of `tree` through the device transform `t` onto a `w × h` canvas.
fn render_transformed(
    tree: &usvg::Tree,
    name: &Path,
    w: u32,
    h: u32,
    t: crate::scene::Affine,
) -> Result<tiny_skia::Pixmap> {
    let cannot = |why: String| Error::Unsupported {
        path: name.to_path_buf(),
        what: format!("resvg cannot render this file: {why}"),
    };
    let reach = device_reach(tree, &t);
    if reach.is_nan() || reach > RESVG_MAX_DEVICE_COORDINATE {
        return Err(cannot(format!(
            "the drawing reaches {reach:.3e} px from the origin, past the {RESVG_MAX_DEVICE_COORDINATE:.1e} px tiny-skia can rasterize"
        )));
    }
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
    crate::guard::quietly(|| resvg::render(tree, ts, &mut pixmap.as_mut()))
        .map_err(|why| cannot(format!("it panicked ({why})")))?;
    Ok(pixmap)
}

/// The largest coordinate magnitude, in device pixels, of any node's stroked bounding box
/// (clip paths, masks and patterns included), under the canvas transform `t`. Infinite or
/// NaN when a box is not finite.
fn device_reach(tree: &usvg::Tree, t: &crate::scene::Affine) -> f64 {
    fn visit(g: &usvg::Group, t: &crate::scene::Affine, reach: &mut f64) {
        for node in g.children() {
            let b = node.stroke_bounding_box();
            let m = node.abs_transform();
            for (x, y) in [
                (b.left(), b.top()),
                (b.right(), b.top()),
                (b.left(), b.bottom()),
                (b.right(), b.bottom()),
            ] {
                let (x, y) = (x as f64, y as f64);
                // The node's own transform, then the canvas transform.
                let ux = m.sx as f64 * x + m.kx as f64 * y + m.tx as f64;
                let uy = m.ky as f64 * x + m.sy as f64 * y + m.ty as f64;
                let dx = t[0] * ux + t[2] * uy + t[4];
                let dy = t[1] * ux + t[3] * uy + t[5];
                let r = dx.abs().max(dy.abs());
                // NaN propagates: `max` would drop it.
                *reach = if r.is_nan() { f64::NAN } else { reach.max(r) };
            }
            if let usvg::Node::Group(child) = node {
                visit(child, t, reach);
            }
            node.subroots(|sub| visit(sub, t, reach));
        }
    }
    let mut reach = 0.0;
    visit(tree.root(), t, &mut reach);
    reach
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

/// Why [`parity_checked`] could not compare a file.
#[derive(Debug)]
pub enum ParityError {
    /// diffsvg refused the file (unreadable, malformed, unsupported, out of range).
    Ours(Error),
    /// diffsvg rendered it but resvg could not (see [`render_resvg`]).
    Reference(Error),
}

impl std::fmt::Display for ParityError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ParityError::Ours(e) | ParityError::Reference(e) => e.fmt(f),
        }
    }
}

impl std::error::Error for ParityError {}

/// A box-filtered reference: resvg renders the tree `factor` times larger in each
/// direction and each pixel is the mean of its `factor × factor` pixels (premultiplied),
/// at the canvas [`render_resvg`] gives. With `factor` 16 its own anti-aliasing errors
/// shrink to a sixteenth of a pixel: what the exactness of both renderers is measured
/// against (`diffsvg parity --supersampled 16`).
pub fn render_resvg_supersampled(
    tree: &usvg::Tree,
    name: &Path,
    sizing: Sizing,
    factor: u32,
) -> Result<Image> {
    let (w, h, t) = canvas_size(tree, sizing, name)?;
    let f = factor.clamp(1, 64);
    let k = f as f64;
    let big_t = [t[0] * k, t[1] * k, t[2] * k, t[3] * k, t[4] * k, t[5] * k];
    let big = render_transformed(tree, name, w * f, h * f, big_t)?;
    let bw = big.width() as usize;
    let data = big.data();
    let mut out = Image::new(w, h);
    let scale = 1.0 / (255.0 * (f * f) as f32);
    for y in 0..h as usize {
        for x in 0..w as usize {
            let mut acc = [0u32; 4];
            for sy in 0..f as usize {
                let row = (y * f as usize + sy) * bw;
                for sx in 0..f as usize {
                    let k = 4 * (row + x * f as usize + sx);
                    for c in 0..4 {
                        acc[c] += data[k + c] as u32;
                    }
                }
            }
            out.data[y * w as usize + x] = acc.map(|v| v as f32 * scale);
        }
    }
    Ok(out)
}

/// Mean absolute difference in 0–255 levels of diffsvg's (with `opts`) and resvg's
/// renderings of the file at `path` against [`render_resvg_supersampled`] with `factor`,
/// as `(diffsvg, resvg)`; both are quantized to 8 bits first, as parity compares them.
pub fn supersampled_mae(
    path: &Path,
    sizing: Sizing,
    opts: &crate::raster::RenderOptions,
    fonts: &Fonts,
    factor: u32,
) -> Result<(f64, f64)> {
    let data = crate::image_io::read_bounded(path, crate::limits::MAX_FILE_BYTES)?;
    let tree = crate::scene::svg_in::parse_tree_with(&data, path, fonts)?;
    let scene = crate::scene::svg_in::from_tree(&tree, path, sizing)?;
    let ours = crate::raster::render(&scene, opts).quantized();
    let theirs = render_resvg(&tree, path, sizing)?;
    let reference = render_resvg_supersampled(&tree, path, sizing, factor)?.quantized();
    Ok((
        crate::metrics::compare(&ours, &reference).mae,
        crate::metrics::compare(&theirs, &reference).mae,
    ))
}

/// Samples per pixel side of the reference that settles a file where diffsvg and resvg
/// differ ([`closer_to_exact`]): resvg rendered this many times larger and box-filtered
/// down, 256 samples per pixel.
pub const EXACT_FACTOR: u32 = 16;

/// For a file where diffsvg and resvg differ: whose rendering is nearer the exact one?
/// The MAE (0–255 levels) of diffsvg's and of resvg's rendering against
/// [`render_resvg_supersampled`] with [`EXACT_FACTOR`], as `[diffsvg, resvg]`.
///
/// resvg anti-aliases with 4 samples per pixel vertically and exact spans horizontally,
/// and draws thin strokes as hairlines by its own rules, where diffsvg computes each
/// pixel's covered area; a difference between the two is then resvg's approximation
/// when diffsvg is the nearer of the two to 256 samples per pixel. `None` where the
/// drawing turns anti-aliasing off anywhere (`shape-rendering: crispEdges` or
/// `optimizeSpeed`, `text-rendering: optimizeSpeed`, an `image-rendering` other than
/// smooth): there the larger rendering is no reference.
pub fn closer_to_exact(path: &Path, sizing: Sizing, fonts: &Fonts) -> Result<Option<[f64; 2]>> {
    let data = crate::image_io::read_bounded(path, crate::limits::MAX_FILE_BYTES)?;
    let tree = crate::scene::svg_in::parse_tree_with(&data, path, fonts)?;
    if turns_off_antialiasing(tree.root()) || uses_morphology(tree.root()) {
        return Ok(None);
    }
    let (ours, theirs) = supersampled_mae(
        path,
        sizing,
        &crate::raster::RenderOptions::default(),
        fonts,
        EXACT_FACTOR,
    )?;
    Ok(Some([ours, theirs]))
}

/// Whether anything under `g` (clip paths, masks, patterns and text included) is drawn
/// without anti-aliasing or with an image filter other than smooth.
fn turns_off_antialiasing(g: &usvg::Group) -> bool {
    g.children().iter().any(|node| {
        let own = match node {
            usvg::Node::Path(p) => !p.rendering_mode().use_shape_antialiasing(),
            usvg::Node::Image(i) => !matches!(
                i.rendering_mode(),
                usvg::ImageRendering::OptimizeQuality
                    | usvg::ImageRendering::Smooth
                    | usvg::ImageRendering::HighQuality
            ),
            usvg::Node::Text(t) => turns_off_antialiasing(t.flattened()),
            usvg::Node::Group(child) => turns_off_antialiasing(child),
        };
        let mut sub = false;
        node.subroots(|r| sub |= turns_off_antialiasing(r));
        own || sub
    })
}

/// Whether a filter under `g` has an feMorphology: resvg computes it by brute force over
/// the whole window, `(2r)²` reads a pixel, so at [`EXACT_FACTOR`] times the size (the
/// radius and the pixel count both scaled) one file can take hours; such a file is not
/// measured against the exact rendering.
fn uses_morphology(g: &usvg::Group) -> bool {
    let own = g.filters().iter().any(|f| {
        f.primitives()
            .iter()
            .any(|p| matches!(p.kind(), usvg::filter::Kind::Morphology(_)))
    });
    own || g.children().iter().any(|node| {
        let mut sub = matches!(node, usvg::Node::Group(c) if uses_morphology(c));
        node.subroots(|r| sub |= uses_morphology(r));
        sub
    })
}

/// Renders the SVG file at `path` with diffsvg and with resvg at the same size (`<text>`
/// in the bundled fonts).
pub fn parity(path: &Path, sizing: Sizing, opts: &crate::raster::RenderOptions) -> Result<Parity> {
    parity_with(path, sizing, opts, crate::scene::fonts::bundled())
}

/// [`parity`] with these fonts for `<text>`.
pub fn parity_with(
    path: &Path,
    sizing: Sizing,
    opts: &crate::raster::RenderOptions,
    fonts: &Fonts,
) -> Result<Parity> {
    parity_checked_with(path, sizing, opts, fonts).map_err(|e| match e {
        ParityError::Ours(e) | ParityError::Reference(e) => e,
    })
}

/// [`parity`], telling a file diffsvg refuses from one only resvg cannot render.
pub fn parity_checked(
    path: &Path,
    sizing: Sizing,
    opts: &crate::raster::RenderOptions,
) -> std::result::Result<Parity, ParityError> {
    parity_checked_with(path, sizing, opts, crate::scene::fonts::bundled())
}

/// [`parity_checked`] with these fonts for `<text>`. The file is parsed once, with
/// `fonts`, and both renderers draw that tree: the same glyph outlines, so the comparison
/// measures the rasterizers, not the font choice.
pub fn parity_checked_with(
    path: &Path,
    sizing: Sizing,
    opts: &crate::raster::RenderOptions,
    fonts: &Fonts,
) -> std::result::Result<Parity, ParityError> {
    let ours = || -> Result<_> {
        let data = crate::image_io::read_bounded(path, crate::limits::MAX_FILE_BYTES)?;
        let tree = crate::scene::svg_in::parse_tree_with(&data, path, fonts)?;
        let scene = crate::scene::svg_in::from_tree(&tree, path, sizing)?;
        Ok((tree, crate::raster::render(&scene, opts)))
    };
    let (tree, ours) = ours().map_err(ParityError::Ours)?;
    let reference = render_resvg(&tree, path, sizing).map_err(ParityError::Reference)?;
    let comparison = crate::metrics::compare(&ours.quantized(), &reference);
    Ok(Parity {
        ours,
        reference,
        comparison,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// issue 13, case 2: the line that made tiny-skia panic.
    const LINE_1E9: &str = r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100"><line x2="1e9" y2="-1e9" stroke="black" stroke-width="1e6"/></svg>"#;

    fn tree(svg: &str) -> usvg::Tree {
        crate::scene::svg_in::parse_tree(svg.as_bytes(), Path::new("t.svg")).unwrap()
    }

    #[test]
    fn line_1e9_is_refused_before_resvg_runs() {
        let err = render_resvg(&tree(LINE_1E9), Path::new("t.svg"), Sizing::Width(128))
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("t.svg: "), "{err}");
        assert!(err.contains("resvg cannot render this file"), "{err}");
        assert!(!err.contains('\n'), "{err}");
    }

    #[test]
    fn tiny_skia_panic_is_caught_quietly() {
        // Past the bound: rendered anyway here, to show the panic is caught.
        let t = tree(&LINE_1E9.replace("1e9", "1e12"));
        let mut pixmap = tiny_skia::Pixmap::new(128, 128).unwrap();
        let ts = tiny_skia::Transform::from_scale(1.28, 1.28);
        let r = crate::guard::quietly(|| resvg::render(&t, ts, &mut pixmap.as_mut()));
        let why = r.expect_err("tiny-skia panics on this line");
        assert!(!why.is_empty());
    }

    #[test]
    fn ordinary_files_still_render() {
        let line = LINE_1E9.replace("1e9", "90").replace("1e6", "4");
        let img = render_resvg(&tree(&line), Path::new("t.svg"), Sizing::Width(128)).unwrap();
        assert_eq!((img.width, img.height), (128, 128));
        assert!(img.data.iter().any(|p| p[3] > 0.5));
        // Still far out, but within what tiny-skia rasterizes.
        let far = LINE_1E9.replace("1e9", "1e6");
        assert!(render_resvg(&tree(&far), Path::new("t.svg"), Sizing::Width(128)).is_ok());
    }
}

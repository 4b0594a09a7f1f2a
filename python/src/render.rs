//! Rendering, the backward pass and losses over numpy images.

use std::path::PathBuf;

use diffsvg::Image;
use diffsvg::loss::Loss;
use diffsvg::raster::{
    RenderOptions, render as raster_render, render_backward_checked as raster_backward_checked,
};
use numpy::{PyArray1, PyArray3, PyReadonlyArrayDyn};
use pyo3::prelude::*;

use crate::array::{color_in, image_in, image_out, vec_out};
use crate::error::{bad, to_py};
use crate::on_pool;
use crate::scene::PyScene;

/// Rasterizer settings from the keywords `tolerance` (pixels between a curve and its
/// chords) and `exact_overlaps`.
pub(crate) fn options(tolerance: f64, exact_overlaps: bool) -> PyResult<RenderOptions> {
    if !(tolerance > 0.0 && tolerance <= 10.0) {
        return Err(bad(format!(
            "tolerance {tolerance} must be in (0, 10] pixels"
        )));
    }
    Ok(RenderOptions {
        tolerance,
        exact_overlaps,
        ..RenderOptions::default()
    })
}

/// Renders `scene` into a `(height, width, 4)` `float32` array of **premultiplied** RGBA
/// in `[0, 1]`, y down. `width` (and optionally `height`) render at another size: the
/// scene is scaled uniformly by `width / scene.width`, the canvas is `width × height`
/// (height by default in proportion). `background` (straight RGBA) is composited under
/// the drawing. `exact_overlaps` integrates exactly the pixels where a path overlaps
/// itself ([`RenderOptions::exact_overlaps`]). The GIL is released while rendering.
#[pyfunction]
#[pyo3(signature = (scene, width=None, height=None, background=None, tolerance=0.02, exact_overlaps=false))]
pub(crate) fn render<'py>(
    py: Python<'py>,
    scene: PyRef<'py, PyScene>,
    width: Option<u32>,
    height: Option<u32>,
    background: Option<[f32; 4]>,
    tolerance: f64,
    exact_overlaps: bool,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let bg = color_in(background, "background")?;
    let opts = options(tolerance, exact_overlaps)?;
    let s = &scene.inner;
    let sized = match (width, height) {
        (None, None) => None,
        (w, h) => {
            let w = w.unwrap_or(s.width);
            if w == 0 || s.width == 0 {
                return Err(bad("render: width must be positive"));
            }
            let k = w as f64 / s.width as f64;
            let h = h.unwrap_or(((s.height as f64 * k).round() as u32).max(1));
            diffsvg::image_io::check_image_size(w, h, "render".as_ref()).map_err(to_py)?;
            let mut c = s.clone();
            c.scale_to(k, w, h);
            Some(c)
        }
    };
    let scene_ref = sized.as_ref().unwrap_or(s);
    let img = py.detach(|| {
        on_pool(|| {
            let mut img = raster_render(scene_ref, &opts);
            if let Some(bg) = bg {
                img.over_background(bg);
            }
            img
        })
    });
    Ok(image_out(py, img))
}

/// The gradient of a loss with respect to every parameter of `scene` (`params()` layout,
/// `float64`), given `d_image = ∂L/∂image` as a `(height, width, 4)` `float32` array of
/// the scene's size. With `background`, `d_image` is the gradient with respect to the
/// image composited over it. `exact_overlaps` differentiates the exact coverage of the
/// pixels where a path overlaps itself, as [`render`] draws it. The GIL is released while
/// it runs.
#[pyfunction]
#[pyo3(signature = (scene, d_image, background=None, tolerance=0.02, exact_overlaps=false))]
pub(crate) fn render_backward<'py>(
    py: Python<'py>,
    scene: PyRef<'py, PyScene>,
    d_image: PyReadonlyArrayDyn<'py, f32>,
    background: Option<[f32; 4]>,
    tolerance: f64,
    exact_overlaps: bool,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let bg = color_in(background, "background")?;
    let opts = options(tolerance, exact_overlaps)?;
    let mut d = image_in(&d_image, "d_image")?;
    let s = &scene.inner;
    if (d.width, d.height) != (s.width, s.height) {
        return Err(bad(format!(
            "d_image: {}x{} (width x height) but the scene is {}x{}",
            d.width, d.height, s.width, s.height
        )));
    }
    let g = py.detach(|| {
        on_pool(|| {
            if let Some(bg) = bg {
                d.over_background_backward(bg);
            }
            raster_backward_checked(s, &opts, &d, std::path::Path::new("scene"))
        })
    });
    Ok(vec_out(py, g.map_err(to_py)?))
}

/// Loss of `image` against `target` (same shape, premultiplied RGBA), the mean over
/// pixels and the first `channels` channels (4: RGBA, 3: RGB), in `f64`; with `grad`,
/// also `∂L/∂image` (`float32`, zero in the channels left out).
#[pyfunction]
#[pyo3(signature = (image, target, kind="mse", grad=false, channels=4))]
pub(crate) fn loss<'py>(
    py: Python<'py>,
    image: PyReadonlyArrayDyn<'py, f32>,
    target: PyReadonlyArrayDyn<'py, f32>,
    kind: &str,
    grad: bool,
    channels: usize,
) -> PyResult<(f64, Option<Bound<'py, PyArray3<f32>>>)> {
    let l: Loss = kind.parse().map_err(bad)?;
    if !(channels == 3 || channels == 4) {
        return Err(bad(format!(
            "channels: {channels} (expected 4 for RGBA or 3 for RGB)"
        )));
    }
    let a = image_in(&image, "image")?;
    let b = image_in(&target, "target")?;
    if (a.width, a.height) != (b.width, b.height) {
        return Err(bad(format!(
            "target: {}x{} (width x height) but the image is {}x{}",
            b.width, b.height, a.width, a.height
        )));
    }
    let (v, d) = py.detach(|| l.eval(&a, &b, channels, grad));
    Ok((v, d.map(|d| image_out(py, d))))
}

/// Reads a PNG or JPEG as premultiplied RGBA `float32`, `(height, width, 4)`.
#[pyfunction]
pub(crate) fn load_image(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyArray3<f32>>> {
    let img = py.detach(|| Image::load(&path)).map_err(to_py)?;
    Ok(image_out(py, img))
}

/// A fitting target: a PNG or JPEG, or an SVG or SVGZ rendered at its own size; resized
/// to `width × height` when given (both or neither: one alone is refused).
#[pyfunction]
#[pyo3(signature = (path, width=None, height=None))]
pub(crate) fn load_target(
    py: Python<'_>,
    path: PathBuf,
    width: Option<u32>,
    height: Option<u32>,
) -> PyResult<Bound<'_, PyArray3<f32>>> {
    let size = match (width, height) {
        (Some(w), Some(h)) => Some((w, h)),
        (None, None) => None,
        _ => return Err(bad("width and height: give both (or neither)")),
    };
    let img = py
        .detach(|| diffsvg::fit::load_target(&path, size))
        .map_err(to_py)?;
    Ok(image_out(py, img))
}

/// Writes a premultiplied RGBA `float32` image as an 8-bit PNG (temporary file, renamed)
/// into a folder that exists.
#[pyfunction]
pub(crate) fn save_png(image: PyReadonlyArrayDyn<'_, f32>, path: PathBuf) -> PyResult<()> {
    crate::output::check_folder(&path)?;
    image_in(&image, "image")?.save_png(&path).map_err(to_py)
}

//! One scene's topology with a batch of parameter vectors: the renders and backward passes
//! `diffsvg.jax` calls once for a whole `vmap` batch (or once for one vector). The rows run
//! in parallel on rayon's pool, each render parallel inside as well; the GIL is released.

use std::sync::Mutex;

use diffsvg::raster::{RenderOptions, render as raster_render, render_backward_checked};
use diffsvg::scene::{ParamLayout, project};
use diffsvg::{Image, Scene};
use numpy::ndarray::{Array2, Array4, ArrayView2, ArrayView4, Axis};
use numpy::{IntoPyArray, PyArray2, PyArray4, PyReadonlyArray2, PyReadonlyArray4};
use pyo3::prelude::*;
use rayon::prelude::*;

use crate::array::color_in;
use crate::error::bad;
use crate::on_pool;
use crate::render::options;
use crate::scene::{PyScene, Rendered};

/// Row `b` of `params` written into a copy of `scene` and projected onto valid scenes, as
/// `Scene.set_params` does; a non-finite value is refused, naming the row and slot.
fn with_row(scene: &Scene, params: &ArrayView2<'_, f64>, b: usize) -> Result<Scene, String> {
    let row: Vec<f64> = params.row(b).iter().copied().collect();
    if let Some(i) = row.iter().position(|x| !x.is_finite()) {
        return Err(format!(
            "params: row {b}, value {i} is {} (not finite)",
            row[i]
        ));
    }
    let mut s = scene.clone();
    s.set_params(&row);
    project(&mut s);
    Ok(s)
}

/// Checks a `(batch, n)` parameter array against the scene's `n` parameters.
fn check_params(scene: &Scene, params: &ArrayView2<'_, f64>) -> PyResult<()> {
    let n = ParamLayout::new(scene).len();
    if params.ncols() != n {
        return Err(bad(format!(
            "params: {} values per row but the scene has {n} parameters",
            params.ncols()
        )));
    }
    Ok(())
}

/// The renders of `scene` with each row of `p` (the core of [`render_batch`], shared with
/// `ffi`'s handler so both give the same bits): on rayon's pool, the rows in parallel;
/// `background` composited under each. The scenes made of the rows go into `cache` for
/// [`backward_rows`] on the same rows.
pub(crate) fn render_rows(
    s: &Scene,
    p: &ArrayView2<'_, f64>,
    background: Option<[f32; 4]>,
    opts: &RenderOptions,
    cache: &Mutex<Vec<Rendered>>,
) -> Result<Vec<Image>, String> {
    let done: Result<Vec<(Image, Rendered)>, String> = on_pool(|| {
        (0..p.nrows())
            .into_par_iter()
            .map(|b| {
                let row = with_row(s, p, b)?;
                let mut img = raster_render(&row, opts);
                if let Some(bg) = background {
                    img.over_background(bg);
                }
                Ok((img, (p.row(b).to_vec(), row)))
            })
            .collect()
    });
    let (images, rendered): (Vec<Image>, Vec<_>) = done?.into_iter().unzip();
    *cache.lock().unwrap_or_else(|e| e.into_inner()) = rendered;
    Ok(images)
}

/// The gradients with respect to each row of `p` given `d = ∂L/∂image` per row
/// (`(rows, height, width, 4)`, the scene's size): the core of [`render_backward_batch`],
/// shared with `ffi`'s handler. Takes the scenes [`render_rows`] left in `cache` for the
/// same rows instead of copying and projecting again.
pub(crate) fn backward_rows(
    s: &Scene,
    p: &ArrayView2<'_, f64>,
    d: &ArrayView4<'_, f32>,
    background: Option<[f32; 4]>,
    opts: &RenderOptions,
    cache: &Mutex<Vec<Rendered>>,
) -> Result<Vec<Vec<f64>>, String> {
    // The copies the forward pass made for these rows, when it made them.
    let mut rendered = std::mem::take(&mut *cache.lock().unwrap_or_else(|e| e.into_inner()));
    if rendered.len() != p.nrows()
        || !rendered
            .iter()
            .enumerate()
            .all(|(b, (r, _))| p.row(b).iter().eq(r.iter()))
    {
        rendered.clear();
    }
    let mut cached: Vec<Option<Scene>> = rendered.into_iter().map(|(_, s)| Some(s)).collect();
    cached.resize_with(p.nrows(), || None);
    on_pool(|| {
        cached
            .into_par_iter()
            .enumerate()
            .map(|(b, c)| {
                let row = match c {
                    Some(row) => row,
                    None => with_row(s, p, b)?,
                };
                let plane = d.index_axis(Axis(0), b);
                let owned;
                let values: &[f32] = match plane.as_slice() {
                    Some(v) => v,
                    None => {
                        owned = plane.iter().copied().collect::<Vec<f32>>();
                        &owned
                    }
                };
                if let Some(i) = values.iter().position(|x| !x.is_finite()) {
                    return Err(format!(
                        "d_images: row {b}, pixel {} holds a non-finite value {}",
                        i / 4,
                        values[i]
                    ));
                }
                let data: Vec<[f32; 4]> = values
                    .chunks_exact(4)
                    .map(|p| [p[0], p[1], p[2], p[3]])
                    .collect();
                let mut di = Image {
                    width: s.width,
                    height: s.height,
                    data,
                };
                if let Some(bg) = background {
                    di.over_background_backward(bg);
                }
                render_backward_checked(&row, opts, &di, std::path::Path::new("scene"))
                    .map_err(|e| e.to_string())
            })
            .collect()
    })
}

/// Renders `scene` with each row of `params` (`(batch, n)` `float64`, the layout of
/// `Scene.params()`): `(batch, height, width, 4)` `float32` premultiplied, the rows in
/// parallel. `background` (straight RGBA) is composited under each; `exact_overlaps` as
/// for `render`.
#[pyfunction]
#[pyo3(signature = (scene, params, background=None, tolerance=0.02, exact_overlaps=false))]
pub(crate) fn render_batch<'py>(
    py: Python<'py>,
    scene: PyRef<'py, PyScene>,
    params: PyReadonlyArray2<'py, f64>,
    background: Option<[f32; 4]>,
    tolerance: f64,
    exact_overlaps: bool,
) -> PyResult<Bound<'py, PyArray4<f32>>> {
    let bg = color_in(background, "background")?;
    let opts = options(tolerance, exact_overlaps)?;
    let s = &scene.inner;
    let p = params.as_array();
    check_params(s, &p)?;
    let (w, h) = (s.width as usize, s.height as usize);
    let cache = &scene.rendered;
    let mut images = py
        .detach(|| render_rows(s, &p, bg, &opts, cache))
        .map_err(bad)?;
    // One image is moved, not copied.
    let flat: Vec<f32> = if images.len() == 1 {
        images.pop().expect("one image").data.into_flattened()
    } else {
        let mut flat = Vec::with_capacity(images.len() * w * h * 4);
        for img in images {
            flat.extend(img.data.into_iter().flatten());
        }
        flat
    };
    let out = Array4::from_shape_vec((p.nrows(), h, w, 4), flat)
        .expect("each image holds width × height pixels");
    Ok(out.into_pyarray(py))
}

/// The gradients of a loss with respect to each row of `params` (`(batch, n)`, as in
/// `render_batch`), given `d_images = ∂L/∂image` per row (`(batch, height, width, 4)`
/// `float32`): `(batch, n)` `float64`, the rows in parallel; `exact_overlaps` as for
/// `render_backward`.
#[pyfunction]
#[pyo3(signature = (scene, params, d_images, background=None, tolerance=0.02, exact_overlaps=false))]
pub(crate) fn render_backward_batch<'py>(
    py: Python<'py>,
    scene: PyRef<'py, PyScene>,
    params: PyReadonlyArray2<'py, f64>,
    d_images: PyReadonlyArray4<'py, f32>,
    background: Option<[f32; 4]>,
    tolerance: f64,
    exact_overlaps: bool,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let bg = color_in(background, "background")?;
    let opts = options(tolerance, exact_overlaps)?;
    let s = &scene.inner;
    let p = params.as_array();
    check_params(s, &p)?;
    let d = d_images.as_array();
    let (w, h) = (s.width as usize, s.height as usize);
    if d.shape() != [p.nrows(), h, w, 4] {
        return Err(bad(format!(
            "d_images: shape {:?} but {} rows of a {w}x{h} scene need {:?}",
            d.shape(),
            p.nrows(),
            [p.nrows(), h, w, 4]
        )));
    }
    let n = p.ncols();
    let cache = &scene.rendered;
    let grads = py
        .detach(|| backward_rows(s, &p, &d, bg, &opts, cache))
        .map_err(bad)?;
    let rows = grads.len();
    let out = Array2::from_shape_vec((rows, n), grads.concat())
        .expect("each gradient holds the scene's parameters");
    Ok(out.into_pyarray(py))
}

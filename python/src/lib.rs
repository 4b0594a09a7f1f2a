//! Python bindings of diffsvg, built with PyO3 and maturin as the extension module
//! `diffsvg._native`; the Python package `diffsvg` (in `python/diffsvg/`) wraps it.
//!
//! Conventions are the library's: device pixels, y down, pixel `(i, j)` covers
//! `[i, i+1] × [j, j+1]`; scene colors straight sRGB in `[0, 1]`; images premultiplied RGBA
//! `float32`, shape `(height, width, 4)`. Every array is checked (shape, dtype, finiteness)
//! before the library sees it, and every library error becomes a Python exception carrying
//! the library's one-line message; the GIL is released while rendering and fitting.

mod array;
mod batch;
mod build;
mod error;
mod ffi;
mod jobs;
mod mesh;
mod output;
mod recon;
mod render;
mod scene;

use pyo3::prelude::*;

/// Runs `f` on a worker of rayon's pool: its parallel parts then start inside the pool
/// instead of each being handed over from this thread and waited for (a wake-up each,
/// most of the time of a small scene's call). Only for calls without Python callbacks,
/// which must stay on the calling thread (signals reach the main thread only).
pub(crate) fn on_pool<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    rayon::scope(|_| f())
}

/// The native half of the `diffsvg` package.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("DiffsvgError", m.py().get_type::<error::DiffsvgError>())?;
    m.add_class::<scene::PyScene>()?;
    m.add_function(wrap_pyfunction!(render::render, m)?)?;
    m.add_function(wrap_pyfunction!(render::render_backward, m)?)?;
    m.add_function(wrap_pyfunction!(batch::render_batch, m)?)?;
    m.add_function(wrap_pyfunction!(batch::render_backward_batch, m)?)?;
    m.add_function(wrap_pyfunction!(ffi::ffi_scene, m)?)?;
    m.add_function(wrap_pyfunction!(ffi::ffi_registered, m)?)?;
    m.add_function(wrap_pyfunction!(render::loss, m)?)?;
    m.add_function(wrap_pyfunction!(render::load_image, m)?)?;
    m.add_function(wrap_pyfunction!(render::load_target, m)?)?;
    m.add_function(wrap_pyfunction!(render::save_png, m)?)?;
    m.add_function(wrap_pyfunction!(jobs::fit, m)?)?;
    m.add_function(wrap_pyfunction!(jobs::vectorize, m)?)?;
    m.add_function(wrap_pyfunction!(jobs::random_blobs, m)?)?;
    m.add_function(wrap_pyfunction!(jobs::random_strokes, m)?)?;
    m.add_function(wrap_pyfunction!(jobs::digit, m)?)?;
    m.add_function(wrap_pyfunction!(jobs::glyph, m)?)?;
    m.add_function(wrap_pyfunction!(recon::recon_voxel, m)?)?;
    m.add_function(wrap_pyfunction!(recon::recon_splat, m)?)?;
    m.add_function(wrap_pyfunction!(recon::recon_ngp, m)?)?;
    m.add_function(wrap_pyfunction!(recon::recon_nerf, m)?)?;
    m.add_function(wrap_pyfunction!(recon::view, m)?)?;
    m.add_class::<mesh::PyMesh>()?;
    m.add_class::<mesh::PyCamera>()?;
    Ok(())
}

//! Images and vectors between numpy and the library: checked on the way in, moved (not
//! copied) on the way out.

use diffsvg::Image;
use numpy::PyUntypedArrayMethods;
use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray1, PyArray3, PyReadonlyArray1, PyReadonlyArrayDyn};
use pyo3::prelude::*;

use crate::error::bad;

/// An image as a `(height, width, 4)` `float32` array; the pixels are moved into numpy.
pub(crate) fn image_out(py: Python<'_>, img: Image) -> Bound<'_, PyArray3<f32>> {
    let (w, h) = (img.width as usize, img.height as usize);
    let flat: Vec<f32> = img.data.into_flattened();
    Array3::from_shape_vec((h, w, 4), flat)
        .expect("an image holds width × height pixels")
        .into_pyarray(py)
}

/// A `(height, width, 4)` `float32` array as an image (one copy), refusing other shapes
/// and non-finite values; `what` names the argument in messages.
pub(crate) fn image_in(a: &PyReadonlyArrayDyn<'_, f32>, what: &str) -> PyResult<Image> {
    let shape = a.shape();
    if shape.len() != 3 || shape[2] != 4 {
        return Err(bad(format!(
            "{what}: expected an array of shape (height, width, 4), got {shape:?}"
        )));
    }
    let (h, w) = (shape[0], shape[1]);
    let (Ok(w32), Ok(h32)) = (u32::try_from(w), u32::try_from(h)) else {
        return Err(bad(format!("{what}: {w}x{h} is too large")));
    };
    let mut data = Vec::with_capacity(w * h);
    let mut push = |s: &[f32]| -> PyResult<()> {
        for p in s.chunks_exact(4) {
            if !p.iter().all(|v| v.is_finite()) {
                return Err(bad(format!(
                    "{what}: pixel {} holds a non-finite value {p:?}",
                    data.len()
                )));
            }
            data.push([p[0], p[1], p[2], p[3]]);
        }
        Ok(())
    };
    match a.as_slice() {
        Ok(s) => push(s)?,
        // Not contiguous: one pass through the view's iterator instead.
        Err(_) => push(&a.as_array().iter().copied().collect::<Vec<f32>>())?,
    }
    Ok(Image {
        width: w32,
        height: h32,
        data,
    })
}

/// A vector of `f64` moved into numpy.
pub(crate) fn vec_out(py: Python<'_>, v: Vec<f64>) -> Bound<'_, PyArray1<f64>> {
    PyArray1::from_vec(py, v)
}

/// A 1-D `float64` array of length `len` with finite values; `what` names it.
pub(crate) fn vector_in(
    a: &PyReadonlyArray1<'_, f64>,
    len: usize,
    what: &str,
) -> PyResult<Vec<f64>> {
    let v: Vec<f64> = match a.as_slice() {
        Ok(s) => s.to_vec(),
        Err(_) => a.as_array().iter().copied().collect(),
    };
    if v.len() != len {
        return Err(bad(format!(
            "{what}: expected {len} values (the scene's parameters), got {}",
            v.len()
        )));
    }
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(bad(format!("{what}: value {i} is {} (not finite)", v[i])));
    }
    Ok(v)
}

/// A straight RGBA color `(r, g, b, a)` in `[0, 1]`.
pub(crate) fn color_in(c: Option<[f32; 4]>, what: &str) -> PyResult<Option<[f32; 4]>> {
    match c {
        Some(c) if !c.iter().all(|v| (0.0..=1.0).contains(v)) => Err(bad(format!(
            "{what}: {c:?} is not a straight RGBA color with values in [0, 1]"
        ))),
        c => Ok(c),
    }
}

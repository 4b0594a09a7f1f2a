//! Library errors as Python exceptions, with the library's one-line message.

use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyValueError};
use pyo3::prelude::*;

pyo3::create_exception!(
    diffsvg,
    DiffsvgError,
    PyValueError,
    "Bad input to diffsvg: malformed or unsupported SVG, an invalid value, a wrong-shaped \
     or mis-sized array, an unreadable image. The message names the file or argument."
);

/// Maps a library error: a missing file is `FileNotFoundError`, other I/O `OSError`,
/// everything else [`DiffsvgError`] (a `ValueError`).
pub(crate) fn to_py(e: diffsvg::Error) -> PyErr {
    let msg = e.to_string();
    match &e {
        diffsvg::Error::Io { cause, .. } if cause.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(msg)
        }
        diffsvg::Error::Io { .. } => PyOSError::new_err(msg),
        _ => DiffsvgError::new_err(msg),
    }
}

/// A [`DiffsvgError`] with this message.
pub(crate) fn bad(msg: impl Into<String>) -> PyErr {
    DiffsvgError::new_err(msg.into())
}

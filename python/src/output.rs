//! Files written from Python: into a folder that exists. The command line creates a
//! missing output folder (`mkdir -p`); a library call does not, so that a typo in a path
//! is an error naming the folder instead of a new folder tree.

use std::path::Path;

use pyo3::PyResult;
use pyo3::exceptions::{PyFileNotFoundError, PyNotADirectoryError};

/// Refuses `path` unless its folder exists: `FileNotFoundError` naming the missing folder
/// (`NotADirectoryError` when it is a file).
pub(crate) fn check_folder(path: &Path) -> PyResult<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => return Ok(()),
    };
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => Ok(()),
        Ok(_) => Err(PyNotADirectoryError::new_err(format!(
            "{}: {} is not a folder",
            path.display(),
            dir.display()
        ))),
        Err(_) => Err(PyFileNotFoundError::new_err(format!(
            "{}: the folder {} does not exist (create it first; diffsvg does not create \
             folders)",
            path.display(),
            dir.display()
        ))),
    }
}

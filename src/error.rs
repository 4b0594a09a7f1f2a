//! Library errors. Each names the file (or input) and the problem.

use std::path::PathBuf;

/// Errors from loading, rendering and saving.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    #[error("{path}: {cause}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause, written into the message (not chained, so that it is said once).
        cause: std::io::Error,
    },
    /// The SVG could not be parsed.
    #[error("{path}: malformed SVG: {message}")]
    Svg {
        /// The file (or `<string>`).
        path: PathBuf,
        /// What the parser said.
        message: String,
    },
    /// The SVG uses something diffsvg does not render.
    #[error("{path}: unsupported: {what}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// The element or feature, with its id when it has one.
        what: String,
    },
    /// A number is NaN, infinite or out of range.
    #[error("{path}: invalid value: {what}")]
    InvalidValue {
        /// The file or input.
        path: PathBuf,
        /// Which value and why.
        what: String,
    },
    /// An option of a job is out of range (checked before any file is read).
    #[error("{name} {message}")]
    Setting {
        /// The option, as its field is named in the library (`max_gaussians`).
        name: String,
        /// The value and the problem (`"0 must be at least 1"`).
        message: String,
    },
    /// An output path cannot be written (wrong extension, a folder, an unwritable place),
    /// found before the work that would write it.
    #[error("{path}: {message}")]
    Output {
        /// The output path.
        path: PathBuf,
        /// The problem.
        message: String,
    },
    /// An image could not be decoded or encoded, or has the wrong size.
    #[error("{path}: {message}")]
    Image {
        /// The file.
        path: PathBuf,
        /// The problem.
        message: String,
    },
}

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Wraps an I/O error with its file.
    pub fn io(path: impl Into<PathBuf>, cause: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            cause,
        }
    }
}

//! The library's error type: every user-facing failure names the file and the element at fault.

use std::path::{Path, PathBuf};

/// Errors returned by clothsr's library functions.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file's content is wrong: malformed, inconsistent or out of range.
    #[error("{path}: {message}")]
    BadInput {
        /// The file at fault.
        path: PathBuf,
        /// What is wrong, naming the element (panel, edge, prim, line).
        message: String,
    },
    /// A pattern or mesh is invalid regardless of where it came from.
    #[error("{0}")]
    Invalid(String),
    /// Reading or writing a file failed.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error (in the message, not also as the error's source: the CLI prints the
        /// whole chain, which then said it twice).
        error: std::io::Error,
    },
    /// The simulation could not continue (NaN, no progress, penetration) even with smaller steps.
    #[error("simulation failed: {0}")]
    Simulation(String),
    /// The embedded Python / usd-core bridge failed.
    #[error("{0}")]
    Bridge(String),
}

impl Error {
    /// A bad-input error for `path`.
    pub fn bad_input(path: impl AsRef<Path>, message: impl Into<String>) -> Self {
        Error::BadInput {
            path: path.as_ref().to_path_buf(),
            message: message.into(),
        }
    }

    /// An I/O error for `path`.
    pub fn io(path: impl AsRef<Path>, error: std::io::Error) -> Self {
        Error::Io {
            path: path.as_ref().to_path_buf(),
            error,
        }
    }

    /// Attach a file to an [`Error::Invalid`] so the message names it.
    pub fn in_file(self, path: impl AsRef<Path>) -> Self {
        match self {
            Error::Invalid(message) => Error::bad_input(path, message),
            other => other,
        }
    }
}

/// Result alias used throughout the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

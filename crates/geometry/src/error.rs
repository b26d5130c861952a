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
    #[error("{message}")]
    Bridge {
        /// What failed; the bridge's own errors name the file and the element.
        message: String,
        /// The bridge refused a file's content (as [`Error::BadInput`]), rather than failing.
        input: bool,
    },
    /// The caller asked for something that cannot be done (an option out of range, a
    /// combination that does not go together), whatever the files hold.
    #[error("{0}")]
    Usage(String),
}

/// What kind of failure an [`Error`] is, for whoever acts on it: a farm reads it as the exit
/// code of the `clothsr` command, the Python package as the exception type; in JSON, its
/// [`ErrorKind::name`].
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum ErrorKind {
    /// The request itself is wrong: fix the command line or the call.
    Usage,
    /// An input file (scene, garment, avatar, models folder) is wrong: fix the file.
    Input,
    /// The work failed while running (a simulation that cannot go on, a full disk, the USD
    /// library): retrying elsewhere, or reporting it, are the options.
    Failure,
}

impl ErrorKind {
    /// The `clothsr` command's exit code: 2 usage (as clap's own), 3 input, 4 failure.
    pub fn exit_code(self) -> i32 {
        match self {
            ErrorKind::Usage => 2,
            ErrorKind::Input => 3,
            ErrorKind::Failure => 4,
        }
    }

    /// A name for machine-readable reports: `usage`, `input` or `failure`.
    pub fn name(self) -> &'static str {
        match self {
            ErrorKind::Usage => "usage",
            ErrorKind::Input => "input",
            ErrorKind::Failure => "failure",
        }
    }
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

    /// What kind of failure this is.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Error::Usage(_) => ErrorKind::Usage,
            Error::BadInput { .. } | Error::Invalid(_) => ErrorKind::Input,
            Error::Bridge { input: true, .. } => ErrorKind::Input,
            Error::Io { error, .. } if error.kind() == std::io::ErrorKind::NotFound => {
                ErrorKind::Input
            }
            Error::Io { .. } | Error::Simulation(_) | Error::Bridge { .. } => ErrorKind::Failure,
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

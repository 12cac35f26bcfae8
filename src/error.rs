//! The library's one error type. Front ends print it with `{err:#}` and exit with code 2.

use std::path::PathBuf;

/// Everything that can go wrong in the library.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The user (or a cancel button, or Ctrl+C) stopped the work.
    #[error("cancelled")]
    Cancelled,
    /// A parameter or an in-memory input is unusable; the message says which and why.
    #[error("{0}")]
    InvalidInput(String),
    /// A file could not be read, decoded or written.
    #[error("{}: {message}", path.display())]
    File {
        /// The file at fault.
        path: PathBuf,
        /// What is wrong with it, one line.
        message: String,
    },
    /// A learned model failed to load or produced unusable output.
    #[error("model {}: {message}", path.display())]
    Model {
        /// The model (or manifest) file.
        path: PathBuf,
        /// What is wrong, one line.
        message: String,
    },
    /// No usable GPU adapter, or the GPU reported an error (validation, out of memory, lost).
    #[error("GPU: {0}")]
    Gpu(String),
}

impl Error {
    /// Shorthand for [`Error::InvalidInput`].
    pub fn invalid(message: impl Into<String>) -> Self {
        Error::InvalidInput(message.into())
    }

    /// Shorthand for [`Error::File`].
    pub fn file(path: impl Into<PathBuf>, message: impl std::fmt::Display) -> Self {
        Error::File {
            path: path.into(),
            message: message.to_string(),
        }
    }
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

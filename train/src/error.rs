//! Errors of the training crate: each names the file or field and the reason.

use std::path::PathBuf;

/// Everything that can stop a training run or its set-up.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// A file-system operation failed.
    #[error("{op} {path}: {source}")]
    Io {
        /// What was being done ("create run folder", "write", ...).
        op: &'static str,
        /// The file or folder.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A TOML config is malformed, has unknown or missing keys, or has an invalid value.
    #[error("config {path}: {reason}")]
    Config {
        /// The config file (or `<string>`).
        path: PathBuf,
        /// What is wrong, naming the field.
        reason: String,
    },
    /// A checkpoint could not be written or read.
    #[error("checkpoint {path}: {reason}")]
    Checkpoint {
        /// The checkpoint folder or file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A loss term or the gradient norm became NaN or infinite; the run stopped without saving.
    #[error(
        "non-finite {what} ({value}) at step {step}; the run stopped. Last good checkpoint: {}",
        last_good.as_ref().map_or_else(|| "none yet".to_string(), |p| p.display().to_string())
    )]
    NonFinite {
        /// The optimiser step at which it happened (1-based: the step being computed).
        step: u64,
        /// Which quantity ("loss term `rec`", "gradient norm").
        what: String,
        /// The value that was seen.
        value: f64,
        /// The newest checkpoint written before, to resume or inspect.
        last_good: Option<PathBuf>,
    },
    /// The backend could not be started.
    #[error(transparent)]
    Backend(#[from] crate::backend::BackendError),
    /// Anything reported by the data or model crates.
    #[error("{0}")]
    Other(String),
}

/// Result alias of this crate.
pub type Result<T, E = TrainError> = std::result::Result<T, E>;

/// Wraps an `io::Error` with the operation and path.
pub(crate) fn io_err(op: &'static str, path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> TrainError {
    let path = path.into();
    move |source| TrainError::Io { op, path, source }
}

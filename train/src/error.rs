//! Errors of the training crate: each names the file, run folder or field and the reason; the other crates' errors
//! pass through typed (`#[from]`), so a caller can tell a bad clip from a bad checkpoint.

use std::path::PathBuf;

use any4d_data::DataError;
use any4d_eval::metrics::EvalError;
use any4d_model::attention::EdgeListError;
use any4d_model::latent_stats::LatentStatsError;
use any4d_model::text::TextError;

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
    /// A run folder lacks a file, holds a bad one, or does not fit what it is used with.
    #[error("run {run}: {reason}")]
    Run {
        /// The run folder.
        run: PathBuf,
        /// What is wrong, naming the file.
        reason: String,
    },
    /// What a command was given does not fit together: a config and its data or VAE, a method and its runs.
    #[error("{0}")]
    Setup(String),
    /// `--devices` / `--strategy` name something this build or burn cannot do.
    #[error("{0}")]
    Devices(String),
    /// An invariant of the training loop broke (a worker panicked, an objective returned the wrong number of terms).
    #[error("training loop: {0}")]
    Loop(String),
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
    /// A clip, store, manifest or evaluation output (data and eval crates).
    #[error(transparent)]
    Data(#[from] DataError),
    /// A metric could not be computed (eval crate).
    #[error(transparent)]
    Eval(#[from] EvalError),
    /// A tokenizer or text-encoder weight file (model crate).
    #[error(transparent)]
    Text(#[from] TextError),
    /// A mesh's edge list (model crate).
    #[error(transparent)]
    EdgeList(#[from] EdgeListError),
    /// Latent statistics that cannot standardise (model crate).
    #[error(transparent)]
    LatentStats(#[from] LatentStatsError),
}

/// Result alias of this crate.
pub type Result<T, E = TrainError> = std::result::Result<T, E>;

/// Wraps an `io::Error` with the operation and path.
pub(crate) fn io_err(op: &'static str, path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> TrainError {
    let path = path.into();
    move |source| TrainError::Io { op, path, source }
}

/// A run-folder error for `run`.
pub(crate) fn run_err(run: impl Into<PathBuf>, reason: impl Into<String>) -> TrainError {
    TrainError::Run {
        run: run.into(),
        reason: reason.into(),
    }
}

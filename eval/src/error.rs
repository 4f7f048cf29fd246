//! Why an evaluation could not be computed: [`EvalError`], the error of every metric, baseline, method, table and
//! view of the crate. A clip or store that cannot be read passes through as the data crate's error.

use std::path::Path;

use any4d_data::DataError;

/// Why an evaluation could not be computed. Every variant names what differs, what is missing or what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvalError {
    /// A clip, store or file the evaluation reads (data crate).
    #[error(transparent)]
    Data(#[from] DataError),
    /// An evaluation input, output, run or setting that cannot be used: `what: field: reason`, the data crate's form.
    #[error("{what}: {field}: {reason}")]
    Invalid {
        /// The file, folder, method or clip concerned.
        what: String,
        /// The field, key, flag or location.
        field: String,
        /// Why.
        reason: String,
    },
    /// Prediction and ground truth disagree on a size.
    #[error("{what} differ: prediction has {pred}, ground truth has {gt}")]
    Mismatch { what: &'static str, pred: usize, gt: usize },
    /// A flat vertex array does not hold `frames × n_vertices` rows.
    #[error("vertex array holds {rows} rows, expected frames × vertices = {frames} × {n_vertices}")]
    Layout {
        rows: usize,
        frames: usize,
        n_vertices: usize,
    },
    /// A sequence has no frames or no vertices.
    #[error("{name} is empty: {frames} frames × {n_vertices} vertices")]
    Empty {
        name: &'static str,
        frames: usize,
        n_vertices: usize,
    },
    /// NaN or infinity in an input.
    #[error("{name}: non-finite coordinate {value:?} at frame {frame}, vertex {vertex}")]
    NonFinite {
        name: &'static str,
        frame: usize,
        vertex: usize,
        value: [f32; 3],
    },
    /// A keyframe or scored frame index past the last frame.
    #[error("{what} index {index} is out of range for {frames} frames")]
    FrameOutOfRange {
        what: &'static str,
        index: usize,
        frames: usize,
    },
    /// A metric needs more frames than the sequence has.
    #[error("{metric} needs at least {needed} frames, the sequence has {frames}")]
    TooFewFrames {
        metric: &'static str,
        needed: usize,
        frames: usize,
    },
    /// The frame set a metric averages over is empty.
    #[error("no frames to score: {0}")]
    NoFrames(String),
    /// A point set of the Chamfer distance is empty.
    #[error("{name} has no points")]
    EmptySet { name: &'static str },
    /// The average of no clips (`metrics::average`).
    #[error("no clips to average")]
    NoClips,
    /// A parameter outside its domain (e.g. a non-positive frame rate).
    #[error("invalid {name}: {reason}")]
    Parameter { name: &'static str, reason: String },
}

impl EvalError {
    /// [`EvalError::Invalid`] of `what` (a path, or a name), `field` and `reason`.
    pub fn invalid(what: impl AsRef<Path>, field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Invalid {
            what: what.as_ref().display().to_string(),
            field: field.into(),
            reason: reason.into(),
        }
    }

    /// The same error reported against `path` (a manifest checked before its file was known).
    pub fn at(self, path: impl AsRef<Path>) -> Self {
        match self {
            Self::Invalid { field, reason, .. } => Self::Invalid {
                what: path.as_ref().display().to_string(),
                field,
                reason,
            },
            Self::Data(e) => Self::Data(e.at(path)),
            other => other,
        }
    }

    /// What an [`EvalError::Invalid`] or a data error names (file, folder, method or clip); empty for the others.
    pub fn what(&self) -> &str {
        match self {
            Self::Invalid { what, .. } | Self::Data(DataError { path: what, .. }) => what,
            _ => "",
        }
    }

    /// The field of an [`EvalError::Invalid`] or of a data error; empty for the others.
    pub fn field(&self) -> &str {
        match self {
            Self::Invalid { field, .. } | Self::Data(DataError { field, .. }) => field,
            _ => "",
        }
    }

    /// The reason of an [`EvalError::Invalid`] or of a data error; empty for the others.
    pub fn reason(&self) -> &str {
        match self {
            Self::Invalid { reason, .. } | Self::Data(DataError { reason, .. }) => reason,
            _ => "",
        }
    }

    /// An I/O failure on `path`.
    pub fn io(path: impl AsRef<Path>, err: std::io::Error) -> Self {
        Self::invalid(path, "file", err.to_string())
    }
}

pub type Result<T, E = EvalError> = std::result::Result<T, E>;

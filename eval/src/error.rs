//! Why an evaluation could not be computed: [`EvalError`], the error of every metric and baseline.

/// Why a metric could not be computed. Every variant names what differs or what is missing.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvalError {
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

pub type Result<T, E = EvalError> = std::result::Result<T, E>;

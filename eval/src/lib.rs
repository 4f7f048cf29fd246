//! Evaluation (docs/method.md §5–§7): metrics as pure functions, baselines, the long-horizon rollout, paper tables,
//! and the HTML clip viewer ([`view`]).

pub mod acap_bdlstm;
pub mod baselines;
pub mod bench;
mod error;
pub mod learned;
pub mod methods;
pub mod metrics;
mod nearest;
pub mod plot;
pub mod protocol;
pub mod render;
pub mod rollout;
pub mod scene_metrics;
pub mod tables;
pub mod view;

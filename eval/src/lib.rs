//! Evaluation (SPEC §5–§7): metrics as pure functions, baselines, the long-horizon rollout, paper tables.

pub mod metrics;
pub mod baselines;
pub mod protocol;
pub mod rollout;
pub mod tables;
pub mod plot;
pub mod methods;
pub mod render;
pub mod run;
pub mod learned;

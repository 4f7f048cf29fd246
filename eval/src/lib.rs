//! Evaluation (SPEC §5–§7): metrics as pure functions, baselines, the long-horizon rollout, paper tables.

pub mod metrics;
pub mod baselines;

//! Training loops, run folders and the `any4d` CLI (the only place that parses arguments).
//!
//! Code map: [`config`] (run TOML), [`backend`] (runtime device), [`run_folder`] + [`checkpoint`] +
//! [`data_order`] (append-only runs that resume exactly), [`loop_common`] (the shared loop), [`progress`],
//! [`plot`].

pub mod cli;

pub mod backend;
pub mod checkpoint;
pub mod config;
pub mod data_order;
pub mod error;
pub mod loop_common;
pub mod plot;
pub mod progress;
pub mod run_folder;

pub use error::{Result, TrainError};

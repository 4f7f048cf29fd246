//! Training loops, run folders and trained runs: everything that writes or reads `runs/…`.
//!
//! Code map: [`config`] (run TOML: `extends`, `--set`, strict parse), [`backend`] (runtime device),
//! [`run_folder`] + [`checkpoint`] + [`data_order`] (append-only runs that resume exactly), [`loop_common`] (the
//! shared loop), [`multi_device`] (its data-parallel strategies), [`progress`], [`plot`], [`vae_loop`]
//! (docs/method.md §3), [`rf_loop`] (docs/method.md §4), [`runs`] (loading trained VAE and RF runs), [`evaluate`]
//! (run folders → evaluation methods), [`run_config`] (a run config of any kind), [`complete`] (a trained model on a user's meshes), [`quickstart`], [`bench`] (`any4d bench train`).

pub mod backend;
pub mod bdlstm;
pub mod bdlstm_acap;
pub mod bdlstm_loop;
pub mod bench;
pub mod checkpoint;
pub mod complete;
pub mod config;
pub mod data_order;
pub mod devices;
pub mod error;
pub mod evaluate;
pub mod grad_clip;
pub mod interop;
pub mod loop_common;
pub mod multi_device;
pub mod pack;
pub mod plot;
pub mod progress;
pub mod quickstart;
pub mod rf_loop;
pub mod run_config;
pub mod run_folder;
pub mod runs;
pub mod vae_loop;

pub use error::{Result, TrainError};

//! Trained networks on the evaluation protocol (docs/method.md §4.6, §5.1, §5.2 `lerp_space = "latent"`, §5.4, §6.1,
//! (E4)): one window (batch 1) is encoded with the mesh VAE, completed by the keyframe RF ((R3)–(R6)), the
//! replacement baseline ((R7)–(R8)), impute-until-τ* ((R9)) or latent interpolation ((L1) on z), and decoded.
//!
//! [`MeshCodec`] turns a normalised window into VAE tensors (FPS on frame 0, edges from faces, padding) and back;
//! [`LearnedModels`] holds one RF checkpoint with its VAE, latent statistics and text encoder; [`RfSampler`],
//! [`LatentLerpSampler`], [`VaeOracleSampler`] and [`VaeReconstructor`] are the eval crate's [`WindowSampler`] /
//! [`Reconstructor`].

mod bdlstm;
mod codec;
mod models;
mod rf;
mod vae;

pub use bdlstm::*;
pub use codec::*;
pub use models::*;
pub use rf::*;
pub use vae::*;

pub use any4d_model::rectified_flow::sampler_noise;

//! Networks of CompletionAny4D (docs/method.md §3–§5): frame-wise mesh VAE, keyframe-conditioned rectified-flow MMDiT,
//! the sequence-wise DyMeshVAE ablation, text encoders. No file IO except weight loading.

pub mod anchor;
pub mod any_vae;
pub mod attention;
pub mod bdlstm;
pub mod bench;
pub mod denormals;
pub mod dymesh_vae;
pub mod frame_vae;
pub mod gelu;
pub mod interop;
pub mod latent_stats;
pub mod mesh_vae;
pub mod mmdit;
pub mod noise;
pub mod point_embed;
pub mod probe;
pub mod rectified_flow;
pub mod summary;
pub mod text;

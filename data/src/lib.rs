//! Clips in and out, preprocessing, the dataset store and burn batches (docs/method.md §2).
//!
//! Formats: DyMesh `.bin` (restricted unpickler, never executes), OBJ sequences, glTF/GLB, and the animated game
//! and capture formats IQM, MD5, MD2, MD3, 0 A.D. PMD/PSA and DeformingThings4D `.anime` (takes, skinning bake).
//! Preprocessing: welding, frame-0 normalisation (D1)–(D3), vertex filter, windows, FPS, padding.

pub mod acap;
pub mod archive;
pub mod augment;
pub mod batch;
pub mod bench;
pub mod caption;
pub mod clip;
pub mod error;
pub mod formats;
pub mod fps;
pub mod inspect;
pub mod io;
pub mod keyframes;
pub mod limits;
pub mod mat3;
pub mod preprocess;
pub mod real_corpus;
pub mod reference;
pub mod render;
pub mod rng;
pub mod scene;
pub mod store;
pub mod synth;

pub use clip::Clip;
pub use error::{DataError, Result};

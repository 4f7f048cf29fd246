//! Clips in and out, preprocessing, the dataset store and burn batches (docs/method.md §2).
//!
//! Formats: DyMesh `.bin` (restricted unpickler, never executes), OBJ sequences, glTF/GLB.
//! Preprocessing: welding, frame-0 normalisation (D1)–(D3), vertex filter, windows, FPS, padding.

pub mod acap;
pub mod batch;
pub mod bench;
pub mod clip;
pub mod error;
pub mod formats;
pub mod fps;
pub mod inspect;
pub mod keyframes;
pub mod limits;
pub mod preprocess;
pub mod render;
pub mod rng;
pub mod store;
pub mod synth;

pub use clip::Clip;
pub use error::{DataError, Result};

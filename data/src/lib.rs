//! Preprocessing, the dataset store, procedural clips and burn batches (docs/method.md §2), on the clips that
//! `any4d-formats` reads and writes (re-exported here as [`formats`], with its [`clip`], [`error`], [`io`],
//! [`limits`] and [`mat3`], so that every crate above reaches clips through this one).
//!
//! Preprocessing: welding, frame-0 normalisation (D1)–(D3), vertex filter, windows, FPS, padding.

pub mod acap;
pub mod archive;
pub mod augment;
pub mod batch;
pub mod bench;
pub mod caption;
pub mod fps;
pub mod inspect;
pub mod keyframes;
pub mod preprocess;
pub mod real_corpus;
pub mod reference;
pub mod render;
pub mod rng;
pub mod scene;
pub mod store;
pub mod synth;

pub use any4d_formats::{self as formats, clip, error, io, limits, mat3};
pub use clip::Clip;
pub use error::{DataError, Result};

//! Clip file formats, one module each, and dispatch by extension.

pub mod pickle;
pub mod dymesh_bin;
pub mod obj;
pub mod gltf;

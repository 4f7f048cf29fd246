//! Clip file formats (docs/method.md §2.1), one module each, and dispatch by extension.
//!
//! Readers return the file's coordinates, vertex order and faces unchanged (glTF: the world-space positions a
//! viewer shows); normalisation is preprocessing's job.

pub mod dymesh_bin;
pub mod gltf;
pub mod obj;
pub mod pickle;

use std::path::Path;

use crate::clip::Clip;
use crate::error::{DataError, Result};

/// A clip file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// DyMesh pickle `.bin` (also `.pkl`, `.pickle`).
    Bin,
    /// A folder of per-frame `.obj` files.
    ObjSeq,
    /// glTF 2.0 JSON with embedded or external buffers.
    Gltf,
    /// Binary glTF.
    Glb,
}

impl Format {
    /// The format of `path`: an existing folder, or a path without extension, is an OBJ sequence; otherwise the
    /// extension decides (case-insensitive).
    pub fn from_path(path: &Path) -> Result<Format> {
        if path.is_dir() {
            return Ok(Format::ObjSeq);
        }
        let Some(ext) = path.extension() else {
            return Ok(Format::ObjSeq);
        };
        match ext.to_string_lossy().to_ascii_lowercase().as_str() {
            "bin" | "pkl" | "pickle" => Ok(Format::Bin),
            "gltf" => Ok(Format::Gltf),
            "glb" => Ok(Format::Glb),
            "obj" => Err(DataError::new(
                path,
                "format",
                "a single .obj is one frame; give the folder of frames",
            )),
            other => Err(DataError::new(
                path,
                "format",
                format!("unknown extension `.{other}` (expected .bin, .pkl, .gltf, .glb or a folder of .obj)"),
            )),
        }
    }
}

/// Read a clip in the format of its path (glTF with [`gltf::GltfReadOptions::default`]).
pub fn read_clip(path: &Path) -> Result<Clip> {
    match Format::from_path(path)? {
        Format::Bin => dymesh_bin::read_bin(path),
        Format::ObjSeq => obj::read_obj_seq(path),
        Format::Gltf | Format::Glb => gltf::read_gltf(path, &gltf::GltfReadOptions::default()),
    }
}

/// Write a clip in the format of its path (glTF at [`gltf::DEFAULT_FPS`]).
pub fn write_clip(path: &Path, clip: &Clip) -> Result<()> {
    match Format::from_path(path)? {
        Format::Bin => dymesh_bin::write_bin(path, clip),
        Format::ObjSeq => obj::write_obj_seq(path, clip),
        Format::Gltf | Format::Glb => gltf::write_gltf(path, clip, gltf::DEFAULT_FPS),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_by_extension() {
        assert_eq!(Format::from_path(Path::new("a/x.BIN")).unwrap(), Format::Bin);
        assert_eq!(Format::from_path(Path::new("a/x.gltf")).unwrap(), Format::Gltf);
        assert_eq!(Format::from_path(Path::new("a/x.glb")).unwrap(), Format::Glb);
        assert_eq!(Format::from_path(Path::new("a/new_seq")).unwrap(), Format::ObjSeq);
        assert_eq!(
            Format::from_path(Path::new(env!("CARGO_MANIFEST_DIR"))).unwrap(),
            Format::ObjSeq
        );
        assert_eq!(Format::from_path(Path::new("x.fbx")).unwrap_err().field, "format");
        assert!(
            Format::from_path(Path::new("x.obj"))
                .unwrap_err()
                .reason
                .contains("folder")
        );
    }
}

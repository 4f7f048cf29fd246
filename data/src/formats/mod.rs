//! Clip file formats (docs/method.md §2.1), one module each, and dispatch by extension.
//!
//! Readers return the file's coordinates, vertex order and faces unchanged (glTF: the world-space positions a
//! viewer shows); normalisation is preprocessing's job.

pub mod dymesh_bin;
pub mod gltf;
pub mod obj;
pub mod pickle;

use std::io::Read;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use crate::clip::Clip;
use crate::error::{DataError, Result};

/// Largest clip file (`.bin`, `.gltf`, `.glb`, one `.obj` frame) read into memory: 4 GiB, far above any clip the
/// method uses (a 4096-vertex, 300-frame clip is 15 MB), so only a wrong path (a disk image, `/dev/zero`) hits it.
pub const MAX_FILE_BYTES: u64 = 1 << 32;

/// Field of the error that [`guard`] makes from a panic.
pub const PANIC_FIELD: &str = "panic";

/// Read a whole regular file of at most `limit` bytes. FIFOs, devices and folders are refused before they are
/// opened (reading one could block or never end), and the size is checked before anything is allocated.
pub fn read_file(path: &Path, limit: u64) -> Result<Vec<u8>> {
    let meta = std::fs::metadata(path).map_err(|e| DataError::io(path, e))?;
    if !meta.is_file() {
        return Err(DataError::new(
            path,
            "file",
            "not a regular file (a folder, FIFO or device is not read)",
        ));
    }
    if meta.len() > limit {
        return Err(DataError::new(
            path,
            "file",
            format!("{} bytes, more than the limit of {limit} bytes", meta.len()),
        ));
    }
    let file = std::fs::File::open(path).map_err(|e| DataError::io(path, e))?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(limit + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| DataError::io(path, e))?;
    if bytes.len() as u64 > limit {
        return Err(DataError::new(
            path,
            "file",
            format!("grew past the limit of {limit} bytes while being read"),
        ));
    }
    Ok(bytes)
}

/// Run one file's read, turning a panic anywhere below it into an error naming the file (field [`PANIC_FIELD`]).
/// Readers validate their input, so a panic here is a bug; the guard keeps it from aborting an import of many
/// files. The panic message still goes to the process's panic hook (stderr by default), which helps report it.
pub fn guard<T>(path: &Path, read: impl FnOnce() -> Result<T>) -> Result<T> {
    catch_unwind(AssertUnwindSafe(read)).unwrap_or_else(|payload| {
        let message = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a non-text panic payload".into());
        Err(DataError::new(
            path,
            PANIC_FIELD,
            format!("the reader panicked (a bug in any4d, please report it): {message}"),
        ))
    })
}

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

/// Read a clip in the format of its path (glTF with [`gltf::GltfReadOptions::default`]), under [`guard`].
pub fn read_clip(path: &Path) -> Result<Clip> {
    let format = Format::from_path(path)?;
    guard(path, || match format {
        Format::Bin => dymesh_bin::read_bin(path),
        Format::ObjSeq => obj::read_obj_seq(path),
        Format::Gltf | Format::Glb => gltf::read_gltf(path, &gltf::GltfReadOptions::default()),
    })
}

/// Write a clip in the format of its path (glTF at [`gltf::DEFAULT_FPS`]). The clip is validated first, so no
/// file is written that the readers would refuse.
pub fn write_clip(path: &Path, clip: &Clip) -> Result<()> {
    clip.validate()?;
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

//! Clip files in and out (docs/method.md §2.1): the clip itself ([`clip::Clip`]), one module per file format,
//! dispatch by extension, the byte and size limits every reader checks before it allocates ([`limits`]), one
//! fsyncing file writer ([`io`]) and the error every reader returns ([`error::DataError`]: file, field, reason).
//! Preprocessing, the dataset store and everything built on clips live in `any4d-data`, which re-exports this crate
//! as `any4d_data::formats`.
//!
//! Readers return the file's coordinates, vertex order and faces unchanged (glTF: the world-space positions a
//! viewer shows; the Z-up game formats turned Y-up, see [`skeletal`]); normalisation is preprocessing's job.
//!
//! Animated game formats hold several takes (animations) per file: [`list_takes`] names them, [`read_take`]
//! bakes one ([`skeletal::TakeSel`]), and [`read_clip`] reads the first. Animation-only companions
//! (`.md5anim`, `.psa`, `.anm`, animation-only `.iqm`, `.bvh` for a rigged `.iqm`) are found beside their mesh and
//! are not clips themselves.

pub mod anime;
pub mod b3d;
pub mod bvh;
pub mod bytes;
pub mod clip;
pub mod dae;
pub mod dymesh_bin;
pub mod error;
pub mod fbx;
pub mod gltf;
pub mod io;
pub mod iqm;
pub mod limits;
pub mod mat3;
pub mod md2;
pub mod md3;
pub mod md5;
pub mod obj;
pub mod pickle;
pub mod pmd;
pub mod skeletal;
pub mod spm;
pub mod x;

use std::io::Read;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use crate::clip::Clip;
use crate::error::{DataError, Result};
use skeletal::{ReadOptions, SkinStats, TakeInfo};

/// Largest clip file (`.bin`, `.gltf`, `.glb`, one `.obj` frame) read into memory by default: 4 GiB, far above any
/// clip the method uses (a 4096-vertex, 300-frame clip is 15 MB), so only a wrong path (a disk image, `/dev/zero`)
/// hits it. The current value is [`FILE_BYTES`](crate::limits::FILE_BYTES) (`--limit-file-bytes`).
pub use crate::limits::MAX_FILE_BYTES;

/// [`read_file`] with the current clip-file limit ([`FILE_BYTES`](crate::limits::FILE_BYTES)).
pub fn read_clip_file(path: &Path) -> Result<Vec<u8>> {
    read_file(path, crate::limits::FILE_BYTES.get())
}

/// Field of the error that [`guard`] makes from a panic.
pub const PANIC_FIELD: &str = "panic";

/// Read a whole regular text file of at most `limit` bytes as UTF-8 (the checks of [`read_file`]).
pub fn read_text_file(path: &Path, limit: u64) -> Result<String> {
    let bytes = read_file(path, limit)?;
    String::from_utf8(bytes).map_err(|e| DataError::new(path, "file", format!("not UTF-8 text: {e}")))
}

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
            format!(
                "{} bytes, more than the limit of {limit} bytes{}",
                meta.len(),
                file_hint(limit)
            ),
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
            format!(
                "grew past the limit of {limit} bytes while being read{}",
                file_hint(limit)
            ),
        ));
    }
    Ok(bytes)
}

/// Names the flag when `limit` is the adjustable clip-file limit.
fn file_hint(limit: u64) -> String {
    let l = &crate::limits::FILE_BYTES;
    if limit == l.get() { l.hint() } else { String::new() }
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
    /// Inter-Quake Model `.iqm`.
    Iqm,
    /// Doom 3 `.md5mesh` (with the `.md5anim` files beside it).
    Md5,
    /// Quake II `.md2`.
    Md2,
    /// Quake III `.md3`.
    Md3,
    /// 0 A.D. `.pmd` (with the `.psa` files beside it).
    Pmd,
    /// DeformingThings4D `.anime`.
    Anime,
    /// Blitz3D `.b3d` (Minetest, Irrlicht).
    B3d,
    /// SuperTuxKart `.spm`.
    Spm,
    /// DirectX `.x` (text form).
    X,
    /// Binary FBX 7.
    Fbx,
    /// COLLADA `.dae`.
    Dae,
}

impl Format {
    /// Short lower-case name, as in the store index's `format` column.
    pub fn name(self) -> &'static str {
        match self {
            Format::Bin => "bin",
            Format::ObjSeq => "obj-seq",
            Format::Gltf => "gltf",
            Format::Glb => "glb",
            Format::Iqm => "iqm",
            Format::Md5 => "md5",
            Format::Md2 => "md2",
            Format::Md3 => "md3",
            Format::Pmd => "pmd",
            Format::Anime => "anime",
            Format::B3d => "b3d",
            Format::Spm => "spm",
            Format::X => "x",
            Format::Fbx => "fbx",
            Format::Dae => "dae",
        }
    }

    /// Whether files of this format hold takes ([`list_takes`]) rather than exactly one clip.
    pub fn has_takes(self) -> bool {
        !matches!(self, Format::Bin | Format::ObjSeq)
    }
}

/// Extensions (lower case) of the files an import picks up as clip sources.
pub const SOURCE_EXTENSIONS: &[&str] = &[
    "bin", "pkl", "pickle", "gltf", "glb", "iqm", "md5mesh", "md2", "md3", "pmd", "anime", "b3d", "spm", "x", "fbx",
    "dae",
];

/// Whether `path` is a clip source for an import: a file with one of [`SOURCE_EXTENSIONS`], except an
/// animation-only `.iqm` (a companion of a mesh file) and the parts of a Quake III player other than its
/// `lower.md3` ([`md3::is_source`]).
pub fn is_source(path: &Path) -> bool {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("iqm") => iqm::has_mesh(path),
        Some("md3") => md3::is_source(path),
        Some(e) => SOURCE_EXTENSIONS.contains(&e),
        None => false,
    }
}

/// The path whose name says what the source `path` is, for its caption: the folder of an assembled Quake III
/// player (its `lower.md3` is named for the body part, the folder for the character), else `path` itself.
pub fn asset_path(path: &Path) -> std::path::PathBuf {
    let player = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("md3")) && md3::Player::of(path).is_some();
    match path.parent() {
        Some(dir) if player && !dir.as_os_str().is_empty() => dir.to_path_buf(),
        _ => path.to_path_buf(),
    }
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
            "iqm" => Ok(Format::Iqm),
            "md5mesh" => Ok(Format::Md5),
            "md2" => Ok(Format::Md2),
            "md3" => Ok(Format::Md3),
            "pmd" => Ok(Format::Pmd),
            "anime" => Ok(Format::Anime),
            "b3d" => Ok(Format::B3d),
            "spm" => Ok(Format::Spm),
            "x" => Ok(Format::X),
            "fbx" => Ok(Format::Fbx),
            "dae" => Ok(Format::Dae),
            "md5anim" | "psa" | "bvh" => Err(DataError::new(
                path,
                "format",
                "an animation without a mesh: give the mesh file (.md5mesh / .pmd / rigged .iqm) beside it",
            )),
            "obj" => Err(DataError::new(
                path,
                "format",
                "a single .obj is one frame; give the folder of frames",
            )),
            other => Err(DataError::new(
                path,
                "format",
                format!(
                    "unknown extension `.{other}` (expected .bin, .pkl, .gltf, .glb, .iqm, .md5mesh, .md2, .md3, \
                     .pmd, .anime, .b3d, .spm, .x, .fbx, .dae or a folder of .obj)"
                ),
            )),
        }
    }
}

/// Read a clip in the format of its path (the first take of a format with takes), under [`guard`].
pub fn read_clip(path: &Path) -> Result<Clip> {
    Ok(read_take(path, &ReadOptions::default())?.clip)
}

/// A clip read from one take of a file.
#[derive(Debug, Clone)]
pub struct Taken {
    pub clip: Clip,
    /// Skin weights that were renormalised or had more than 4 entries.
    pub stats: SkinStats,
    /// The take read; `None` for a single-clip format.
    pub take: Option<TakeInfo>,
}

/// Read take `opts.take` of `path` (single-clip formats accept only the first take), under [`guard`].
pub fn read_take(path: &Path, opts: &ReadOptions) -> Result<Taken> {
    let format = Format::from_path(path)?;
    guard(path, || read_take_unguarded(path, format, opts))
}

fn read_take_unguarded(path: &Path, format: Format, opts: &ReadOptions) -> Result<Taken> {
    let single = |clip: Clip| -> Result<Taken> {
        if opts.take != skeletal::TakeSel::First && opts.take != skeletal::TakeSel::Index(0) {
            return Err(DataError::new(
                path,
                "take",
                "this format holds one clip; there are no takes to pick",
            ));
        }
        Ok(Taken {
            clip,
            stats: SkinStats::default(),
            take: None,
        })
    };
    let (clip, stats, take) = match format {
        Format::Bin => return single(dymesh_bin::read_bin(path)?),
        Format::ObjSeq => return single(obj::read_obj_seq(path)?),
        Format::Gltf | Format::Glb => gltf::read(path, opts)?,
        Format::Iqm => iqm::read(path, opts)?,
        Format::Md5 => md5::read(path, opts)?,
        Format::Md2 => md2::read(path, opts)?,
        Format::Md3 => md3::read(path, opts)?,
        Format::Pmd => pmd::read(path, opts)?,
        Format::Anime => anime::read(path, opts)?,
        Format::B3d => b3d::read(path, opts)?,
        Format::Spm => spm::read(path, opts)?,
        Format::X => x::read(path, opts)?,
        Format::Fbx => fbx::read(path, opts)?,
        Format::Dae => dae::read(path, opts)?,
    };
    Ok(Taken {
        clip,
        stats,
        take: Some(take),
    })
}

/// The takes of `path`; `None` for a single-clip format. Runs under [`guard`].
pub fn list_takes(path: &Path) -> Result<Option<Vec<TakeInfo>>> {
    let format = Format::from_path(path)?;
    guard(path, || list_takes_unguarded(path, format))
}

fn list_takes_unguarded(path: &Path, format: Format) -> Result<Option<Vec<TakeInfo>>> {
    Ok(Some(match format {
        Format::Bin | Format::ObjSeq => return Ok(None),
        Format::Gltf | Format::Glb => gltf::list_takes(path)?,
        Format::Iqm => iqm::list_takes(path)?,
        Format::Md5 => md5::list_takes(path)?,
        Format::Md2 => md2::list_takes(path)?,
        Format::Md3 => md3::list_takes(path)?,
        Format::Pmd => pmd::list_takes(path)?,
        Format::Anime => anime::list_takes(path)?,
        Format::B3d => b3d::list_takes(path)?,
        Format::Spm => spm::list_takes(path)?,
        Format::X => x::list_takes(path)?,
        Format::Fbx => fbx::list_takes(path)?,
        Format::Dae => dae::list_takes(path)?,
    }))
}

/// The animations of `path` that have one frame, by name: poses, which are not takes (a clip needs motion), listed
/// so that none is dropped unseen (`data inspect`, the import's report). Formats whose takes of one frame are
/// listed as takes (and refused when read) return none. Runs under [`guard`].
pub fn one_frame_takes(path: &Path) -> Result<Vec<String>> {
    let format = Format::from_path(path)?;
    guard(path, || match format {
        Format::Md2 => md2::one_frame_takes(path),
        Format::Md3 => md3::one_frame_takes(path),
        Format::X => x::one_frame_takes(path),
        Format::Fbx => fbx::one_frame_takes(path),
        Format::Dae => dae::one_frame_takes(path),
        _ => Ok(Vec::new()),
    })
}

/// Write a clip in the format of its path (glTF at [`gltf::DEFAULT_FPS`]). The clip is validated first, so no
/// file is written that the readers would refuse.
pub fn write_clip(path: &Path, clip: &Clip) -> Result<()> {
    write_clip_at(path, clip, None)
}

/// [`write_clip`] keeping a frame rate where the format has one (glTF's key times): `Some(fps)` with a rate
/// that [`skeletal::check_fps`] accepts and that is positive (a take's rate), else [`gltf::DEFAULT_FPS`].
pub fn write_clip_at(path: &Path, clip: &Clip, fps: Option<f32>) -> Result<()> {
    clip.validate()?;
    let fps = fps
        .filter(|&f| f > 0.0 && skeletal::fps_in_range(f64::from(f)))
        .unwrap_or(gltf::DEFAULT_FPS);
    match Format::from_path(path)? {
        Format::Bin => dymesh_bin::write_bin(path, clip),
        Format::ObjSeq => obj::write_obj_seq(path, clip),
        Format::Gltf | Format::Glb => gltf::write_gltf(path, clip, fps),
        Format::Anime => crate::io::write_atomic(path, &anime::write_anime(clip)),
        other => Err(DataError::new(
            path,
            "format",
            format!(
                "writing {} is not supported (write .bin, .gltf, .glb, .anime or an OBJ folder)",
                other.name()
            ),
        )),
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
        assert_eq!(Format::from_path(Path::new("x.FBX")).unwrap(), Format::Fbx);
        assert_eq!(Format::from_path(Path::new("x.DAE")).unwrap(), Format::Dae);
        assert_eq!(Format::from_path(Path::new("x.blend")).unwrap_err().field, "format");
        assert_eq!(Format::from_path(Path::new("a/b.MD5MESH")).unwrap(), Format::Md5);
        assert_eq!(
            Format::from_path(Path::new("deer.dae.cached.pmd")).unwrap(),
            Format::Pmd
        );
        assert!(
            Format::from_path(Path::new("walk.md5anim"))
                .unwrap_err()
                .reason
                .contains("mesh")
        );
        assert!(
            Format::from_path(Path::new("x.obj"))
                .unwrap_err()
                .reason
                .contains("folder")
        );
    }
}

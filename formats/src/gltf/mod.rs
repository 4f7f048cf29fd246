//! glTF 2.0 / GLB clips: animation baked to per-frame world-space vertex positions, and a writer that
//! stores a clip as frame-0 mesh + one morph target per frame.
//!
//! Reading takes the animations (all of them when no two target the same node property, as exporters that write
//! one animation per joint do; else the first) and the first triangle primitive of the chosen mesh, samples every channel
//! (STEP, LINEAR with slerp for rotations, CUBICSPLINE) at `t = f / fps` for `f = 0..=⌊duration · fps⌋`, and bakes
//! morph targets (`p = base + Σ_k w_k · target_k`), then skinning (`v = Σ_i w_i · G(joint_i) · IBM_i · p`) or, for
//! an unskinned mesh, the mesh node's world matrix. The caption is `asset.extras.caption` (written by
//! [`write_gltf`]), else " ".
//!
//! # Hostile input
//! The gltf crate only parses and validates the JSON. Everything after that is code of this module, which checks
//! before use every index, accessor type, component type, stride and byte range (`accessor.rs`), and loads the
//! buffers itself (`source.rs`): the GLB chunks inside the file, base64 `data:` URIs, and relative URIs naming a
//! regular file inside the glTF file's folder (no absolute paths, `..`, symlinks out of the folder, FIFOs or
//! devices), each at most [`BUFFER_BYTES`](crate::limits::BUFFER_BYTES) and size-checked before it is read. The frame count is bounded by
//! [`FRAMES`](crate::limits::FRAMES) (a longer animation is an error unless [`GltfReadOptions::max_frames`] asks for its first
//! frames), the baked vertices by [`CLIP_VERTICES`](crate::limits::CLIP_VERTICES), accessors by [`MAX_ACCESSOR_VALUES`] and the baking
//! work by [`MAX_BAKE_STEPS`]. One file's read runs under [`super::guard`], so a panic left anywhere below is an
//! error naming the file rather than an abort.

mod accessor;
mod bake;
mod read;
mod scene;
mod source;
mod write;

use std::path::{Path, PathBuf};

use crate::clip::Clip;
use crate::error::{DataError, Result};
use crate::skeletal::{self, ReadOptions, SkinStats, TakeInfo};

pub use write::{MAX_WRITE_FRAMES, write_gltf};

/// Frame rate used when none is given.
pub const DEFAULT_FPS: f32 = 30.0;
/// Most numbers (count × components) one accessor may decode to: 2^24 are 128 MiB as f64, a 4 M-vertex position
/// accessor; it bounds accessors whose count no buffer bytes back (sparse or without a buffer view).
pub const MAX_ACCESSOR_VALUES: usize = 1 << 24;
/// Largest buffer (GLB chunk, `data:` URI or external file) read by default (`--limit-buffer-bytes`).
pub use crate::limits::MAX_BUFFER_BYTES;
/// Most vertex updates (per frame: vertices × (1 + morph targets with a non-zero weight + joint influences))
/// one read may do: 2^34 is about a minute of baking, so a small file cannot keep an import busy for hours.
pub const MAX_BAKE_STEPS: u64 = 1 << 34;

/// How to bake a glTF animation into frames.
#[derive(Debug, Clone, PartialEq)]
pub struct GltfReadOptions {
    /// Sampling rate in frames per second.
    pub fps: f32,
    /// Keep at most this many frames. `None` bakes the whole animation and refuses one longer than [`FRAMES`](crate::limits::FRAMES);
    /// `Some(m)` keeps the first `m` frames of an animation of any length.
    pub max_frames: Option<usize>,
    /// Mesh index to read; `None` = the first mesh that a node instantiates.
    pub mesh: Option<usize>,
    /// The take baked ([`list_takes`]: all animations when they drive disjoint channels, else one each).
    pub take: usize,
}

impl Default for GltfReadOptions {
    fn default() -> Self {
        Self {
            fps: DEFAULT_FPS,
            max_frames: None,
            mesh: None,
            take: 0,
        }
    }
}

/// Where buffers with a file URI may be read from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ExternalBuffers {
    /// Relative URIs name regular files inside this folder (the glTF file's own).
    Folder(PathBuf),
    /// Only buffers inside the file (GLB chunk, `data:` URIs); a file URI is an error.
    Refuse,
}

/// Read and bake a `.gltf` / `.glb` clip. Errors name the file and the glTF part (field) at fault.
pub fn read_gltf(path: &Path, opts: &GltfReadOptions) -> Result<Clip> {
    super::guard(path, || {
        let bytes = super::read_clip_file(path)?;
        read::read(&bytes, path, opts, &ExternalBuffers::Folder(folder_of(path)))
    })
}

/// The still meshes of a glTF file as one triangle mesh in its world coordinates (unchecked beyond the indices and
/// the triangle count).
#[derive(Debug, Clone, PartialEq)]
pub struct StillMeshes {
    pub vertices: Vec<[f32; 3]>,
    pub faces: Vec<[u32; 3]>,
}

/// The static scene of a `.gltf` / `.glb` (its still meshes beside the animated one, docs/method.md §6.5), or
/// `None` when it has none.
pub fn static_scene(path: &Path) -> Result<Option<StillMeshes>> {
    super::guard(path, || {
        let bytes = super::read_clip_file(path)?;
        scene::static_scene(&bytes, path, &ExternalBuffers::Folder(folder_of(path)))
    })
}

/// The takes of a `.gltf` / `.glb` at [`DEFAULT_FPS`]: one of all its animations when no two drive the same
/// channel (node and property), else one per animation, named after it.
pub fn list_takes(path: &Path) -> Result<Vec<TakeInfo>> {
    let bytes = super::read_clip_file(path)?;
    read::takes(&bytes, path, DEFAULT_FPS, &ExternalBuffers::Folder(folder_of(path)))
}

/// Read take `opts.take` of a `.gltf` / `.glb` at [`DEFAULT_FPS`], its length checked against `opts.max_frames`
/// before it is baked.
pub fn read(path: &Path, opts: &ReadOptions) -> Result<(Clip, SkinStats, TakeInfo)> {
    let bytes = super::read_clip_file(path)?;
    let external = ExternalBuffers::Folder(folder_of(path));
    let takes = read::takes(&bytes, path, DEFAULT_FPS, &external)?;
    if takes.is_empty() {
        return Err(DataError::new(
            path,
            "animations",
            "no animation: a static mesh is not a clip",
        ));
    }
    let k = skeletal::pick(path, &takes, &opts.take)?;
    skeletal::check_frames(path, &takes[k].name, takes[k].frames, opts.max_frames)?;
    let gltf_opts = GltfReadOptions {
        take: k,
        ..GltfReadOptions::default()
    };
    let clip = read::read(&bytes, path, &gltf_opts, &external)?;
    Ok((clip, SkinStats::default(), takes[k].clone()))
}

/// The folder a glTF's relative buffer URIs resolve against.
fn folder_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Read and bake glTF or GLB `bytes`; `path` names the file in errors and gives the clip its id and source.
pub fn read_gltf_bytes(bytes: &[u8], path: &Path, opts: &GltfReadOptions, external: &ExternalBuffers) -> Result<Clip> {
    super::guard(path, || read::read(bytes, path, opts, external))
}

/// The files a `.gltf` names as external buffers (`buffers[].uri` other than `data:`), resolved against its
/// folder: an import leaves them out of its sources, since they are parts of the glTF and not clips. A file that
/// cannot be read or parsed names none (reading it as a clip then says why).
pub fn buffer_files(path: &Path) -> Vec<PathBuf> {
    let Ok(bytes) = super::read_clip_file(path) else {
        return Vec::new();
    };
    let Ok(doc) = serde_json::from_slice::<serde_json::Value>(&bytes) else {
        return Vec::new();
    };
    let folder = path.parent().unwrap_or(Path::new("."));
    doc.get("buffers")
        .and_then(|b| b.as_array())
        .into_iter()
        .flatten()
        .filter_map(|b| b.get("uri")?.as_str())
        .filter(|uri| !uri.starts_with("data:"))
        .filter_map(|uri| source::percent_decode(uri).ok())
        .map(|rel| folder.join(rel))
        .collect()
}

/// Errors of one read: the file and the field at fault.
#[derive(Clone, Copy)]
struct Ctx<'a> {
    path: &'a Path,
}

impl Ctx<'_> {
    fn err(&self, field: impl Into<String>, reason: impl Into<String>) -> DataError {
        DataError::new(self.path, field, reason)
    }
}

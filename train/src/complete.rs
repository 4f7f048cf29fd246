//! `any4d complete` and `any4d extend`: a trained keyframe RF on a user's own meshes (docs/method.md §4.6, §7).
//!
//! The keyframes come either from one clip file (the frames to keep) or from separate meshes of one topology, each
//! with its frame index; frame 0 must be among them, since the method generates relative to the first frame's
//! mesh (the reference). The sequence is normalised by frame 0 as in training (D1)–(D3), completed window by window
//! (one window for a sequence of T frames, the long-horizon rollout of docs/method.md §7 beyond), and written back
//! in the user's coordinates and vertex order; keyframes are the user's meshes exactly.
//!
//! Vertices: the encoder reads P farthest-point tokens of the reference and the decoder queries every vertex, so
//! there is no upper vertex limit besides the readers' (memory grows with T · N · P in the decoder); a mesh with
//! fewer vertices than P is refused, since its tokens could not be distinct surface points.

use std::path::{Path, PathBuf};

use any4d_data::formats::{self, obj};
use any4d_data::preprocess::normalize;
use any4d_data::scene::Scene;
use any4d_data::{Clip, DataError};
use any4d_eval::methods::{Method, Request};
use any4d_eval::rollout::{OverlapSource, RolloutSpec};
use any4d_eval::tables::long_horizon::generate_windows;

use crate::error::{Result, TrainError};

/// Seeds of sample k are `seed + k · SAMPLE_SEED_STRIDE` (window w of a rollout adds w), so sample 0 of
/// `--samples N` is the single sample of the same seed (up to float rounding: samples of one window share network calls).
pub const SAMPLE_SEED_STRIDE: u64 = 1_000_000;

/// The keyframes of one completion in the user's coordinates: meshes of one topology at frame indices.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyMeshes {
    /// Name for the outputs (the clip's or the reference file's stem).
    pub id: String,
    /// Vertices per mesh.
    pub n_vertices: usize,
    /// The shared triangles.
    pub faces: Vec<[u32; 3]>,
    /// (frame, `[N]` rows of xyz), sorted by frame; the first is frame 0.
    pub keys: Vec<(usize, Vec<[f32; 3]>)>,
    /// Frames of the clip the keyframes came from (`None` for separate meshes).
    pub clip_frames: Option<usize>,
    /// The clip's caption (`None` for separate meshes).
    pub clip_caption: Option<String>,
}

fn bad(path: impl AsRef<Path>, field: &str, reason: String) -> TrainError {
    TrainError::Data(DataError::new(path.as_ref(), field, reason))
}

impl KeyMeshes {
    /// Frames `keyframes` of the clip in `path` (any readable clip format; the first take).
    pub fn from_clip(path: &Path, keyframes: &[usize]) -> Result<Self> {
        let clip = formats::read_clip(path)?;
        if let Some(&f) = keyframes.iter().find(|&&f| f >= clip.frames) {
            return Err(bad(
                path,
                "keyframes",
                format!("frame {f} is outside the clip's {} frames", clip.frames),
            ));
        }
        let keys = keyframes.iter().map(|&f| (f, clip.frame(f).to_vec())).collect();
        Self::checked(
            path,
            clip.id.clone(),
            clip.n_vertices,
            clip.faces.clone(),
            keys,
            Some(clip.frames),
            Some(clip.caption.clone()),
        )
    }

    /// One mesh per keyframe: `(frame, file)`. A `.obj` file is one mesh; any other clip file gives its frame 0.
    /// Every mesh must have the reference's (frame 0's) vertex count and triangles.
    pub fn from_files(files: &[(usize, PathBuf)]) -> Result<Self> {
        let mut keys = Vec::with_capacity(files.len());
        let mut topology: Option<(usize, Vec<[u32; 3]>, PathBuf)> = None;
        let mut sorted: Vec<&(usize, PathBuf)> = files.iter().collect();
        sorted.sort_by_key(|(f, _)| *f);
        for (frame, path) in sorted {
            let (vertices, faces) = read_mesh(path)?;
            match &topology {
                None => topology = Some((vertices.len(), faces, path.clone())),
                Some((n, ref_faces, ref_path)) => {
                    if vertices.len() != *n {
                        return Err(bad(
                            path,
                            "vertices",
                            format!(
                                "{} vertices, the reference {} has {n}: keyframes must share one topology",
                                vertices.len(),
                                ref_path.display()
                            ),
                        ));
                    }
                    if faces != *ref_faces {
                        return Err(bad(
                            path,
                            "faces",
                            format!(
                                "the triangles differ from those of the reference {}: keyframes must share one topology",
                                ref_path.display()
                            ),
                        ));
                    }
                }
            }
            keys.push((*frame, vertices));
        }
        let Some((n, faces, reference)) = topology else {
            return Err(bad("keyframes", "key", "no keyframe mesh was given".into()));
        };
        let id = reference
            .file_stem()
            .map_or_else(|| "keys".to_string(), |s| s.to_string_lossy().into_owned());
        Self::checked(&reference, id, n, faces, keys, None, None)
    }

    fn checked(
        path: &Path,
        id: String,
        n_vertices: usize,
        faces: Vec<[u32; 3]>,
        mut keys: Vec<(usize, Vec<[f32; 3]>)>,
        clip_frames: Option<usize>,
        clip_caption: Option<String>,
    ) -> Result<Self> {
        keys.sort_by_key(|(f, _)| *f);
        if keys.is_empty() {
            return Err(bad(path, "keyframes", "no keyframe was given".into()));
        }
        if let Some(w) = keys.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(bad(path, "keyframes", format!("frame {} is given twice", w[0].0)));
        }
        if keys[0].0 != 0 {
            return Err(bad(
                path,
                "keyframes",
                format!(
                    "the first keyframe is frame {}; frame 0 must be given: the model generates relative to the \
                     first frame's mesh (the reference)",
                    keys[0].0
                ),
            ));
        }
        if n_vertices == 0 {
            return Err(bad(path, "vertices", "the mesh has no vertices".into()));
        }
        Ok(Self {
            id,
            n_vertices,
            faces,
            keys,
            clip_frames,
            clip_caption,
        })
    }

    /// The keyframe indices, ascending.
    pub fn frames(&self) -> Vec<usize> {
        self.keys.iter().map(|(f, _)| *f).collect()
    }
}

/// One mesh from `path`: a single `.obj` file, or frame 0 of any clip file.
fn read_mesh(path: &Path) -> Result<obj::ObjFrame> {
    let is_obj = path.is_file()
        && path
            .extension()
            .is_some_and(|e| e.to_string_lossy().eq_ignore_ascii_case("obj"));
    if is_obj {
        let text = formats::read_text_file(path, any4d_data::limits::FILE_BYTES.get())?;
        return Ok(obj::parse_obj(&text, path)?);
    }
    let clip = formats::read_clip(path)?;
    Ok((clip.frame(0).to_vec(), clip.faces.clone()))
}

/// How to complete.
#[derive(Debug, Clone)]
pub struct CompleteOptions {
    /// Frames of the output (≥ the model's window T; more than T runs the windowed rollout).
    pub frames: usize,
    /// The prompt ("" = unconditional).
    pub caption: String,
    /// Sampler seed of sample 0.
    pub seed: u64,
    /// Number of samples.
    pub samples: usize,
    /// The static scene, in the keyframes' coordinates, for a method that reads it (normalised with the keyframes;
    /// one window only: the rollout of a longer clip is not told it).
    pub scene: Option<Scene>,
}

/// Completes `keys` with `method` (built for windows of `window` frames) into `opts.samples` clips of
/// `opts.frames` frames, in the keyframes' coordinates and vertex order. Keyframe frames are the given meshes
/// exactly; every other frame is generated.
pub fn complete(
    keys: &KeyMeshes,
    method: &dyn Method,
    window: usize,
    tokens: usize,
    opts: &CompleteOptions,
) -> Result<Vec<Clip>> {
    let n = keys.n_vertices;
    let setup = |field: &str, reason: String| Err(bad(&keys.id, field, reason));
    if opts.samples == 0 {
        return setup("samples", "at least one sample must be asked for".into());
    }
    if opts.frames < window {
        return setup(
            "frames",
            format!(
                "{} frames asked; the model generates windows of {window} frames, ask for at least that many",
                opts.frames
            ),
        );
    }
    let (frames_limit, rows_limit) = (&any4d_data::limits::FRAMES, &any4d_data::limits::CLIP_VERTICES);
    if opts.frames > frames_limit.get_usize() {
        return setup(
            "frames",
            format!(
                "{} frames is more than the limit of {}{}",
                opts.frames,
                frames_limit.get(),
                frames_limit.hint()
            ),
        );
    }
    if let Some(&(f, _)) = keys.keys.iter().find(|(f, _)| *f >= opts.frames) {
        return setup(
            "keyframes",
            format!(
                "frame {f} is outside the {} frames asked for (ask for more with --frames N, or `any4d extend`)",
                opts.frames
            ),
        );
    }
    if n < tokens {
        return setup(
            "vertices",
            format!(
                "the mesh has {n} vertices, fewer than the P = {tokens} points the VAE encodes: its tokens could not \
                 be distinct surface points"
            ),
        );
    }
    if opts
        .frames
        .checked_mul(n)
        .is_none_or(|rows| rows > rows_limit.get_usize())
    {
        return setup(
            "frames",
            format!(
                "{} frames × {n} vertices is more than the limit of {} vertex rows{}",
                opts.frames,
                rows_limit.get(),
                rows_limit.hint()
            ),
        );
    }
    // Hidden frames hold the reference; the rollout reads only frame 0 and the keyframes.
    let reference = &keys.keys[0].1;
    let mut vertices = Vec::with_capacity(opts.frames * n);
    for f in 0..opts.frames {
        match keys.keys.iter().find(|(k, _)| *k == f) {
            Some((_, mesh)) => vertices.extend_from_slice(mesh),
            None => vertices.extend_from_slice(reference),
        }
    }
    let user = Clip::new(
        &keys.id,
        vertices,
        opts.frames,
        n,
        keys.faces.clone(),
        opts.caption.as_str(),
        "any4d complete",
    )?;
    let (normalised, norm) = normalize(&user);
    let scene = match &opts.scene {
        Some(_) if opts.frames > window => {
            return setup(
                "scene",
                format!(
                    "a scene is told to one window of {window} frames; {} frames roll out window by window, which \
                     is not told it",
                    opts.frames
                ),
            );
        }
        Some(s) => Some(s.normalized(&norm).ok_or_else(|| {
            bad(
                &keys.id,
                "scene",
                "is not finite in the keyframes' normalised frame".into(),
            )
        })?),
        None => None,
    };
    let spec = RolloutSpec {
        window,
        stride: window - 1,
        overlap_source: OverlapSource::GroundTruth,
    };
    let key_frames = keys.frames();
    let captions = [opts.caption.clone()];
    let seed_of = |k: usize| opts.seed.wrapping_add(k as u64 * SAMPLE_SEED_STRIDE);
    // One window: the samples go through the network together, SAMPLE_BATCH at a time (each keeps its own noise, so
    // sample k is what it would be alone, up to float rounding). Longer clips roll out sample by sample.
    let mut batched: Vec<Vec<[f32; 3]>> = Vec::new();
    if opts.frames == window {
        let seeds: Vec<u64> = (0..opts.samples).map(seed_of).collect();
        for chunk in seeds.chunks(SAMPLE_BATCH) {
            let requests: Vec<Request<'_>> = chunk
                .iter()
                .map(|&seed| Request {
                    clip: &normalised,
                    keyframes: &key_frames,
                    seed,
                    scene: scene.as_ref(),
                })
                .collect();
            batched.extend(method.complete_batch(&requests, &opts.caption)?);
        }
    }
    let mut out = Vec::with_capacity(opts.samples.min(64));
    for k in 0..opts.samples {
        let vertices = match batched.get_mut(k) {
            Some(v) => std::mem::take(v),
            None => generate_windows(method, &normalised, &key_frames, &captions, seed_of(k), spec)?.vertices,
        };
        let mut clip = Clip {
            vertices,
            ..normalised.clone()
        };
        norm.invert(&mut clip);
        // The keyframes are the user's meshes, bit for bit (not their normalised round trip).
        for (f, mesh) in &keys.keys {
            clip.vertices[f * n..(f + 1) * n].copy_from_slice(mesh);
        }
        if let Some(i) = clip.vertices.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(bad(
                &keys.id,
                "output",
                format!("sample {k}: non-finite vertex at frame {}, vertex {}", i / n, i % n),
            ));
        }
        clip.id = match opts.samples {
            1 => format!("{}_completed", keys.id),
            _ => format!("{}_completed_s{k}", keys.id),
        };
        out.push(clip);
    }
    Ok(out)
}

/// Samples of one window that `complete` sends through the network together.
pub const SAMPLE_BATCH: usize = 8;

/// Where sample `k` of `samples` goes: `out` itself for one sample, else `<stem>_s<k>.<ext>` (an OBJ folder:
/// `<folder>_s<k>`).
pub fn sample_path(out: &Path, k: usize, samples: usize) -> PathBuf {
    if samples == 1 {
        return out.to_path_buf();
    }
    let stem = out
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let name = match out.extension() {
        Some(ext) => format!("{stem}_s{k}.{}", ext.to_string_lossy()),
        None => format!("{stem}_s{k}"),
    };
    out.with_file_name(name)
}

/// A benchmark input of exactly `n` vertices (n ≥ 3): points on a unit sphere (Fibonacci lattice) joined by a
/// triangle strip, at frame 0 and, rotated by 90° about the vertical axis, at frame `last`.
pub fn benchmark_keys(n: usize, last: usize) -> Result<KeyMeshes> {
    if n < 3 {
        return Err(bad(
            "benchmark",
            "vertices",
            format!("{n} vertices: a mesh needs at least 3"),
        ));
    }
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    let sphere: Vec<[f32; 3]> = (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - y * y).max(0.0).sqrt();
            let a = golden * i as f32;
            [r * a.cos(), y, r * a.sin()]
        })
        .collect();
    let turned = sphere.iter().map(|p| [p[2], p[1], -p[0]]).collect();
    let faces = (0..n as u32 - 2).map(|i| [i, i + 1, i + 2]).collect();
    KeyMeshes::checked(
        Path::new("benchmark"),
        format!("sphere{n}"),
        n,
        faces,
        vec![(0, sphere), (last, turned)],
        None,
        None,
    )
}

/// The per-vertex mean of several completions of the same keyframes (`complete --average`), with every keyframe
/// copied back exactly. It estimates the centre of the model's distribution, which beat linear interpolation where
/// single samples did not (experiments/2026-12-02-small-w256); it is smoother than any one sample and, like any
/// mean, may underplay motion the samples disagree on.
pub fn average_samples(samples: &[Clip], keys: &KeyMeshes) -> Result<Clip> {
    let Some(first) = samples.first() else {
        return Err(bad(&keys.id, "samples", "nothing to average".into()));
    };
    if let Some(other) = samples
        .iter()
        .find(|c| (c.frames, c.n_vertices) != (first.frames, first.n_vertices))
    {
        return Err(bad(
            &keys.id,
            "samples",
            format!(
                "samples of different sizes ({} × {} and {} × {})",
                first.frames, first.n_vertices, other.frames, other.n_vertices
            ),
        ));
    }
    let mut sum = vec![[0.0f64; 3]; first.vertices.len()];
    for clip in samples {
        for (s, v) in sum.iter_mut().zip(&clip.vertices) {
            for c in 0..3 {
                s[c] += f64::from(v[c]);
            }
        }
    }
    let k = samples.len() as f64;
    let mut out = first.clone();
    for (o, s) in out.vertices.iter_mut().zip(&sum) {
        *o = s.map(|x| (x / k) as f32);
    }
    for (f, rows) in &keys.keys {
        if *f < out.frames {
            out.frame_mut(*f).copy_from_slice(rows);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn benchmark_meshes_have_the_asked_size_and_two_keyframes() {
        let k = benchmark_keys(512, 15).unwrap();
        assert_eq!((k.n_vertices, k.frames()), (512, vec![0, 15]));
        assert!(k.keys.iter().all(|(_, m)| m.len() == 512));
        assert_ne!(k.keys[0].1, k.keys[1].1, "the second keyframe is turned");
        assert!(benchmark_keys(2, 15).is_err());
    }

    #[test]
    fn sample_paths_number_several_samples() {
        assert_eq!(sample_path(Path::new("a/b.glb"), 0, 1), Path::new("a/b.glb"));
        assert_eq!(sample_path(Path::new("a/b.glb"), 1, 2), Path::new("a/b_s1.glb"));
        assert_eq!(sample_path(Path::new("a/objs"), 0, 3), Path::new("a/objs_s0"));
    }
}

//! Preprocessing of clips (docs/method.md §2.2–2.6): welding, frame-0 normalisation (D1)–(D3), the vertex filter,
//! training windows, zero padding and the undirected edge list of the neighbour attention.
//!
//! Normalisation convention, stated once: every clip (or window) is expressed in the frame of its **first frame**:
//! the frame-0 bounding-box centre goes to the origin and the largest frame-0 half-extent (L∞) goes to 1.
//! Later frames may leave [−1, 1]³.

use std::collections::HashMap;

use crate::clip::Clip;
use crate::error::{DataError, Result};

/// Merge vertices that coincide (Euclidean distance ≤ `eps`) in **every** frame, remap the faces and drop the
/// faces that become degenerate (two equal corners).
///
/// Vertices that coincide in frame 0 but separate later stay apart (they are split seams that move apart).
/// Kept vertices keep the order of their first occurrence; a later vertex merges into the first kept vertex it
/// coincides with. `eps = 0` merges exact duplicates only. Caption, id and source are kept.
pub fn weld(clip: &Clip, eps: f32) -> Clip {
    let n = clip.n_vertices;
    let eps = eps.max(0.0);
    let eps2 = eps * eps;
    // Spatial hash of frame-0 positions of the kept vertices; cell size eps (exact bits when eps = 0).
    let cell = |p: [f32; 3]| -> [i64; 3] {
        if eps > 0.0 {
            p.map(|c| (c / eps).floor() as i64)
        } else {
            p.map(|c| i64::from((c + 0.0).to_bits()))
        }
    };
    let reach: i64 = if eps > 0.0 { 1 } else { 0 };
    let coincide = |a: usize, b: usize| {
        (0..clip.frames).all(|f| {
            let (p, q) = (clip.vertices[f * n + a], clip.vertices[f * n + b]);
            let d2: f32 = (0..3).map(|k| (p[k] - q[k]) * (p[k] - q[k])).sum();
            d2 <= eps2
        })
    };
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    let mut kept: Vec<usize> = Vec::new(); // old index of each new vertex
    let mut remap = vec![0u32; n];
    for (v, slot) in remap.iter_mut().enumerate() {
        let c = cell(clip.vertices[v]);
        let mut found = None;
        'search: for dx in -reach..=reach {
            for dy in -reach..=reach {
                for dz in -reach..=reach {
                    if let Some(list) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        for &new in list {
                            if coincide(kept[new], v) && found.is_none_or(|f| new < f) {
                                found = Some(new);
                            }
                        }
                    }
                    if found == Some(0) {
                        break 'search;
                    }
                }
            }
        }
        *slot = match found {
            Some(new) => new as u32,
            None => {
                grid.entry(c).or_default().push(kept.len());
                kept.push(v);
                (kept.len() - 1) as u32
            }
        };
    }
    let vertices = (0..clip.frames)
        .flat_map(|f| kept.iter().map(move |&v| clip.vertices[f * n + v]))
        .collect();
    let faces = clip
        .faces
        .iter()
        .map(|face| face.map(|v| remap[v as usize]))
        .filter(|[a, b, c]| a != b && b != c && a != c)
        .collect();
    Clip {
        id: clip.id.clone(),
        vertices,
        frames: clip.frames,
        n_vertices: kept.len(),
        faces,
        caption: clip.caption.clone(),
        source: clip.source.clone(),
    }
}

/// The axis-aligned box of `points`: (lowest, highest corner); (+∞, −∞) for no points.
pub fn bounds(points: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// The frame-0 normalisation of docs/method.md §2.3: `x̄ = (x − center) / scale`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalization {
    /// Frame-0 bounding-box centre c (D1).
    pub center: [f32; 3],
    /// Frame-0 L∞ half-extent s, including the 1e-8 guard (D2).
    pub scale: f32,
}

impl Normalization {
    /// Compute (c, s) from the real vertices of frame 0. An empty frame gives c = 0, s = 1e-8.
    pub fn from_frame(frame0: &[[f32; 3]]) -> Self {
        if frame0.is_empty() {
            return Self {
                center: [0.0; 3],
                scale: 1e-8,
            };
        }
        let (lo, hi) = bounds(frame0);
        let center = [0, 1, 2].map(|k| (hi[k] + lo[k]) / 2.0); // (D1)
        let half = frame0
            .iter()
            .flat_map(|p| (0..3).map(move |k| (p[k] - center[k]).abs()))
            .fold(0.0f32, f32::max);
        Self {
            center,
            scale: half + 1e-8,
        } // (D2)
    }

    /// Normalise every frame of `clip` in place.
    pub fn apply(&self, clip: &mut Clip) {
        self.apply_points(&mut clip.vertices);
    }

    /// (D3) on any points in the clip's coordinates (a scene's vertices, docs/method.md §6.5): `(x − c) / s`.
    pub fn apply_points(&self, points: &mut [[f32; 3]]) {
        for p in points {
            for (x, c) in p.iter_mut().zip(self.center) {
                *x = (*x - c) / self.scale; // (D3)
            }
        }
    }

    /// Undo [`Normalization::apply`] in place: `x = x̄ · s + c`.
    pub fn invert(&self, clip: &mut Clip) {
        for p in &mut clip.vertices {
            for (x, c) in p.iter_mut().zip(self.center) {
                *x = *x * self.scale + c;
            }
        }
    }
}

/// A normalised copy of `clip` (by its frame 0) and the transform that undoes it.
pub fn normalize(clip: &Clip) -> (Clip, Normalization) {
    let norm = Normalization::from_frame(clip.frame(0));
    let mut out = clip.clone();
    norm.apply(&mut out);
    (out, norm)
}

/// The vertex-count filter of docs/method.md §2.2, bounds inclusive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VertexFilter {
    /// Smallest accepted vertex count (inclusive).
    pub min: usize,
    /// Largest accepted vertex count (inclusive).
    pub max: usize,
}

impl Default for VertexFilter {
    /// 512 ≤ N_v ≤ 4096.
    fn default() -> Self {
        Self { min: 512, max: 4096 }
    }
}

impl VertexFilter {
    /// `Ok` when `min ≤ clip.n_vertices ≤ max`; the error names the source, field "vertices" and the count.
    pub fn check(&self, clip: &Clip) -> Result<()> {
        let n = clip.n_vertices;
        if n < self.min || n > self.max {
            return Err(DataError::new(
                &clip.source,
                "vertices",
                format!(
                    "clip {} has {n} vertices, outside the accepted {}..={}",
                    clip.id, self.min, self.max
                ),
            ));
        }
        Ok(())
    }
}

/// Fewest frames a take needs before [`loop_to`] treats it as a cycle: two or three frames are a pose change, not
/// a loop.
pub const LOOP_MIN_FRAMES: usize = 4;

/// Largest closing gap, as a multiple of the take's median frame-to-frame step, that still counts as a loop
/// (docs/method.md §2.6): the jump from the last frame back to the first is no larger than an ordinary step.
pub const LOOP_CLOSE: f32 = 1.5;

/// A closing gap below this multiple of the median step means the last frame repeats the first (many exporters
/// store a cycle with its first pose at both ends): the repeat is dropped from the cycle.
pub const LOOP_REPEAT: f32 = 0.25;

/// Root-mean-square distance between frames `a` and `b` of `clip`.
fn frame_distance(clip: &Clip, a: usize, b: usize) -> f32 {
    let (fa, fb) = (clip.frame(a), clip.frame(b));
    let sum: f64 = fa
        .iter()
        .zip(fb)
        .map(|(p, q)| (0..3).map(|k| f64::from(p[k] - q[k]).powi(2)).sum::<f64>())
        .sum();
    (sum / fa.len().max(1) as f64).sqrt() as f32
}

/// A take shorter than `len` frames played as a cycle until it is `len` frames long (docs/method.md §2.6), or
/// `None` when it does not loop: fewer than [`LOOP_MIN_FRAMES`] frames, or a jump from its last frame back to
/// its first larger than [`LOOP_CLOSE`] × its median step. A last frame that repeats the first (gap below
/// [`LOOP_REPEAT`] × the median step) is played once per cycle, not twice. A still take (every step zero) loops.
/// The id gains `_loop` so that stored windows say where they came from; a clip of `len` frames or more is
/// returned unchanged.
pub fn loop_to(clip: &Clip, len: usize) -> Option<Clip> {
    if clip.frames >= len {
        return Some(clip.clone());
    }
    if clip.frames < LOOP_MIN_FRAMES {
        return None;
    }
    let mut steps: Vec<f32> = (1..clip.frames).map(|f| frame_distance(clip, f - 1, f)).collect();
    steps.sort_by(f32::total_cmp);
    let median = steps[steps.len() / 2];
    let gap = frame_distance(clip, clip.frames - 1, 0);
    // NaN distances (non-finite frames) fail this test and do not loop.
    if gap.is_nan() || gap > LOOP_CLOSE * median {
        return None;
    }
    let period = if gap <= LOOP_REPEAT * median {
        clip.frames - 1
    } else {
        clip.frames
    };
    let n = clip.n_vertices;
    let vertices = (0..len)
        .flat_map(|f| clip.frame(f % period).iter().copied())
        .collect::<Vec<_>>();
    debug_assert_eq!(vertices.len(), len * n);
    Some(Clip {
        id: format!("{}_loop", clip.id),
        vertices,
        frames: len,
        ..clip.clone()
    })
}

/// Windows of `len` frames every `stride` frames (docs/method.md §2.6). An id in the AAM form
/// `<uid>_offset<k>_<s>-<e>` keeps that form with the window's own frame range
/// (`<uid>_offset<k>_<s+start>-<s+start+len−1>`, so consecutive windows sharing a frame pair up for the long-horizon
/// protocol, docs/method.md §2.7); other ids get `_w<start>`.
///
/// A clip of exactly `len` frames gives itself unchanged (same id); a shorter clip gives none. Windows are
/// **not** normalised here: callers normalise each window by its own first frame ([`normalize`]).
///
/// # Panics
/// If `len < 2` (a clip needs two frames) or `stride == 0`; both are programming errors, not data errors.
pub fn windows(clip: &Clip, len: usize, stride: usize) -> Vec<Clip> {
    assert!(len >= 2, "windows: len must be at least 2 frames, got {len}");
    assert!(stride >= 1, "windows: stride must be at least 1");
    if clip.frames < len {
        return Vec::new();
    }
    if clip.frames == len {
        return vec![clip.clone()];
    }
    let n = clip.n_vertices;
    (0..=clip.frames - len)
        .step_by(stride)
        .map(|start| Clip {
            id: window_id(&clip.id, start, len),
            vertices: clip.vertices[start * n..(start + len) * n].to_vec(),
            frames: len,
            n_vertices: n,
            faces: clip.faces.clone(),
            caption: clip.caption.clone(),
            source: clip.source.clone(),
        })
        .collect()
}

/// Id of the window of `len` frames starting at local frame `start` (see [`windows`]).
fn window_id(id: &str, start: usize, len: usize) -> String {
    let aam = id.rsplit_once('_').and_then(|(stem, range)| {
        let (s, e) = range.split_once('-')?;
        let (s, _e): (usize, usize) = (s.parse().ok()?, e.parse().ok()?);
        stem.contains("_offset")
            .then(|| format!("{stem}_{}-{}", s + start, s + start + len - 1))
    });
    aam.unwrap_or_else(|| format!("{id}_w{start}"))
}

/// Zero-pad normalised vertices to `n_max` rows per frame (docs/method.md §2.4) and build the vertex mask.
///
/// `frames` holds `t · n_real` frame-major rows. Errors (path "pad_vertices", field "vertices"; callers
/// relabel with [`DataError::at`]) if `n_real > n_max` or the row count is not `t · n_real`.
///
/// # Shapes
/// - `frames`: `[T · N_v]` rows of xyz
/// - returns `([T · N · 3] f32, [N] bool)` with N = `n_max`; the mask is true for the first `n_real` rows
pub fn pad_vertices(frames: &[[f32; 3]], n_real: usize, t: usize, n_max: usize) -> Result<(Vec<f32>, Vec<bool>)> {
    let err = |reason: String| Err(DataError::new("pad_vertices", "vertices", reason));
    if n_real > n_max {
        return err(format!("{n_real} real vertices exceed the padded size {n_max}"));
    }
    if frames.len() != t * n_real {
        return err(format!(
            "{} rows, expected frames × vertices = {t} × {n_real}",
            frames.len()
        ));
    }
    let mut out = vec![0.0f32; t * n_max * 3];
    for f in 0..t {
        for (v, p) in frames[f * n_real..(f + 1) * n_real].iter().enumerate() {
            out[(f * n_max + v) * 3..(f * n_max + v) * 3 + 3].copy_from_slice(p);
        }
    }
    let mask = (0..n_max).map(|v| v < n_real).collect();
    Ok((out, mask))
}

/// Undirected, deduplicated, sorted edges `[a, b]` with `a < b` of a triangle list over `n` vertices.
///
/// Degenerate corners (a face repeating a vertex) give no self-edge. Errors (path "edges_from_faces", field
/// "faces") if a face indexes past `n`.
///
/// # Shapes
/// - `faces`: `[M]` triangles; returns `[E]` edges
pub fn edges_from_faces(faces: &[[u32; 3]], n: usize) -> Result<Vec<[u32; 2]>> {
    if let Some((i, face)) = faces
        .iter()
        .enumerate()
        .find(|(_, f)| f.iter().any(|&v| v as usize >= n))
    {
        return Err(DataError::new(
            "edges_from_faces",
            "faces",
            format!("face {i} = {face:?} indexes past the {n} vertices"),
        ));
    }
    let mut edges: Vec<[u32; 2]> = faces
        .iter()
        .flat_map(|&[a, b, c]| [[a, b], [b, c], [c, a]])
        .filter(|[a, b]| a != b)
        .map(|[a, b]| [a.min(b), a.max(b)])
        .collect();
    edges.sort_unstable();
    edges.dedup();
    Ok(edges)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clip(frames: Vec<Vec<[f32; 3]>>, faces: Vec<[u32; 3]>) -> Clip {
        let (t, n) = (frames.len(), frames[0].len());
        Clip::new("obj_offset0_0-1", frames.concat(), t, n, faces, "cap", "x.bin").unwrap()
    }

    #[test]
    fn normalization_hand_case_and_round_trip() {
        // Frame-0 bbox x ∈ [1, 5], y ∈ [0, 2], z ∈ [−1, 1]: c = (3, 1, 0), s = 2.
        let f0 = vec![[1.0, 0.0, -1.0], [5.0, 2.0, 1.0], [3.0, 1.0, 0.5]];
        let f1 = vec![[9.0, 1.0, 0.0], [5.0, 2.0, 1.0], [3.0, 1.0, 0.5]];
        let c = clip(vec![f0, f1], vec![[0, 1, 2]]);
        let (nc, norm) = normalize(&c);
        assert_eq!(norm.center, [3.0, 1.0, 0.0]);
        assert!((norm.scale - 2.0).abs() < 1e-6);
        assert_eq!(nc.frame(0)[0], [-1.0, -0.5, -0.5]);
        let max = nc.frame(0).iter().flatten().fold(0.0f32, |m, x| m.max(x.abs()));
        assert!((max - 1.0).abs() < 1e-6, "{max}");
        assert_eq!(
            nc.frame(1)[0],
            [3.0, 0.0, 0.0],
            "later frames use the frame-0 transform and may leave [-1, 1]"
        );
        let mut back = nc.clone();
        norm.invert(&mut back);
        for (a, b) in back.vertices.iter().zip(&c.vertices) {
            assert!((0..3).all(|k| (a[k] - b[k]).abs() < 1e-6), "{a:?} vs {b:?}");
        }
    }

    #[test]
    fn weld_merges_only_vertices_coincident_in_every_frame() {
        // 0 and 3 coincide in both frames → merged; 1 and 4 coincide only in frame 0 → kept apart.
        let f0 = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1e-7],
            [1.0, 0.0, 0.0],
        ];
        let f1 = vec![
            [0.0, 0.0, 2.0],
            [1.0, 0.0, 2.0],
            [0.0, 1.0, 2.0],
            [0.0, 0.0, 2.0],
            [1.0, 0.5, 2.0],
        ];
        let faces = vec![[0, 1, 2], [3, 4, 2], [0, 3, 2]];
        let w = weld(&clip(vec![f0, f1], faces), 1e-5);
        assert_eq!(w.n_vertices, 4);
        assert_eq!(
            w.faces,
            vec![[0, 1, 2], [0, 3, 2]],
            "the face 0-3-2 became degenerate and is dropped"
        );
        assert_eq!(
            w.frame(1)[3],
            [1.0, 0.5, 2.0],
            "vertex 4 survives as new index 3, first-occurrence order"
        );
        w.validate().unwrap();
        // eps = 0 merges exact duplicates only: 0 and 3 differ by 1e-7 in frame 0.
        let f0 = vec![
            [0.0; 3],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1e-7],
            [1.0, 0.0, 0.0],
        ];
        let exact = weld(&clip(vec![f0.clone(), f0], vec![[0, 1, 2]]), 0.0);
        assert_eq!(exact.n_vertices, 4);
    }

    #[test]
    fn filter_bounds_are_inclusive() {
        let tri = |n: usize| {
            let v: Vec<[f32; 3]> = (0..n).map(|i| [i as f32, 0.0, 0.0]).collect();
            clip(vec![v.clone(), v], vec![])
        };
        let f = VertexFilter { min: 4, max: 6 };
        assert!(f.check(&tri(4)).is_ok() && f.check(&tri(6)).is_ok());
        let e = f.check(&tri(7)).unwrap_err();
        assert_eq!(e.field, "vertices");
        assert!(e.reason.contains("7 vertices"), "{e}");
        assert!(f.check(&tri(3)).is_err());
        assert_eq!(VertexFilter::default(), VertexFilter { min: 512, max: 4096 });
    }

    #[test]
    fn windows_ids_and_frames() {
        let frames: Vec<Vec<[f32; 3]>> = (0..5).map(|f| vec![[f as f32, 0.0, 0.0]; 3]).collect();
        let c = clip(frames, vec![[0, 1, 2]]);
        let w = windows(&c, 3, 1);
        assert_eq!(w.len(), 3);
        // AAM ids keep their form with the window's own frame range; other ids get `_w<start>`.
        assert_eq!(w[2].id, "obj_offset0_2-4");
        assert_eq!(w[2].object_uid(), "obj");
        assert_eq!(w[2].frame(0)[0], [2.0, 0.0, 0.0]);
        assert_eq!(w[1].frames, 3);
        assert_eq!(
            windows(&c, 3, 2).iter().map(|w| w.id.clone()).collect::<Vec<_>>(),
            ["obj_offset0_0-2", "obj_offset0_2-4"]
        );
        let plain = Clip {
            id: "plain".into(),
            ..c.clone()
        };
        assert_eq!(windows(&plain, 3, 2)[1].id, "plain_w2");
        assert_eq!(windows(&c, 5, 1), vec![c.clone()]);
        assert!(windows(&c, 6, 1).is_empty());
    }

    /// A vertex on a circle at `k` of `period` equal steps, as frame `k` of a cycle.
    fn circle_frames(period: usize, frames: usize) -> Vec<Vec<[f32; 3]>> {
        (0..frames)
            .map(|k| {
                let a = std::f32::consts::TAU * k as f32 / period as f32;
                vec![[a.cos(), a.sin(), 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]]
            })
            .collect()
    }

    #[test]
    fn loops_play_cycles_and_refuse_takes_that_do_not_loop() {
        // Six frames of a six-step cycle: the last frame leads back to the first in one ordinary step.
        let open = clip(circle_frames(6, 6), vec![[0, 1, 2]]);
        let l = loop_to(&open, 16).expect("a cycle loops");
        assert_eq!((l.frames, l.id.as_str()), (16, "obj_offset0_0-1_loop"));
        assert_eq!(l.object_uid(), "obj");
        for f in 0..16 {
            assert_eq!(l.frame(f), open.frame(f % 6), "frame {f}");
        }
        // Seven frames whose last repeats the first: the repeat is played once per cycle.
        let closed = clip(circle_frames(6, 7), vec![[0, 1, 2]]);
        let l = loop_to(&closed, 16).unwrap();
        for f in 0..16 {
            assert_eq!(l.frame(f), closed.frame(f % 6), "frame {f}");
        }
        // Half a turn ends far from where it began: not a loop.
        assert!(loop_to(&clip(circle_frames(12, 7), vec![[0, 1, 2]]), 16).is_none());
        // Too short to call a cycle; a still take loops; a long take is unchanged.
        assert!(loop_to(&clip(circle_frames(3, 3), vec![[0, 1, 2]]), 16).is_none());
        let still = clip(vec![vec![[0.5; 3]; 3]; 5], vec![[0, 1, 2]]);
        assert_eq!(loop_to(&still, 8).unwrap().frames, 8);
        assert_eq!(loop_to(&open, 6).unwrap(), open);
    }

    #[test]
    fn padding_zeroes_and_masks() {
        let frames = vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0], [10.0, 11.0, 12.0]];
        let (x, m) = pad_vertices(&frames, 2, 2, 3).unwrap();
        assert_eq!(
            x,
            vec![
                1., 2., 3., 4., 5., 6., 0., 0., 0., 7., 8., 9., 10., 11., 12., 0., 0., 0.
            ]
        );
        assert_eq!(m, vec![true, true, false]);
        let e = pad_vertices(&frames, 4, 1, 3).unwrap_err();
        assert!(e.reason.contains("exceed"), "{e}");
        assert!(pad_vertices(&frames, 2, 3, 3).is_err());
    }

    #[test]
    fn edges_are_undirected_sorted_unique() {
        let e = edges_from_faces(&[[0, 1, 2], [2, 1, 3], [3, 3, 1]], 4).unwrap();
        assert_eq!(e, vec![[0, 1], [0, 2], [1, 2], [1, 3], [2, 3]]);
        assert_eq!(edges_from_faces(&[[0, 1, 4]], 4).unwrap_err().field, "faces");
    }
}

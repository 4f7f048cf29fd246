//! The clip record (docs/method.md §2.1): vertices `[T, N, 3]` f32, fixed faces `[M, 3]`, caption, source.

use crate::error::{DataError, Result};

/// One animated mesh with fixed topology.
///
/// `vertices` is frame-major: vertex `v` of frame `f` is `vertices[f * n_vertices + v]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Clip {
    /// AAM form `<object uid>_offset<k>_<start>-<end>` when known; otherwise the file stem.
    pub id: String,
    /// Absolute (or normalised) positions, `T * N` rows of xyz.
    pub vertices: Vec<[f32; 3]>,
    /// Number of frames T.
    pub frames: usize,
    /// Number of real vertices N.
    pub n_vertices: usize,
    /// Triangles, indices into `0..n_vertices`, fixed over time.
    pub faces: Vec<[u32; 3]>,
    /// Caption; the empty string means unconditional.
    pub caption: String,
    /// Where the clip came from (a path, or `synth:<seed>:<index>`).
    pub source: String,
}

impl Clip {
    /// Build a clip and validate it (see [`Clip::validate`]).
    pub fn new(
        id: impl Into<String>,
        vertices: Vec<[f32; 3]>,
        frames: usize,
        n_vertices: usize,
        faces: Vec<[u32; 3]>,
        caption: impl Into<String>,
        source: impl Into<String>,
    ) -> Result<Self> {
        let clip = Self {
            id: id.into(),
            vertices,
            frames,
            n_vertices,
            faces,
            caption: caption.into(),
            source: source.into(),
        };
        clip.validate()?;
        Ok(clip)
    }

    /// The vertices of frame `f`, `[N]` rows of xyz.
    pub fn frame(&self, f: usize) -> &[[f32; 3]] {
        &self.vertices[f * self.n_vertices..(f + 1) * self.n_vertices]
    }

    /// Mutable vertices of frame `f`.
    pub fn frame_mut(&mut self, f: usize) -> &mut [[f32; 3]] {
        let n = self.n_vertices;
        &mut self.vertices[f * n..(f + 1) * n]
    }

    /// Object uid: the part of the id before `_offset` (AAM naming), else the whole id. Splits group by it.
    pub fn object_uid(&self) -> &str {
        object_uid(&self.id)
    }

    /// Checks docs/method.md §2.1 invariants: T ≥ 2, N ≥ 3, `vertices.len() == T·N`, finite coordinates, 0 ≤ face index
    /// < N. The error names the source and the field.
    pub fn validate(&self) -> Result<()> {
        let err = |field: &str, reason: String| Err(DataError::new(&self.source, field, reason));
        if self.frames < 2 {
            return err("vertices", format!("needs at least 2 frames, found {}", self.frames));
        }
        if self.n_vertices < 3 {
            return err(
                "vertices",
                format!("needs at least 3 vertices, found {}", self.n_vertices),
            );
        }
        if self.vertices.len() != self.frames * self.n_vertices {
            return err(
                "vertices",
                format!(
                    "holds {} rows, expected frames × vertices = {} × {}",
                    self.vertices.len(),
                    self.frames,
                    self.n_vertices
                ),
            );
        }
        if let Some(i) = self.vertices.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return err(
                "vertices",
                format!(
                    "non-finite coordinate {:?} at frame {}, vertex {}",
                    self.vertices[i],
                    i / self.n_vertices,
                    i % self.n_vertices
                ),
            );
        }
        if let Some((i, face)) = self
            .faces
            .iter()
            .enumerate()
            .find(|(_, f)| f.iter().any(|&v| v as usize >= self.n_vertices))
        {
            return err(
                "faces",
                format!("face {i} = {face:?} indexes past the {} vertices", self.n_vertices),
            );
        }
        Ok(())
    }
}

/// Object uid of a clip id: the part before `_offset` (AAM naming), else the whole id.
pub fn object_uid(id: &str) -> &str {
    id.split_once("_offset").map_or(id, |(uid, _)| uid)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(frames: usize) -> Vec<[f32; 3]> {
        (0..frames)
            .flat_map(|f| [[0.0, 0.0, f as f32], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
            .collect()
    }

    #[test]
    fn valid_clip_passes_and_frames_slice() {
        let c = Clip::new("a_offset0_0-2", tri(2), 2, 3, vec![[0, 1, 2]], "", "x.bin").unwrap();
        assert_eq!(c.frame(1)[0], [0.0, 0.0, 1.0]);
        assert_eq!(c.object_uid(), "a");
    }

    #[test]
    fn rejects_bad_clips_naming_field() {
        let e = Clip::new("a", tri(1), 1, 3, vec![], "", "x.bin").unwrap_err();
        assert_eq!((e.path.as_str(), e.field.as_str()), ("x.bin", "vertices"));
        let mut v = tri(2);
        v[4][1] = f32::NAN;
        let e = Clip::new("a", v, 2, 3, vec![], "", "x.bin").unwrap_err();
        assert!(e.reason.contains("frame 1, vertex 1"), "{e}");
        let e = Clip::new("a", tri(2), 2, 3, vec![[0, 1, 3]], "", "x.bin").unwrap_err();
        assert_eq!(e.field, "faces");
        let e = Clip::new("a", tri(2), 3, 3, vec![], "", "x.bin").unwrap_err();
        assert!(e.reason.contains("expected"), "{e}");
    }
}

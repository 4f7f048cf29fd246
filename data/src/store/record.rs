//! Decoding one record of `clips.bin` (layout in the [`crate::store`] module doc): every count checked against the
//! bytes the record has before anything is allocated, every field named with its absolute offset on error.

use std::path::Path;

use crate::clip::Clip;
use crate::error::{DataError, Result};
use crate::preprocess::Normalization;
use crate::scene::Scene;

use super::format::Catalog;
use super::{Split, StoredClip};

/// A bounds-checked little-endian reader over one record that names the field and absolute offset on error.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
    base: u64,
    path: &'a Path,
    clip: usize,
}

impl Cursor<'_> {
    fn take(&mut self, n: usize, field: &str) -> Result<&[u8]> {
        if self.bytes.len() - self.at < n {
            return Err(self.error(
                field,
                format!(
                    "needs {n} bytes but the record has {} left (corrupt or truncated)",
                    self.bytes.len() - self.at
                ),
            ));
        }
        self.at += n;
        Ok(&self.bytes[self.at - n..self.at])
    }

    fn error(&self, field: &str, reason: String) -> DataError {
        DataError::new(
            self.path,
            format!("clip {} {field} at byte {}", self.clip, self.base + self.at as u64),
            reason,
        )
    }

    fn u32(&mut self, field: &str) -> Result<u32> {
        let b = self.take(4, field)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn string(&mut self, field: &str) -> Result<String> {
        let n = self.u32(field)? as usize;
        let start = self.at;
        let b = self.take(n, field)?.to_vec();
        String::from_utf8(b).map_err(|e| {
            DataError::new(
                self.path,
                format!("clip {} {field} at byte {}", self.clip, self.base + start as u64),
                e.to_string(),
            )
        })
    }

    /// `count` points of three little-endian f32 (`None`: a count that overflowed).
    fn points(&mut self, count: Option<usize>, field: &str) -> Result<Vec<[f32; 3]>> {
        let words = self.words(count.and_then(|c| c.checked_mul(3)), field)?;
        Ok(words
            .chunks_exact(12)
            .map(|b| [0, 4, 8].map(|k| f32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]])))
            .collect())
    }

    /// `count` triangles of three little-endian u32 vertex indices.
    fn triangles(&mut self, count: usize, field: &str) -> Result<Vec<[u32; 3]>> {
        let words = self.words(count.checked_mul(3), field)?;
        Ok(words
            .chunks_exact(12)
            .map(|b| [0, 4, 8].map(|k| u32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]])))
            .collect())
    }

    /// `count` little-endian 4-byte words; the length is checked before anything is allocated.
    fn words(&mut self, count: Option<usize>, field: &str) -> Result<&[u8]> {
        let n = count
            .and_then(|c| c.checked_mul(4))
            .ok_or_else(|| self.error(field, "element count overflows".into()))?;
        self.take(n, field)
    }
}

/// Decode record `index` (bytes `record`, starting at absolute `offset` of `path`) with its `split`.
pub fn decode(
    record: &[u8],
    offset: u64,
    path: &Path,
    index: usize,
    split: Split,
    catalog: &Catalog,
) -> Result<StoredClip> {
    let (frames, p) = (catalog.frames, catalog.p);
    let mut c = Cursor {
        bytes: record,
        at: 0,
        base: offset,
        path,
        clip: index,
    };
    let id = c.string("id")?;
    let caption = c.string("caption")?;
    let source = c.string("source")?;
    let t = c.u32("frames")? as usize;
    let n = c.u32("vertices")? as usize;
    let m = c.u32("faces")? as usize;
    let np = c.u32("fps")? as usize;
    if t != frames || np != p {
        return Err(c.error(
            "frames/fps",
            format!("clip {id} has T = {t}, P = {np}; the header says T = {frames}, P = {p}"),
        ));
    }
    let vertices = c.points(t.checked_mul(n), "vertices")?;
    let faces = c.triangles(m, "faces")?;
    let fps_at = c.at;
    let fps: Vec<u32> = c
        .words(Some(np), "fps")?
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if let Some(bad) = fps.iter().find(|&&i| i as usize >= n) {
        return Err(DataError::new(
            path,
            format!("clip {index} fps at byte {}", offset + fps_at as u64),
            format!("index {bad} ≥ {n} vertices"),
        ));
    }
    let norm: Vec<f32> = c
        .words(Some(4), "normalization")?
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let scene = match catalog.scenes {
        true => scene_section(&mut c)?,
        false => None,
    };
    if c.at != record.len() {
        return Err(c.error("end", format!("{} unread bytes after the record", record.len() - c.at)));
    }
    let clip = Clip::new(id, vertices, t, n, faces, caption, source)
        .map_err(|e| DataError::new(path, format!("clip {index} at byte {offset}: {}", e.field), e.reason))?;
    let normalization = Normalization {
        center: [norm[0], norm[1], norm[2]],
        scale: norm[3],
    };
    if !(norm.iter().all(|x| x.is_finite()) && normalization.scale > 0.0) {
        return Err(DataError::new(
            path,
            format!(
                "clip {index} normalization at byte {}",
                offset + record.len() as u64 - 16
            ),
            format!(
                "center {:?} and scale {} do not undo a normalisation",
                normalization.center, normalization.scale
            ),
        ));
    }
    Ok(StoredClip {
        clip,
        fps,
        normalization,
        split,
        scene,
    })
}

/// A record's scene section: vertex and face counts, then the vertices and faces (none: no scene), each count
/// checked against the bytes left before anything is allocated, the scene checked by [`Scene::new`].
fn scene_section(c: &mut Cursor) -> Result<Option<Scene>> {
    let sv = c.u32("scene vertices")? as usize;
    let sm = c.u32("scene faces")? as usize;
    let vertices = c.points(Some(sv), "scene vertices")?;
    let faces = c.triangles(sm, "scene faces")?;
    if sv == 0 && sm == 0 {
        return Ok(None);
    }
    Scene::new(vertices, faces, c.path)
        .map(Some)
        .map_err(|e| c.error(&format!("scene {}", e.field), e.reason))
}

/// Decode clip `index` of a `clips.bin` held in memory, as [`super::Store::get`] decodes it from the file.
pub fn decode_clip_bytes(bytes: &[u8], catalog: &Catalog, index: usize, path: &Path) -> Result<StoredClip> {
    let e = catalog.entries.get(index).copied().ok_or_else(|| {
        DataError::new(
            path,
            "clip index",
            format!("clip {index} requested, the store holds {}", catalog.entries.len()),
        )
    })?;
    let record = usize::try_from(e.offset)
        .ok()
        .zip(usize::try_from(e.offset + e.len).ok())
        .and_then(|(start, end)| bytes.get(start..end))
        .ok_or_else(|| DataError::new(path, format!("clip {index}"), "record lies outside these bytes"))?;
    decode(record, e.offset, path, index, e.split, catalog)
}

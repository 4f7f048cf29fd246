//! The `clips.bin` container of a dataset store: a streaming writer and a random-access reader (docs/method.md
//! §2.1–§2.5 record; layout in the [`crate::store`] module doc).
//!
//! Every read is bounds-checked against the file: a corrupt or truncated file gives a [`DataError`] naming the
//! file, the clip, the field and the byte offset, never a panic and never an allocation larger than the file.

use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::error::{DataError, Result};

use super::{Split, StoredClip};

/// First 8 bytes of `clips.bin`.
pub const MAGIC: &[u8; 8] = b"A4DSTORE";
/// Last 8 bytes of `clips.bin` (a missing end magic means a truncated or unfinished file).
pub const END_MAGIC: &[u8; 8] = b"A4DTABLE";
/// Layout version written in the header.
pub const VERSION: u32 = 1;
/// Header: magic (8) + version, T, P, flags (4 × u32).
pub const HEADER_LEN: u64 = 24;
/// Header flag: every record ends with a scene section (docs/method.md §6.5; layout in the [`crate::store`] doc).
pub const FLAG_SCENES: u32 = 1;
/// Trailer: table offset (u64) + clip count (u64) + end magic (8).
pub const TRAILER_LEN: u64 = 24;
/// One table entry: record offset (u64) + split (u8).
pub const ENTRY_LEN: u64 = 9;

/// Appends encoded clips to a temporary file next to `clips.bin`; [`StoreWriter::finish`] writes the table and
/// renames it into place (atomic on one file system).
///
/// A writer dropped before [`StoreWriter::finish`] (an error or a panic on the way) removes its temporary file.
pub struct StoreWriter {
    /// Set by [`StoreWriter::finish`]; until then the temporary file is removed on drop.
    finished: bool,
    tmp: PathBuf,
    dest: PathBuf,
    /// `None` once [`StoreWriter::finish`] has taken it.
    out: Option<BufWriter<File>>,
    pos: u64,
    entries: Vec<(u64, Split)>,
    frames: u32,
    p: u32,
    /// Whether records carry a scene section ([`FLAG_SCENES`]).
    scenes: bool,
}

impl StoreWriter {
    /// Start `dest` (written as `dest` + `.tmp` until [`StoreWriter::finish`]) for clips of `frames` frames and
    /// `p` FPS indices.
    pub fn create(dest: &Path, frames: usize, p: usize) -> Result<Self> {
        Self::create_with(dest, frames, p, false)
    }

    /// [`StoreWriter::create`] for a store whose records carry a scene section ([`FLAG_SCENES`]) when `scenes`.
    pub fn create_with(dest: &Path, frames: usize, p: usize, scenes: bool) -> Result<Self> {
        let tmp = dest.with_extension("bin.tmp");
        let file = File::create(&tmp).map_err(|e| DataError::io(&tmp, e))?;
        let frames = u32_field(frames, dest, "header.frames")?;
        let p = u32_field(p, dest, "header.p")?;
        let mut w = Self {
            finished: false,
            tmp,
            dest: dest.to_path_buf(),
            out: Some(BufWriter::new(file)),
            pos: 0,
            entries: Vec::new(),
            frames,
            p,
            scenes,
        };
        let mut header = Vec::with_capacity(HEADER_LEN as usize);
        header.extend_from_slice(MAGIC);
        let flags = if scenes { FLAG_SCENES } else { 0 };
        for v in [VERSION, frames, p, flags] {
            header.extend_from_slice(&v.to_le_bytes());
        }
        w.write(&header)?;
        Ok(w)
    }

    /// Number of clips appended so far.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when no clip has been appended.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Append one clip; its frame count and FPS length must match the header. Returns the record's
    /// [`checksum`].
    pub fn append(&mut self, clip: &StoredClip) -> Result<u64> {
        if clip.clip.frames != self.frames as usize || clip.fps.len() != self.p as usize {
            return Err(DataError::new(
                &clip.clip.source,
                "store",
                format!(
                    "clip {} has T = {}, P = {}; this store holds T = {}, P = {}",
                    clip.clip.id,
                    clip.clip.frames,
                    clip.fps.len(),
                    self.frames,
                    self.p
                ),
            ));
        }
        if clip.scene.is_some() && !self.scenes {
            return Err(DataError::new(
                &clip.clip.source,
                "scene",
                format!(
                    "clip {} has a scene; this store was started without scenes",
                    clip.clip.id
                ),
            ));
        }
        let bytes = encode_with(clip, &self.dest, self.scenes)?;
        self.append_encoded(&bytes, clip.split)
    }

    /// Append a record already encoded by [`encode`] (used to copy clips from an older store unchanged). Returns
    /// the record's [`checksum`].
    pub fn append_encoded(&mut self, record: &[u8], split: Split) -> Result<u64> {
        // `pos` counts every byte written so far, header included, so the record starts there.
        self.entries.push((self.pos, split));
        self.write(record)?;
        Ok(checksum(record))
    }

    /// Write the entry table and trailer, flush to disk and rename over `dest`.
    pub fn finish(mut self) -> Result<()> {
        let table_offset = self.pos;
        let mut table = Vec::with_capacity(self.entries.len() * ENTRY_LEN as usize + TRAILER_LEN as usize);
        for &(offset, split) in &self.entries {
            table.extend_from_slice(&offset.to_le_bytes());
            table.push(split.code());
        }
        table.extend_from_slice(&table_offset.to_le_bytes());
        table.extend_from_slice(&(self.entries.len() as u64).to_le_bytes());
        table.extend_from_slice(END_MAGIC);
        self.write(&table)?;
        let file = self
            .out
            .take()
            .ok_or_else(|| DataError::new(&self.tmp, "store", "finished twice"))?
            .into_inner()
            .map_err(|e| DataError::io(&self.tmp, e.into_error()))?;
        file.sync_all().map_err(|e| DataError::io(&self.tmp, e))?;
        std::fs::rename(&self.tmp, &self.dest).map_err(|e| DataError::io(&self.dest, e))?;
        self.finished = true;
        Ok(())
    }

    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        let out = self
            .out
            .as_mut()
            .ok_or_else(|| DataError::new(&self.tmp, "store", "written after finish"))?;
        out.write_all(bytes).map_err(|e| DataError::io(&self.tmp, e))?;
        self.pos += bytes.len() as u64;
        Ok(())
    }
}

impl Drop for StoreWriter {
    fn drop(&mut self) {
        if !self.finished {
            drop(self.out.take());
            // Best effort: the caller is already handling the error (or panic) that stopped the writer.
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// The checksum of an encoded record: xxh3-64, stored per clip in the index and checked by
/// [`super::verify_store`].
pub fn checksum(record: &[u8]) -> u64 {
    xxhash_rust::xxh3::xxh3_64(record)
}

fn u32_field(v: usize, path: &Path, field: &str) -> Result<u32> {
    u32::try_from(v).map_err(|_| DataError::new(path, field, format!("{v} does not fit in u32")))
}

/// Encode one clip as a record of a store without scenes (layout in the module doc of [`crate::store`]); `path`
/// only labels errors.
pub fn encode(c: &StoredClip, path: &Path) -> Result<Vec<u8>> {
    encode_with(c, path, false)
}

/// [`encode`], followed by the clip's scene section (empty for a clip without a scene) when `scenes`.
pub fn encode_with(c: &StoredClip, path: &Path, scenes: bool) -> Result<Vec<u8>> {
    let clip = &c.clip;
    let mut b = Vec::with_capacity(64 + clip.vertices.len() * 12 + clip.faces.len() * 12 + c.fps.len() * 4);
    for (field, s) in [("id", &clip.id), ("caption", &clip.caption), ("source", &clip.source)] {
        b.extend_from_slice(&u32_field(s.len(), path, field)?.to_le_bytes());
        b.extend_from_slice(s.as_bytes());
    }
    for (field, v) in [
        ("frames", clip.frames),
        ("vertices", clip.n_vertices),
        ("faces", clip.faces.len()),
        ("fps", c.fps.len()),
    ] {
        b.extend_from_slice(&u32_field(v, path, field)?.to_le_bytes());
    }
    for p in &clip.vertices {
        for x in p {
            b.extend_from_slice(&x.to_le_bytes());
        }
    }
    for f in &clip.faces {
        for i in f {
            b.extend_from_slice(&i.to_le_bytes());
        }
    }
    for i in &c.fps {
        b.extend_from_slice(&i.to_le_bytes());
    }
    for x in c.normalization.center.iter().chain([&c.normalization.scale]) {
        b.extend_from_slice(&x.to_le_bytes());
    }
    if scenes {
        let (vertices, faces) = c
            .scene
            .as_ref()
            .map_or((&[][..], &[][..]), |s| (&s.vertices[..], &s.faces[..]));
        for (field, v) in [("scene vertices", vertices.len()), ("scene faces", faces.len())] {
            b.extend_from_slice(&u32_field(v, path, field)?.to_le_bytes());
        }
        vertices
            .iter()
            .flatten()
            .for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
        faces
            .iter()
            .flatten()
            .for_each(|i| b.extend_from_slice(&i.to_le_bytes()));
    }
    Ok(b)
}

/// Where one record lives in `clips.bin`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Entry {
    /// Byte offset of the record.
    pub offset: u64,
    /// Record length in bytes.
    pub len: u64,
    /// Train or validation.
    pub split: Split,
}

/// The parsed header and table of a `clips.bin`.
#[derive(Debug, Clone)]
pub struct Catalog {
    /// Frames per clip T.
    pub frames: usize,
    /// FPS indices per clip P.
    pub p: usize,
    /// Whether records carry a scene section ([`FLAG_SCENES`]).
    pub scenes: bool,
    /// One entry per clip, in file order.
    pub entries: Vec<Entry>,
}

/// Read and check the header, trailer and entry table of `path`.
pub fn read_catalog(path: &Path) -> Result<Catalog> {
    let mut file = File::open(path).map_err(|e| DataError::io(path, e))?;
    let size = file.metadata().map_err(|e| DataError::io(path, e))?.len();
    catalog_of(&mut file, size, path)
}

/// [`read_catalog`] of a `clips.bin` held in memory; `path` names it in errors.
pub fn read_catalog_bytes(bytes: &[u8], path: &Path) -> Result<Catalog> {
    catalog_of(&mut std::io::Cursor::new(bytes), bytes.len() as u64, path)
}

fn catalog_of<R: Read + Seek>(file: &mut R, size: u64, path: &Path) -> Result<Catalog> {
    let err = |field: &str, reason: String| DataError::new(path, field, reason);
    if size < HEADER_LEN + TRAILER_LEN {
        return Err(err(
            "file",
            format!(
                "{size} bytes is shorter than header + trailer ({} bytes)",
                HEADER_LEN + TRAILER_LEN
            ),
        ));
    }
    let header = read_at(file, path, 0, HEADER_LEN as usize, "header")?;
    if &header[..8] != MAGIC {
        return Err(err(
            "header.magic at byte 0",
            format!(
                "expected {:?}, found {:?}: not an any4d store",
                as_text(MAGIC),
                as_text(&header[..8])
            ),
        ));
    }
    let word = |i: usize| {
        u32::from_le_bytes([
            header[8 + 4 * i],
            header[9 + 4 * i],
            header[10 + 4 * i],
            header[11 + 4 * i],
        ])
    };
    if word(0) != VERSION {
        return Err(err(
            "header.version at byte 8",
            format!("version {} is not supported (this build reads {VERSION})", word(0)),
        ));
    }
    let (frames, p) = (word(1) as usize, word(2) as usize);
    if word(3) & !FLAG_SCENES != 0 {
        return Err(err(
            "header.flags at byte 20",
            format!("flags {:#x} name features this build does not read", word(3)),
        ));
    }
    let scenes = word(3) & FLAG_SCENES != 0;
    let trailer_at = size - TRAILER_LEN;
    let trailer = read_at(file, path, trailer_at, TRAILER_LEN as usize, "trailer")?;
    if &trailer[16..] != END_MAGIC {
        return Err(err(
            &format!("trailer.magic at byte {}", trailer_at + 16),
            format!(
                "expected {:?}, found {:?}: the file is truncated or was not finished",
                as_text(END_MAGIC),
                as_text(&trailer[16..])
            ),
        ));
    }
    let table_offset = u64_at(&trailer, 0);
    let count = u64_at(&trailer, 8);
    let table_len = count.checked_mul(ENTRY_LEN);
    if table_offset < HEADER_LEN || table_len.is_none_or(|l| table_offset.checked_add(l) != Some(trailer_at)) {
        return Err(err(
            &format!("trailer at byte {trailer_at}"),
            format!("table offset {table_offset} and clip count {count} do not fit a {size}-byte file"),
        ));
    }
    let table = read_at(file, path, table_offset, (trailer_at - table_offset) as usize, "table")?;
    let mut entries = Vec::with_capacity(count as usize);
    for i in 0..count as usize {
        let at = i * ENTRY_LEN as usize;
        let offset = u64_at(&table, at);
        let end = if i + 1 < count as usize {
            u64_at(&table, at + ENTRY_LEN as usize)
        } else {
            table_offset
        };
        let entry_at = table_offset + at as u64;
        if offset < HEADER_LEN || end < offset || end > table_offset {
            return Err(err(
                &format!("table entry {i} at byte {entry_at}"),
                format!("record offsets {offset}..{end} are outside the records area {HEADER_LEN}..{table_offset}"),
            ));
        }
        let split = Split::from_code(table[at + 8]).ok_or_else(|| {
            err(
                &format!("table entry {i} split at byte {}", entry_at + 8),
                format!("unknown split code {}", table[at + 8]),
            )
        })?;
        entries.push(Entry {
            offset,
            len: end - offset,
            split,
        });
    }
    Ok(Catalog {
        frames,
        p,
        scenes,
        entries,
    })
}

fn as_text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut w = [0u8; 8];
    w.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(w)
}

/// Read `len` bytes at `offset`; the caller has checked the range against the file size.
pub fn read_at<R: Read + Seek>(file: &mut R, path: &Path, offset: u64, len: usize, field: &str) -> Result<Vec<u8>> {
    let mut buf = vec![0u8; len];
    file.seek(SeekFrom::Start(offset))
        .and_then(|_| file.read_exact(&mut buf))
        .map_err(|e| DataError::new(path, format!("{field} at byte {offset}"), e.to_string()))?;
    Ok(buf)
}

/// The strings a record starts with, in order: `id`, `caption`, `source`.
pub const HEADER_STRINGS: [&str; 3] = ["id", "caption", "source"];

/// The `field` string of the record at `offset` (`len` bytes) of `path`, one of [`HEADER_STRINGS`], reading only
/// the start of the record.
pub fn read_header_string<R: Read + Seek>(
    file: &mut R,
    path: &Path,
    (offset, len): (u64, u64),
    clip: usize,
    field: &str,
) -> Result<String> {
    let err = |field: &str, at: u64, reason: String| {
        DataError::new(path, format!("clip {clip} {field} at byte {at}"), reason)
    };
    let end = offset + len;
    let mut at = offset;
    let mut string_len = |at: u64, field: &str| -> Result<u64> {
        if at + 4 > end {
            return Err(err(
                field,
                at,
                "the record ends before this length (corrupt or truncated)".into(),
            ));
        }
        let b = read_at(file, path, at, 4, field)?;
        let n = u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        if at + 4 + n > end {
            return Err(err(
                field,
                at,
                format!("length {n} runs past the record's end (corrupt or truncated)"),
            ));
        }
        Ok(n)
    };
    let Some(position) = HEADER_STRINGS.iter().position(|&f| f == field) else {
        return Err(err(
            field,
            offset,
            format!("not one of the record's strings {HEADER_STRINGS:?}"),
        ));
    };
    for before in &HEADER_STRINGS[..position] {
        at += 4 + string_len(at, before)?;
    }
    let n = string_len(at, field)?;
    let bytes = read_at(file, path, at + 4, n as usize, field)?;
    String::from_utf8(bytes).map_err(|e| err(field, at + 4, e.to_string()))
}

//! Checking a store: `clips.bin` against `index.parquet` by sizes (cheap, [`check_index`], run by `data inspect`)
//! and every clip fully by checksum and decoding ([`verify_store`], `data verify`).

use std::fmt;
use std::path::{Path, PathBuf};

use super::format::checksum;
use super::{CLIPS_FILE, INDEX_FILE, IndexRow, Status, Store, read_index};
use crate::error::{DataError, Result};

/// Length of the record [`super::format::encode`] writes for the clip of `row` in a store of `p` FPS tokens, from the
/// index alone; `None` for a rejected row or one whose sizes overflow.
pub fn record_len(row: &IndexRow, p: usize) -> Option<u64> {
    let (t, n, m) = (row.frames? as u64, row.vertices? as u64, row.faces? as u64);
    let text = 12 + row.id.len() as u64 + row.caption.len() as u64 + row.source.len() as u64;
    let body = t.checked_mul(n)?.checked_mul(12)?.checked_add(m.checked_mul(12)?)?;
    text.checked_add(16)?
        .checked_add(body)?
        .checked_add(4 * p as u64)?
        .checked_add(16)
}

/// Check that `clips.bin` of `store` holds exactly the stored clips that `rows` (its index) lists, with the
/// record sizes the index implies. Reads no clip data.
pub fn check_index(store: &Store, rows: &[IndexRow]) -> Result<()> {
    let dir = store.dir();
    let ok: Vec<&IndexRow> = rows.iter().filter(|r| r.status == Status::Ok).collect();
    if ok.len() != store.len() {
        return Err(DataError::new(
            dir.join(CLIPS_FILE),
            "clip count",
            format!(
                "holds {} clips, {INDEX_FILE} lists {}: the store is damaged (re-import its sources)",
                store.len(),
                ok.len()
            ),
        ));
    }
    for (i, (row, entry)) in ok.iter().zip(store.entries()).enumerate() {
        let want = record_len(row, store.p());
        // A record of a store with scenes adds its scene section (8 bytes and the scene), which the index does not
        // size: it must hold at least the clip and the section's counts; `data verify` decodes it whole.
        let fits = match store.has_scenes() {
            false => want == Some(entry.len),
            true => want.and_then(|w| w.checked_add(8)).is_some_and(|w| entry.len >= w),
        };
        if !fits || row.frames != Some(store.frames() as u32) {
            return Err(DataError::new(
                dir.join(CLIPS_FILE),
                format!("clip {i} ({})", row.id),
                format!(
                    "record of {} bytes at byte {}; {INDEX_FILE} implies {} bytes (T = {:?}, N = {:?}, M = {:?}, \
                     P = {}): the store is damaged (re-import its sources)",
                    entry.len,
                    entry.offset,
                    want.map_or("an impossible number of".into(), |w| w.to_string()),
                    row.frames,
                    row.vertices,
                    row.faces,
                    store.p()
                ),
            ));
        }
    }
    Ok(())
}

/// One clip that failed [`verify_store`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Problem {
    /// Position of the clip in `clips.bin`.
    pub clip: usize,
    /// Its id in the index.
    pub id: String,
    /// What is wrong.
    pub reason: String,
}

/// What [`verify_store`] found.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct VerifyReport {
    pub dir: PathBuf,
    /// Clips read and decoded.
    pub clips: usize,
    /// Shards whose `clips.bin` matched the size and checksum of the manifest (`None`: a one-file store).
    pub shards: Option<usize>,
    /// Of those, clips whose index row has a checksum (0 for a store written before checksums).
    pub with_checksum: usize,
    /// Every clip that failed, with the reason.
    pub problems: Vec<Problem>,
}

impl VerifyReport {
    /// True when every clip passed.
    pub fn is_ok(&self) -> bool {
        self.problems.is_empty()
    }
}

impl fmt::Display for VerifyReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{}: {} clips read and decoded, {} checked against their checksum; {} problems",
            self.dir.display(),
            self.clips,
            self.with_checksum,
            self.problems.len()
        )?;
        if let Some(n) = self.shards {
            writeln!(f, "  {n} shards match the size and checksum their manifest records")?;
        }
        if self.with_checksum < self.clips {
            writeln!(
                f,
                "  {} clips have no checksum in {INDEX_FILE} (a store written before checksums: re-import its \
                 sources to add them)",
                self.clips - self.with_checksum
            )?;
        }
        for p in &self.problems {
            writeln!(f, "  clip {} ({}): {}", p.clip, p.id, p.reason)?;
        }
        Ok(())
    }
}

/// Check every clip of the store in `dir`: its record against the index checksum, its decoding (the checks of
/// [`Store::get`]) and the decoded id, source, caption, sizes and split against its index row. Damage that makes
/// clips and index rows impossible to pair (counts, sizes) is an error; anything per clip is a [`Problem`].
///
/// A sharded store is checked whole: every shard's `clips.bin` against the size and checksum of its manifest line
/// first (a mismatch is an error naming the shard), then every clip as above, numbered in store order.
pub fn verify_store(dir: &Path) -> Result<VerifyReport> {
    let local = super::remote::local_dir(dir)?;
    let dir = local.as_path();
    let sharded = dir.join(super::shards::MANIFEST_FILE).is_file();
    if sharded {
        super::shards::check_checksums(dir)?;
    }
    let store = Store::open(dir)?;
    let rows = read_index(dir)?;
    check_index(&store, &rows)?;
    let ok: Vec<&IndexRow> = rows.iter().filter(|r| r.status == Status::Ok).collect();
    let mut report = VerifyReport {
        dir: dir.to_path_buf(),
        clips: store.len(),
        shards: sharded.then(|| store.shard_count()),
        with_checksum: 0,
        problems: Vec::new(),
    };
    for (i, row) in ok.iter().enumerate() {
        if let Err(reason) = verify_clip(&store, i, row, &mut report.with_checksum) {
            report.problems.push(Problem {
                clip: i,
                id: row.id.clone(),
                reason,
            });
        }
    }
    Ok(report)
}

fn verify_clip(store: &Store, i: usize, row: &IndexRow, with_checksum: &mut usize) -> std::result::Result<(), String> {
    let raw = store.raw(i).map_err(|e| e.to_string())?;
    if let Some(want) = row.checksum {
        *with_checksum += 1;
        let got = checksum(&raw);
        if got != want {
            return Err(format!(
                "checksum {got:016x} of its {} bytes differs from {want:016x} in {INDEX_FILE}: the data changed \
                 after import",
                raw.len()
            ));
        }
    }
    let c = store
        .decode(i, &raw)
        .map_err(|e| format!("{}: {}", e.field, e.reason))?;
    let found = (
        c.clip.id.as_str(),
        c.clip.source.as_str(),
        c.clip.caption.as_str(),
        c.clip.frames,
        c.clip.n_vertices,
        c.clip.faces.len(),
        Some(c.split),
    );
    let listed = (
        row.id.as_str(),
        row.source.as_str(),
        row.caption.as_str(),
        row.frames.map_or(usize::MAX, |x| x as usize),
        row.vertices.map_or(usize::MAX, |x| x as usize),
        row.faces.map_or(usize::MAX, |x| x as usize),
        row.split,
    );
    if found != listed {
        return Err(format!(
            "clips.bin holds (id, source, caption, T, N, M, split) = {found:?}, {INDEX_FILE} lists {listed:?}"
        ));
    }
    Ok(())
}

//! `data merge`: a sharded store's manifest written over shard folders imported apart (layout and rules in
//! [`super::shards`]), after checking that they make one store, each shard at most a bounded size.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::shards::{
    MANIFEST_FILE, MANIFEST_FORMAT, MANIFEST_VERSION, Manifest, ShardEntry, SplitRule, file_checksum, slash_path,
    source_base, write_manifest,
};
use super::{CLIPS_FILE, INDEX_FILE, IndexRow, Status, Store, check_index};
use crate::error::{DataError, Result};

/// Write `store/manifest.json` listing the one-file stores `shards` (in this order); returns the manifest.
/// Refuses shards that disagree on T, P or the scene flag, two shards holding the same source, a shard named
/// twice, a shard whose `clips.bin` does not match its index, and a store folder that is itself a one-file store.
/// The manifest is written to a temporary name and renamed into place.
pub fn merge(store: &Path, shards: &[PathBuf]) -> Result<Manifest> {
    merge_bounded(store, shards, DEFAULT_MAX_SHARD_BYTES)
}

/// The largest `clips.bin` [`merge`] takes into a store: 1 GiB, so that a shard is a unit a worker fetches, caches
/// and checksums in seconds, and a store's shards are many enough to spread over machines (docs/data.md).
pub const DEFAULT_MAX_SHARD_BYTES: u64 = 1 << 30;

/// Parses a byte size: a whole number with an optional unit, `K`/`M`/`G`/`T` or `KB`…`TB` (powers of 1,000) or
/// `KiB`…`TiB` (powers of 1,024), case-insensitive: `1GiB`, `500M`, `2000000000`. Zero, fractions, signs and sizes
/// past 2⁶⁴ are refused.
pub fn parse_bytes(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    let split = t.find(|c: char| !c.is_ascii_digit()).unwrap_or(t.len());
    let (digits, unit) = t.split_at(split);
    if digits.is_empty() {
        return Err(format!(
            "{text:?} is not a size: a whole number with an optional unit (1GiB, 500M, 2000000000)"
        ));
    }
    let scale: u64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1,
        "k" | "kb" => 1_000,
        "m" | "mb" => 1_000_000,
        "g" | "gb" => 1_000_000_000,
        "t" | "tb" => 1_000_000_000_000,
        "kib" => 1 << 10,
        "mib" => 1 << 20,
        "gib" => 1 << 30,
        "tib" => 1 << 40,
        other => {
            return Err(format!(
                "{text:?}: unknown unit {other:?} (K, M, G, T, KiB, MiB, GiB, TiB)"
            ));
        }
    };
    let n: u64 = digits
        .parse()
        .map_err(|_| format!("{text:?} is larger than 2^64 bytes"))?;
    match n.checked_mul(scale) {
        Some(0) => Err(format!("{text:?}: a size must be positive")),
        Some(b) => Ok(b),
        None => Err(format!("{text:?} is larger than 2^64 bytes")),
    }
}

/// [`merge`] refusing, before anything is read or written, a shard whose `clips.bin` is larger than `max_bytes`,
/// naming each such shard and a shard count `N` for `--shard K/N` that would keep them under the bound.
pub fn merge_bounded(store: &Path, shards: &[PathBuf], max_bytes: u64) -> Result<Manifest> {
    let mut sizes = Vec::with_capacity(shards.len());
    for dir in shards {
        // A missing file is left to the checks of the merge itself, which name it.
        sizes.push(std::fs::metadata(dir.join(CLIPS_FILE)).map_or(0, |m| m.len()));
    }
    let over: Vec<String> = shards
        .iter()
        .zip(&sizes)
        .filter(|&(_, &b)| b > max_bytes)
        .map(|(d, b)| format!("{} ({b} bytes)", d.display()))
        .collect();
    if !over.is_empty() {
        let total: u64 = sizes.iter().sum();
        // Hash shares vary by a few percent; a quarter of headroom keeps every shard under the bound.
        let n = (total as f64 * 1.25 / max_bytes as f64).ceil().max(1.0) as u64;
        return Err(DataError::new(
            store,
            "max shard bytes",
            format!(
                "{} larger than the bound of {max_bytes} bytes: {}; the {} shards hold {total} bytes together, so \
                 import them again as --shard K/{n} (or raise --max-shard-bytes)",
                if over.len() == 1 { "one shard is" } else { "shards are" },
                over.join(", "),
                shards.len()
            ),
        ));
    }
    merge_checked(store, shards)
}

fn merge_checked(store: &Path, shards: &[PathBuf]) -> Result<Manifest> {
    if shards.is_empty() {
        return Err(DataError::new(store, "shards", "no shard folder given"));
    }
    if let Some(url) = std::iter::once(store)
        .chain(shards.iter().map(PathBuf::as_path))
        .find(|p| super::is_url(p))
    {
        return Err(DataError::new(
            url,
            "merge",
            "a merge reads and writes local folders; upload the merged store with scripts/upload_store.py",
        ));
    }
    if store.join(CLIPS_FILE).exists() {
        return Err(DataError::new(
            store,
            CLIPS_FILE,
            "this folder is a one-file store: merge shards into a new folder",
        ));
    }
    let mut entries = Vec::with_capacity(shards.len());
    let mut first: Option<(PathBuf, usize, usize, bool)> = None;
    let mut owner: HashMap<String, usize> = HashMap::new();
    let mut seen: HashMap<PathBuf, usize> = HashMap::new();
    for (k, dir) in shards.iter().enumerate() {
        let canon = std::fs::canonicalize(dir).map_err(|e| DataError::io(dir, e))?;
        if let Some(j) = seen.insert(canon.clone(), k) {
            return Err(DataError::new(
                dir,
                "shards",
                format!("named twice (shards {j} and {k})"),
            ));
        }
        if canon.join(MANIFEST_FILE).exists() {
            return Err(DataError::new(
                dir,
                MANIFEST_FILE,
                "this folder is itself a sharded store: merge its shard folders instead",
            ));
        }
        let shard = Store::open(&canon)?;
        let rows = super::index::read_index_file(&canon)?;
        check_index(&shard, &rows)?;
        let shape = (shard.frames(), shard.p(), shard.has_scenes());
        match &first {
            None => first = Some((dir.clone(), shape.0, shape.1, shape.2)),
            Some((d0, t, p, s)) => {
                if shape != (*t, *p, *s) {
                    return Err(DataError::new(
                        dir,
                        "shard",
                        format!(
                            "holds T = {}, P = {}, scenes {}; shard {} holds T = {t}, P = {p}, scenes {s}: all \
                             shards of a store must agree",
                            shape.0,
                            shape.1,
                            shape.2,
                            d0.display()
                        ),
                    ));
                }
            }
        }
        for row in &rows {
            let base = source_base(&row.source);
            if let Some(&j) = owner.get(base)
                && j != k
            {
                return Err(DataError::new(
                    dir,
                    INDEX_FILE,
                    format!(
                        "source {base} is also in shard {}: two shards claim one source (imported with different \
                         --shard splits?)",
                        shards[j].display()
                    ),
                ));
            }
            owner.insert(base.to_owned(), k);
        }
        let ok: Vec<&IndexRow> = rows.iter().filter(|r| r.status == Status::Ok).collect();
        let val = ok.iter().filter(|r| r.split == Some(super::Split::Val)).count();
        let (bytes, sum) = file_checksum(&canon.join(CLIPS_FILE))?;
        entries.push(ShardEntry {
            // Made relative to the store below, once every shard passed and the folder exists.
            path: canon.display().to_string(),
            clips: ok.len(),
            train: ok.len() - val,
            val,
            rejected: rows.len() - ok.len(),
            bytes,
            checksum: format!("{sum:016x}"),
        });
    }
    std::fs::create_dir_all(store).map_err(|e| DataError::io(store, e))?;
    let store_canon = std::fs::canonicalize(store).map_err(|e| DataError::io(store, e))?;
    for entry in &mut entries {
        if let Ok(rel) = Path::new(&entry.path).strip_prefix(&store_canon)
            && rel.components().count() > 0
        {
            entry.path = slash_path(rel);
        }
    }
    let (_, frames, p, scenes) = first.expect("at least one shard");
    let manifest = Manifest {
        format: MANIFEST_FORMAT.to_owned(),
        version: MANIFEST_VERSION,
        frames,
        p,
        scenes,
        split: SplitRule::current(),
        shards: entries,
    };
    write_manifest(store, &manifest)?;
    Ok(manifest)
}

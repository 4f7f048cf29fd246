//! Sharded stores: one store made of shard folders, each a one-file store, listed by a manifest.
//!
//! A store that no single process can write (DyMesh is 1.7 TB) is imported one shard at a time, by as many
//! processes or machines as there are — a Slurm array, a Kubernetes indexed Job, GNU parallel: `data import
//! --shard K/N` (or `data synth --shard K/N`) takes the sources whose [`ShardSpec::takes`] hash lands on K and
//! writes them as an ordinary one-file store; `data merge STORE SHARD...` then writes `STORE/manifest.json`, which
//! lists the shards without copying a clip. [`super::Store::open`] reads a sharded store as one store whose clips
//! are numbered shard after shard; a one-file store is a store of one shard.
//!
//! # `manifest.json`
//! ```text
//! { "format": "any4d-sharded-store", "version": 1, "frames": T, "p": P, "scenes": bool,
//!   "split": { "key": "object uid", "seed": 666, "val_fraction": 0.2 },
//!   "shards": [ { "path": "shard-0000", "clips": …, "train": …, "val": …, "rejected": …,
//!                 "bytes": size of its clips.bin, "checksum": xxh3-64 of its clips.bin in 16 hex digits }, … ] }
//! ```
//! A shard's `path` is relative to the store folder when the shard lies inside it (the store can then be moved
//! or copied whole), else absolute. Opening checks every shard against its line: present, `bytes` long (a
//! truncated shard, or one re-imported since the merge, fails here), and of the manifest's T, P, scene flag and
//! clip count. The checksum is read in full only by `data verify`, which also verifies every clip.
//!
//! # Which shard a source lands on
//! The key of a file is its path relative to the source folder it was found under (its file name when it was
//! named itself), `/`-separated; the key of a procedural clip is its `synth:<seed>:<index>`. Source K of N takes
//! the keys whose xxh3-64 is K modulo N. The key reads nothing but the path below the folder given, so the same
//! file lands in the same shard on every machine and in every run, and re-importing a source rewrites only its
//! shard (then `data merge` again, to record the shard's new size and checksum). The 80/20 split is still the
//! object-uid rule of [`super::Split::of_object`], which does not depend on the sharding.

use std::collections::HashMap;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::{CLIPS_FILE, IndexRow, Part, SPLIT_SEED, Status, Store, VAL_FRACTION};
use crate::error::{DataError, Result};

/// File name of a sharded store's manifest.
pub const MANIFEST_FILE: &str = "manifest.json";
/// The manifest's `format` value.
pub const MANIFEST_FORMAT: &str = "any4d-sharded-store";
/// The manifest layout written by this build.
pub const MANIFEST_VERSION: u32 = 1;
/// Largest manifest read (a line is about 200 bytes, so about a million shards).
pub const MAX_MANIFEST_BYTES: u64 = 256 << 20;
/// Most shards a store may have (a manifest claiming more is refused before anything is opened).
pub const MAX_SHARDS: usize = 1 << 20;
/// The split rule's key: the object uid of [`crate::clip::object_uid`].
pub const SPLIT_KEY: &str = "object uid";

/// A sharded store's manifest (layout in the module doc).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    pub format: String,
    pub version: u32,
    /// Frames per clip T, the same in every shard.
    pub frames: usize,
    /// FPS tokens per clip P, the same in every shard.
    pub p: usize,
    /// Whether the shards' records carry a scene section.
    pub scenes: bool,
    pub split: SplitRule,
    pub shards: Vec<ShardEntry>,
}

/// The train/validation rule the shards were split by (docs/method.md §2.2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SplitRule {
    pub key: String,
    pub seed: u64,
    pub val_fraction: f64,
}

impl SplitRule {
    /// The rule of this build: object uid, seed [`SPLIT_SEED`], [`VAL_FRACTION`] to validation.
    pub fn current() -> Self {
        Self {
            key: SPLIT_KEY.to_owned(),
            seed: SPLIT_SEED,
            val_fraction: VAL_FRACTION,
        }
    }
}

/// One shard of a manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardEntry {
    /// The shard folder: relative to the store folder, or absolute.
    pub path: String,
    /// Stored clips, and how they split.
    pub clips: usize,
    pub train: usize,
    pub val: usize,
    /// Rejected sources listed in the shard's index.
    pub rejected: usize,
    /// Size of the shard's `clips.bin`.
    pub bytes: u64,
    /// xxh3-64 of the shard's `clips.bin`, 16 lower-case hex digits.
    pub checksum: String,
}

/// `K/N`: shard K of N (0 ≤ K < N), the share of the sources one import process takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShardSpec {
    pub index: usize,
    pub count: usize,
}

impl ShardSpec {
    /// Whether a source of this key (module doc) belongs to this shard.
    pub fn takes(&self, key: &str) -> bool {
        xxhash_rust::xxh3::xxh3_64(key.as_bytes()) % self.count as u64 == self.index as u64
    }
}

impl FromStr for ShardSpec {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let (k, n) = s
            .split_once('/')
            .ok_or_else(|| format!("{s:?} is not K/N (shard K of N, counted from 0: 0/4 … 3/4)"))?;
        let parse = |v: &str, what: &str| {
            v.trim()
                .parse::<usize>()
                .map_err(|e| format!("{what} {v:?} in {s:?}: {e}"))
        };
        let (index, count) = (parse(k, "shard index")?, parse(n, "shard count")?);
        if count == 0 {
            return Err(format!("{s:?}: the shard count must be at least 1"));
        }
        if count > MAX_SHARDS {
            return Err(format!("{s:?}: at most {MAX_SHARDS} shards"));
        }
        if index >= count {
            return Err(format!(
                "{s:?}: shard index {index} is not below the count {count} (shards are counted from 0)"
            ));
        }
        Ok(Self { index, count })
    }
}

/// The shard key of `path` (module doc), found under one of the canonical `roots` (a folder it lies in, or the
/// file itself).
pub fn shard_key(path: &Path, roots: &[PathBuf]) -> String {
    let below = roots
        .iter()
        .filter(|r| r.as_path() != path)
        .filter_map(|r| path.strip_prefix(r).ok())
        .min_by_key(|rel| rel.components().count());
    match below {
        Some(rel) => slash_path(rel),
        None => path
            .file_name()
            .map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned()),
    }
}

/// A relative path with `/` between its parts, whatever the platform.
pub(super) fn slash_path(rel: &Path) -> String {
    rel.components()
        .map(|c| c.as_os_str().to_string_lossy())
        .collect::<Vec<_>>()
        .join("/")
}

/// The file part of a source (`path#take` → `path`): all takes of a file are imported together.
pub(super) fn source_base(source: &str) -> &str {
    source.rsplit_once('#').map_or(source, |(path, _)| path)
}

/// (size, xxh3-64) of a file, read in 8 MiB pieces.
pub fn file_checksum(path: &Path) -> Result<(u64, u64)> {
    let mut file = File::open(path).map_err(|e| DataError::io(path, e))?;
    let mut hasher = xxhash_rust::xxh3::Xxh3::new();
    let mut buf = vec![0u8; 8 << 20];
    let mut bytes = 0u64;
    loop {
        let n = file.read(&mut buf).map_err(|e| DataError::io(path, e))?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
        bytes += n as u64;
    }
    Ok((bytes, hasher.digest()))
}

/// Write `store/manifest.json` atomically.
pub(super) fn write_manifest(store: &Path, manifest: &Manifest) -> Result<()> {
    let path = store.join(MANIFEST_FILE);
    let mut text =
        serde_json::to_string_pretty(manifest).map_err(|e| DataError::new(&path, "manifest", e.to_string()))?;
    text.push('\n');
    crate::io::write_atomic(&path, text.as_bytes())
}

/// Read and check `store/manifest.json` (size, JSON, format, version, split rule, shard count, unique paths); the
/// shards themselves are not opened.
pub fn read_manifest(store: &Path) -> Result<Manifest> {
    let path = store.join(MANIFEST_FILE);
    let err = |field: &str, reason: String| DataError::new(&path, field, reason);
    let file = File::open(&path).map_err(|e| DataError::io(&path, e))?;
    let size = file.metadata().map_err(|e| DataError::io(&path, e))?.len();
    if size > MAX_MANIFEST_BYTES {
        return Err(err(
            "file",
            format!("{size} bytes; a manifest is at most {MAX_MANIFEST_BYTES} bytes"),
        ));
    }
    let mut text = String::new();
    file.take(MAX_MANIFEST_BYTES)
        .read_to_string(&mut text)
        .map_err(|e| DataError::io(&path, e))?;
    parse_manifest(&text, &path)
}

/// [`read_manifest`] of a manifest's text; `path` names it in errors.
pub fn parse_manifest(text: &str, path: &Path) -> Result<Manifest> {
    let err = |field: &str, reason: String| DataError::new(path, field, reason);
    let manifest: Manifest = serde_json::from_str(text).map_err(|e| {
        err(
            &format!("line {} column {}", e.line(), e.column()),
            format!("{e}: not a manifest of this build"),
        )
    })?;
    if manifest.format != MANIFEST_FORMAT {
        return Err(err(
            "format",
            format!("{:?}, expected {MANIFEST_FORMAT:?}", manifest.format),
        ));
    }
    if manifest.version != MANIFEST_VERSION {
        return Err(err(
            "version",
            format!("{}; this build reads version {MANIFEST_VERSION}", manifest.version),
        ));
    }
    if manifest.split != SplitRule::current() {
        return Err(err(
            "split",
            format!(
                "{:?}; this build splits by {:?}: clips would change sides",
                manifest.split,
                SplitRule::current()
            ),
        ));
    }
    if manifest.shards.is_empty() || manifest.shards.len() > MAX_SHARDS {
        return Err(err(
            "shards",
            format!("{} shards; a store has 1 to {MAX_SHARDS}", manifest.shards.len()),
        ));
    }
    let mut paths = HashMap::new();
    for (k, s) in manifest.shards.iter().enumerate() {
        if let Some(j) = paths.insert(s.path.as_str(), k) {
            return Err(err(
                &format!("shards[{k}].path"),
                format!("{:?} is also shard {j}", s.path),
            ));
        }
    }
    Ok(manifest)
}

/// The folder of shard `entry` of the store in `store`.
pub fn shard_dir(store: &Path, entry: &ShardEntry) -> PathBuf {
    let p = Path::new(&entry.path);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        store.join(p)
    }
}

/// Open the sharded store in `dir` ([`super::Store::open`] calls this when the folder holds a manifest).
pub(super) fn open(dir: &Path) -> Result<Store> {
    let manifest = read_manifest(dir)?;
    let mut parts = Vec::with_capacity(manifest.shards.len());
    for (k, entry) in manifest.shards.iter().enumerate() {
        let shard = shard_dir(dir, entry);
        let clips = shard.join(CLIPS_FILE);
        let field = format!("{MANIFEST_FILE} shards[{k}] ({})", entry.path);
        let size = match std::fs::metadata(&clips) {
            Ok(m) => m.len(),
            Err(e) => {
                return Err(DataError::new(&clips, field, format!("the shard is missing ({e})")));
            }
        };
        if size != entry.bytes {
            return Err(DataError::new(
                &clips,
                field,
                format!(
                    "{size} bytes, the manifest records {}: truncated, or re-imported since the merge (run `data \
                     merge` again)",
                    entry.bytes
                ),
            ));
        }
        let part = Part::open(&shard)?;
        let c = &part.catalog;
        if (c.frames, c.p, c.scenes, c.entries.len()) != (manifest.frames, manifest.p, manifest.scenes, entry.clips) {
            return Err(DataError::new(
                &clips,
                field,
                format!(
                    "holds T = {}, P = {}, scenes {}, {} clips; the manifest records T = {}, P = {}, scenes {}, {} \
                     clips",
                    c.frames,
                    c.p,
                    c.scenes,
                    c.entries.len(),
                    manifest.frames,
                    manifest.p,
                    manifest.scenes,
                    entry.clips
                ),
            ));
        }
        let checksum = u64::from_str_radix(&entry.checksum, 16).map_err(|_| {
            DataError::new(
                dir.join(MANIFEST_FILE),
                format!("shards[{k}].checksum ({})", entry.path),
                format!("{:?} is not 16 hex digits", entry.checksum),
            )
        })?;
        parts.push(Part {
            checksum: Some(checksum),
            ..part
        });
    }
    Ok(Store::of_parts(dir, parts))
}

/// The index of a sharded store: every shard's stored rows in shard order (the store's clip order), then every
/// shard's rejected rows.
pub(super) fn read_index(dir: &Path) -> Result<Vec<IndexRow>> {
    let manifest = read_manifest(dir)?;
    let mut ok = Vec::new();
    let mut rejected = Vec::new();
    for entry in &manifest.shards {
        let rows = super::index::read_index_file(&shard_dir(dir, entry))?;
        let (o, r): (Vec<IndexRow>, Vec<IndexRow>) = rows.into_iter().partition(|r| r.status == Status::Ok);
        ok.extend(o);
        rejected.extend(r);
    }
    ok.extend(rejected);
    Ok(ok)
}

/// Check every shard's `clips.bin` against the checksum its manifest line records (read in full).
pub fn check_checksums(dir: &Path) -> Result<()> {
    let manifest = read_manifest(dir)?;
    for (k, entry) in manifest.shards.iter().enumerate() {
        let clips = shard_dir(dir, entry).join(CLIPS_FILE);
        let (bytes, sum) = file_checksum(&clips)?;
        let sum = format!("{sum:016x}");
        if bytes != entry.bytes || sum != entry.checksum {
            return Err(DataError::new(
                &clips,
                format!("{MANIFEST_FILE} shards[{k}] ({})", entry.path),
                format!(
                    "{bytes} bytes with checksum {sum}; the manifest records {} bytes with checksum {}: the shard \
                     changed after the merge (re-imported: run `data merge` again; else it is damaged)",
                    entry.bytes, entry.checksum
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_specs_parse_and_refuse() {
        assert_eq!("3/4".parse::<ShardSpec>(), Ok(ShardSpec { index: 3, count: 4 }));
        assert_eq!("0/1".parse::<ShardSpec>(), Ok(ShardSpec { index: 0, count: 1 }));
        for bad in ["3/2", "2/2", "0/0", "1", "a/2", "1/b", "-1/2", "", "/", "1/99999999999"] {
            let e = bad.parse::<ShardSpec>().unwrap_err();
            assert!(e.contains(&format!("{bad:?}")) || bad.is_empty(), "{bad}: {e}");
        }
    }

    #[test]
    fn every_key_lands_on_exactly_one_shard() {
        let n = 5;
        let specs: Vec<ShardSpec> = (0..n).map(|index| ShardSpec { index, count: n }).collect();
        let mut per = vec![0usize; n];
        for i in 0..2000 {
            let key = format!("synth:7:{i}");
            let takers: Vec<usize> = specs.iter().filter(|s| s.takes(&key)).map(|s| s.index).collect();
            assert_eq!(takers.len(), 1, "{key}");
            per[takers[0]] += 1;
        }
        // Binomial(2000, 0.2): mean 400, sd 18; ±100 is more than 5 sd.
        assert!(per.iter().all(|&c| (300..=500).contains(&c)), "{per:?}");
        // The hash is frozen: a change would move sources between shards of stores already imported.
        let golden: String = (0..16)
            .map(|i| char::from(b'0' + (xxhash_rust::xxh3::xxh3_64(format!("k{i}").as_bytes()) % 10) as u8))
            .collect();
        assert_eq!(golden, SHARD_GOLDEN);
    }

    /// xxh3-64 of `k0`…`k15` modulo 10 (printed once by this test and frozen).
    const SHARD_GOLDEN: &str = "3518148511351489";

    #[test]
    fn keys_are_relative_to_the_folder_given() {
        let roots = [PathBuf::from("/data/corpus"), PathBuf::from("/data/one.glb")];
        assert_eq!(shard_key(Path::new("/data/corpus/a/b.md2"), &roots), "a/b.md2");
        assert_eq!(shard_key(Path::new("/data/one.glb"), &roots), "one.glb");
        // Moved elsewhere, the same tree gives the same keys.
        let moved = [PathBuf::from("/mnt/x/corpus")];
        assert_eq!(shard_key(Path::new("/mnt/x/corpus/a/b.md2"), &moved), "a/b.md2");
    }
}

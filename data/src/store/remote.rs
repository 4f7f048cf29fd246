//! Stores in object storage: a sharded store (its `manifest.json` and shard folders, [`super::shards`]) read from an
//! `s3://`, `gs://`, `az://` or `http(s)://` URL through the `object_store` crate, cached on local disk shard by
//! shard.
//!
//! Every command that takes a store folder takes such a URL: [`local_dir`] fetches the manifest, then every shard
//! whose cached copy is not the one the manifest records (by size and checksum), and returns the cache folder, a
//! local sharded store. A shard is streamed to a temporary file while its xxh3-64 is computed, checked against the
//! manifest's size and checksum, and only then renamed into place; the cache's own manifest is written last. A
//! transfer that fails halfway, a server that sends more or fewer bytes than the manifest records, or a checksum
//! that disagrees is an error naming the shard, and leaves no file that looks complete.
//!
//! Credentials and endpoints come from the environment as each service's tools expect (`AWS_ACCESS_KEY_ID`,
//! `AWS_SECRET_ACCESS_KEY`, `AWS_REGION`, `AWS_ENDPOINT_URL`, `AWS_ALLOW_HTTP`, `GOOGLE_SERVICE_ACCOUNT`,
//! `AZURE_STORAGE_ACCOUNT_NAME`, …: the keys of `object_store`'s builders). The cache lives in `$ANY4D_CACHE`, else
//! `$XDG_CACHE_HOME/any4d`, else `$HOME/.cache/any4d`, under `stores/`, one folder per URL. A remote store's
//! shards must lie inside it (relative paths without `..`).

use std::io::Write;
use std::path::{Component, Path, PathBuf};

use futures::StreamExt;
use object_store::ObjectStore;
use object_store::ObjectStoreExt;
use object_store::path::Path as ObjectPath;

use super::shards::{MANIFEST_FILE, MAX_MANIFEST_BYTES, parse_manifest};
use super::{CLIPS_FILE, INDEX_FILE};
use crate::error::{DataError, Result};

pub use super::{URL_SCHEMES, is_url};

/// Largest shard index file fetched (its `clips.bin` is bounded by the manifest's size instead).
pub const MAX_INDEX_BYTES: u64 = 1 << 30;

/// Name of the marker beside a cached shard's files: the checksum of the `clips.bin` it holds, written once both
/// files are in place.
const MARKER: &str = ".fetched";

/// `p` itself for a folder; for a URL the local cache folder of the store it names, fetched first ([`fetch`]
/// with the environment's options, in [`cache_root`]).
pub fn local_dir(p: &Path) -> Result<PathBuf> {
    match p.to_str() {
        Some(url) if is_url(p) => fetch(url, &env_options(), &cache_root()?),
        _ => Ok(p.to_path_buf()),
    }
}

/// The folder remote stores are cached in (module doc).
pub fn cache_root() -> Result<PathBuf> {
    let var = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty()).map(PathBuf::from);
    let base = var("ANY4D_CACHE")
        .or_else(|| var("XDG_CACHE_HOME").map(|d| d.join("any4d")))
        .or_else(|| var("HOME").map(|d| d.join(".cache").join("any4d")))
        .ok_or_else(|| {
            DataError::new(
                "remote store",
                "cache",
                "no cache folder: set ANY4D_CACHE (or XDG_CACHE_HOME or HOME)",
            )
        })?;
    Ok(base.join("stores"))
}

/// The environment variables the object-storage builders read (lower-cased names; the builders ignore the rest).
pub fn env_options() -> Vec<(String, String)> {
    std::env::vars()
        .map(|(k, v)| (k.to_ascii_lowercase(), v))
        .filter(|(k, _)| ["aws_", "google_", "azure_"].iter().any(|p| k.starts_with(p)))
        .collect()
}

/// Fetch the sharded store at `url` into its folder under `cache` with the builder `options` (module doc); returns
/// that folder.
pub fn fetch(url: &str, options: &[(String, String)], cache: &Path) -> Result<PathBuf> {
    let err = |field: &str, reason: String| DataError::new(url, field, reason);
    let parsed = url::Url::parse(url.trim_end_matches('/')).map_err(|e| err("url", e.to_string()))?;
    let mut options = options.to_vec();
    if parsed.scheme() == "http" {
        // A plain-http URL was asked for by name; the client refuses plain http unless told.
        options.push(("allow_http".into(), "true".into()));
    }
    let (store, base) = object_store::parse_url_opts(&parsed, options).map_err(|e| err("url", e.to_string()))?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| err("runtime", e.to_string()))?;
    let dir = cache.join(cache_name(url));
    fetch_into(&runtime, store.as_ref(), &base, url, &dir)?;
    Ok(dir)
}

/// A cache folder name for `url`: its host and path made safe, then its hash (two URLs never share a folder).
fn cache_name(url: &str) -> String {
    let readable: String = url
        .split_once("://")
        .map_or(url, |(_, rest)| rest)
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .take(80)
        .collect();
    format!("{readable}-{:016x}", xxhash_rust::xxh3::xxh3_64(url.as_bytes()))
}

fn fetch_into(
    runtime: &tokio::runtime::Runtime,
    store: &dyn ObjectStore,
    base: &ObjectPath,
    url: &str,
    dir: &Path,
) -> Result<()> {
    let at = |rel: &str| -> ObjectPath { rel.split('/').fold(base.clone(), |p, part| p.clone().join(part)) };
    let manifest_url = format!("{}/{MANIFEST_FILE}", url.trim_end_matches('/'));
    let text = runtime
        .block_on(fetch_small(
            store,
            &at(MANIFEST_FILE),
            &manifest_url,
            MAX_MANIFEST_BYTES,
        ))
        .map_err(|mut e| {
            e.reason += " (a store in object storage is a sharded store: `data merge` writes its manifest.json)";
            e
        })?;
    let text = String::from_utf8(text).map_err(|e| DataError::new(&manifest_url, "file", e.to_string()))?;
    let manifest = parse_manifest(&text, Path::new(&manifest_url))?;
    for (k, entry) in manifest.shards.iter().enumerate() {
        let rel = Path::new(&entry.path);
        if rel.is_absolute() || rel.components().any(|c| !matches!(c, Component::Normal(_))) {
            return Err(DataError::new(
                &manifest_url,
                format!("shards[{k}].path"),
                format!(
                    "{:?}: a remote store's shards must lie inside it (a relative path without ..)",
                    entry.path
                ),
            ));
        }
    }
    std::fs::create_dir_all(dir).map_err(|e| DataError::io(dir, e))?;
    for (k, entry) in manifest.shards.iter().enumerate() {
        let local = dir.join(&entry.path);
        let marker = local.join(MARKER);
        let fresh = std::fs::read_to_string(&marker).is_ok_and(|m| m.trim() == entry.checksum)
            && std::fs::metadata(local.join(CLIPS_FILE)).is_ok_and(|m| m.len() == entry.bytes)
            && local.join(INDEX_FILE).is_file();
        if fresh {
            continue;
        }
        std::fs::create_dir_all(&local).map_err(|e| DataError::io(&local, e))?;
        // The marker goes first, so a fetch cut short never leaves one that vouches for a half-replaced shard.
        match std::fs::remove_file(&marker) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(DataError::io(&marker, e)),
            _ => {}
        }
        let shard_url = format!("{}/{}", url.trim_end_matches('/'), entry.path);
        let label = format!("{MANIFEST_FILE} shards[{k}] ({})", entry.path);
        fetch_clips(
            runtime,
            store,
            &at(&format!("{}/{CLIPS_FILE}", entry.path)),
            &shard_url,
            &label,
            entry,
            &local,
        )?;
        let index = runtime.block_on(fetch_small(
            store,
            &at(&format!("{}/{INDEX_FILE}", entry.path)),
            &shard_url,
            MAX_INDEX_BYTES,
        ))?;
        crate::io::write_atomic(&local.join(INDEX_FILE), &index)?;
        crate::io::write_atomic(&marker, entry.checksum.as_bytes())?;
    }
    // Last: until it is written, the cache folder is not a store.
    super::shards::write_manifest(dir, &manifest)
}

/// A whole object of at most `limit` bytes (its size is checked before it is read).
async fn fetch_small(store: &dyn ObjectStore, path: &ObjectPath, url: &str, limit: u64) -> Result<Vec<u8>> {
    let err = |reason: String| DataError::new(url, path.as_ref(), reason);
    let got = store.get(path).await.map_err(|e| err(format!("cannot be read: {e}")))?;
    if got.meta.size > limit {
        return Err(err(format!("{} bytes; at most {limit} are read", got.meta.size)));
    }
    let mut out = Vec::new();
    let mut stream = got.into_stream();
    while let Some(chunk) = stream.next().await {
        let chunk = chunk.map_err(|e| err(format!("the transfer failed after {} bytes: {e}", out.len())))?;
        if out.len() as u64 + chunk.len() as u64 > limit {
            return Err(err(format!("more than {limit} bytes")));
        }
        out.extend_from_slice(&chunk);
    }
    Ok(out)
}

/// Stream a shard's `clips.bin` into place through [`crate::io::write_atomic_with`], checking its size and checksum
/// against the manifest line before the temporary file is renamed over the cached copy.
fn fetch_clips(
    runtime: &tokio::runtime::Runtime,
    store: &dyn ObjectStore,
    path: &ObjectPath,
    url: &str,
    label: &str,
    entry: &super::shards::ShardEntry,
    local: &Path,
) -> Result<()> {
    let err = |reason: String| DataError::new(format!("{url}/{CLIPS_FILE}"), label, reason);
    let got = runtime
        .block_on(store.get(path))
        .map_err(|e| err(format!("cannot be read: {e}")))?;
    if got.meta.size != entry.bytes {
        return Err(err(format!(
            "{} bytes, the manifest records {}: the shard changed after the merge",
            got.meta.size, entry.bytes
        )));
    }
    crate::io::write_atomic_with(&local.join(CLIPS_FILE), |out, tmp| {
        runtime.block_on(async {
            let mut hasher = xxhash_rust::xxh3::Xxh3::new();
            let mut bytes = 0u64;
            let mut stream = got.into_stream();
            while let Some(chunk) = stream.next().await {
                let chunk = chunk.map_err(|e| err(format!("the transfer failed after {bytes} bytes: {e}")))?;
                bytes += chunk.len() as u64;
                if bytes > entry.bytes {
                    return Err(err(format!("more than the {} bytes the manifest records", entry.bytes)));
                }
                hasher.update(&chunk);
                out.write_all(&chunk).map_err(|e| DataError::io(tmp, e))?;
            }
            let sum = format!("{:016x}", hasher.digest());
            if bytes != entry.bytes || sum != entry.checksum {
                return Err(err(format!(
                    "{bytes} bytes with checksum {sum} arrived; the manifest records {} bytes with checksum {}",
                    entry.bytes, entry.checksum
                )));
            }
            Ok(())
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_are_told_from_folders_and_cached_apart() {
        assert!(is_url(Path::new("s3://bucket/store")));
        assert!(is_url(Path::new("https://host/store/")));
        assert!(!is_url(Path::new("/data/s3://x")));
        assert!(!is_url(Path::new("store")));
        let a = cache_name("s3://bucket/store");
        assert!(a.starts_with("bucket_store-"), "{a}");
        assert_ne!(a, cache_name("s3://bucket/store2"));
        assert_ne!(
            cache_name("s3://b/a_b"),
            cache_name("s3://b/a/b"),
            "the hash keeps look-alikes apart"
        );
    }
}

//! Loading a glTF document: the GLB container, the JSON (parsed and validated by the gltf crate) and every
//! buffer, each checked against [`BUFFER_BYTES`](crate::limits::BUFFER_BYTES) and its declared `byteLength` before it is used.
//!
//! Buffer URIs: no URI is buffer 0 of a GLB (its BIN chunk); `data:…;base64,` is decoded in memory; anything else
//! must be a relative path (percent-encoded as a URI reference) that names a regular file inside the folder of the
//! glTF file, after symlinks are resolved. Absolute paths, `..`, other schemes, FIFOs, devices and files shorter
//! than `byteLength` are errors; only `byteLength` bytes are read.

use std::io::Read;
use std::path::{Component, Path};

use base64::Engine;
use base64::engine::{DecodePaddingMode, GeneralPurpose, GeneralPurposeConfig};
use gltf::json::Root;
use gltf::json::mesh::Semantic;
use gltf::json::validation::Checked;

use super::{Ctx, ExternalBuffers};
use crate::error::Result;
use crate::limits::BUFFER_BYTES;

/// A document with its buffers (each exactly `byteLength` bytes) and the caption from `asset.extras.caption`.
pub(super) struct Document {
    pub root: Root,
    pub buffers: Vec<Vec<u8>>,
    pub caption: Option<String>,
}

/// GLB magic, first 4 bytes of a binary glTF.
const GLB_MAGIC: &[u8; 4] = b"glTF";

/// Parse `bytes` (glTF JSON or GLB), validate it and load its buffers.
pub(super) fn load(ctx: Ctx, bytes: &[u8], external: &ExternalBuffers) -> Result<Document> {
    let (json, bin) = if bytes.starts_with(GLB_MAGIC) {
        split_glb(ctx, bytes)?
    } else {
        (bytes, None)
    };
    let root: Root = gltf::json::deserialize::from_slice(json).map_err(|e| ctx.err("gltf", e.to_string()))?;
    // The gltf crate's validation indexes `accessors` by each POSITION attribute without a bounds check.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if let Some(a) = prim.attributes.get(&Checked::Valid(Semantic::Positions))
                && a.value() >= root.accessors.len()
            {
                return Err(ctx.err(
                    format!("meshes[{m}].primitives[{p}].attributes.POSITION"),
                    format!("accessor {} does not exist", a.value()),
                ));
            }
        }
    }
    let root = gltf::Document::from_json(root)
        .map_err(|e| ctx.err("gltf", e.to_string()))?
        .into_json();
    let caption = caption_of(json);
    let mut buffers = Vec::with_capacity(root.buffers.len());
    for (i, b) in root.buffers.iter().enumerate() {
        let field = format!("buffers[{i}]");
        let declared = b.byte_length.0;
        let limit = BUFFER_BYTES.get();
        if declared > limit {
            return Err(ctx.err(
                &field,
                format!(
                    "byteLength {declared} is more than the limit of {limit} bytes{}",
                    BUFFER_BYTES.hint()
                ),
            ));
        }
        let declared = declared as usize;
        let mut data = match (&b.uri, bin) {
            (None, Some(bin)) if i == 0 => bin.to_vec(),
            (None, _) => {
                return Err(ctx.err(&field, "has no uri and is not the BIN chunk of a GLB file"));
            }
            (Some(uri), _) if uri.starts_with("data:") => data_uri(uri).map_err(|r| ctx.err(&field, r))?,
            (Some(uri), _) => external_file(ctx, &field, uri, declared, external)?,
        };
        if data.len() < declared {
            return Err(ctx.err(
                &field,
                format!("holds {} bytes, byteLength says {declared}", data.len()),
            ));
        }
        data.truncate(declared);
        buffers.push(data);
    }
    Ok(Document { root, buffers, caption })
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// The JSON chunk and the optional BIN chunk of a GLB; every length is checked against the file.
fn split_glb<'a>(ctx: Ctx, bytes: &'a [u8]) -> Result<(&'a [u8], Option<&'a [u8]>)> {
    let err = |reason: String| ctx.err("glb", reason);
    if bytes.len() < 20 {
        return Err(err(format!(
            "{} bytes is shorter than a GLB header and chunk header",
            bytes.len()
        )));
    }
    let version = u32_at(bytes, 4);
    if version != 2 {
        return Err(err(format!("version {version}, expected 2")));
    }
    let length = u32_at(bytes, 8) as usize;
    if length < 20 || length > bytes.len() {
        return Err(err(format!(
            "header length {length} does not fit the {}-byte file",
            bytes.len()
        )));
    }
    let mut rest = &bytes[12..length];
    let mut chunk = |what: &str| -> Result<Option<(&'a [u8], [u8; 4])>> {
        if rest.is_empty() {
            return Ok(None);
        }
        if rest.len() < 8 {
            return Err(err(format!("{what} chunk header is truncated")));
        }
        let len = u32_at(rest, 0) as usize;
        let kind = [rest[4], rest[5], rest[6], rest[7]];
        if len > rest.len() - 8 {
            return Err(err(format!(
                "{what} chunk claims {len} bytes, {} are left",
                rest.len() - 8
            )));
        }
        let data = &rest[8..8 + len];
        rest = &rest[8 + len..];
        Ok(Some((data, kind)))
    };
    let json = match chunk("first")? {
        Some((data, kind)) if &kind == b"JSON" => data,
        _ => return Err(err("the first chunk is not JSON".into())),
    };
    let bin = match chunk("second")? {
        Some((data, kind)) if &kind == b"BIN\0" => Some(data),
        _ => None, // unknown chunks are ignored (glTF 2.0 §4.4.3)
    };
    Ok((json, bin))
}

/// The bytes of a `data:[<media type>];base64,<data>` URI.
fn data_uri(uri: &str) -> std::result::Result<Vec<u8>, String> {
    let (head, payload) = uri.split_once(',').ok_or("data URI without a comma before its data")?;
    if !head.ends_with(";base64") {
        return Err("only base64 data URIs are supported".into());
    }
    // A decoded buffer is at most 3/4 of its text, which is part of the file already read.
    let limit = BUFFER_BYTES.get();
    if payload.len() as u64 / 4 * 3 > limit {
        return Err(format!(
            "data URI decodes to more than {limit} bytes{}",
            BUFFER_BYTES.hint()
        ));
    }
    const LENIENT: GeneralPurpose = GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        GeneralPurposeConfig::new().with_decode_padding_mode(DecodePaddingMode::Indifferent),
    );
    LENIENT
        .decode(payload)
        .map_err(|e| format!("data URI is not valid base64: {e}"))
}

/// Percent-decode a URI reference; invalid escapes and non-UTF-8 results are errors.
pub(super) fn percent_decode(uri: &str) -> std::result::Result<String, String> {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = b
                .get(i + 1..i + 3)
                .and_then(|h| std::str::from_utf8(h).ok())
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(|| format!("invalid percent escape at byte {i} of uri {uri:?}"))?;
            out.push(hex);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).map_err(|_| format!("uri {uri:?} decodes to bytes that are not UTF-8"))
}

/// The first `declared` bytes of the regular file that relative URI `uri` names inside the allowed folder.
fn external_file(ctx: Ctx, field: &str, uri: &str, declared: usize, external: &ExternalBuffers) -> Result<Vec<u8>> {
    let err = |reason: String| ctx.err(field, reason);
    let folder = match external {
        ExternalBuffers::Folder(f) => f,
        ExternalBuffers::Refuse => {
            return Err(err(format!("uri {uri:?}: external buffers are not read here")));
        }
    };
    let rel = percent_decode(uri).map_err(err)?;
    let scheme = rel.split(['/', '\\']).next().is_some_and(|first| first.contains(':'));
    let rel_path = Path::new(&rel);
    if rel.is_empty()
        || scheme
        || rel.contains('\\')
        || rel_path
            .components()
            .any(|c| !matches!(c, Component::Normal(_) | Component::CurDir))
    {
        return Err(err(format!(
            "uri {uri:?} is not a relative path inside the glTF file's folder (no scheme, absolute path or `..`)"
        )));
    }
    let canon_folder = folder
        .canonicalize()
        .map_err(|e| err(format!("folder {}: {e}", folder.display())))?;
    let path = folder.join(rel_path);
    let canon = path
        .canonicalize()
        .map_err(|e| err(format!("uri {uri:?} ({}): {e}", path.display())))?;
    if !canon.starts_with(&canon_folder) {
        return Err(err(format!(
            "uri {uri:?} resolves to {}, outside the glTF file's folder",
            canon.display()
        )));
    }
    let meta = std::fs::metadata(&canon).map_err(|e| err(format!("{}: {e}", canon.display())))?;
    if !meta.is_file() {
        return Err(err(format!(
            "uri {uri:?} names {}, which is not a regular file",
            canon.display()
        )));
    }
    if meta.len() < declared as u64 {
        return Err(err(format!(
            "{} has {} bytes, byteLength says {declared}",
            canon.display(),
            meta.len()
        )));
    }
    let file = std::fs::File::open(&canon).map_err(|e| err(format!("{}: {e}", canon.display())))?;
    let mut data = Vec::with_capacity(declared);
    file.take(declared as u64)
        .read_to_end(&mut data)
        .map_err(|e| err(format!("{}: {e}", canon.display())))?;
    Ok(data)
}

/// `asset.extras.caption` from the raw JSON (the gltf crate drops extras).
fn caption_of(json: &[u8]) -> Option<String> {
    #[derive(serde::Deserialize)]
    struct Top {
        asset: Asset,
    }
    #[derive(serde::Deserialize)]
    struct Asset {
        extras: Option<Extras>,
    }
    #[derive(serde::Deserialize)]
    struct Extras {
        caption: Option<serde_json::Value>,
    }
    let top: Top = serde_json::from_slice(json).ok()?;
    top.asset.extras?.caption?.as_str().map(str::to_string)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percent_decoding_refuses_bad_escapes() {
        assert_eq!(percent_decode("a%20b.bin").unwrap(), "a b.bin");
        assert!(percent_decode("%ff").unwrap_err().contains("not UTF-8"));
        assert!(percent_decode("x%2").unwrap_err().contains("invalid percent escape"));
        assert!(percent_decode("x%zz").unwrap_err().contains("invalid percent escape"));
    }

    #[test]
    fn data_uris_decode_base64_only() {
        assert_eq!(
            data_uri("data:application/octet-stream;base64,AAEC").unwrap(),
            vec![0, 1, 2]
        );
        assert_eq!(data_uri("data:;base64,AAE").unwrap(), vec![0, 1]);
        assert!(data_uri("data:text/plain,hello").unwrap_err().contains("base64"));
        assert!(data_uri("data:;base64,@@@@").unwrap_err().contains("not valid base64"));
        assert!(data_uri("data:;base64").unwrap_err().contains("comma"));
    }
}

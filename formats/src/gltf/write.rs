//! The glTF / GLB writer: frame 0 as the base mesh, one morph target per frame and a STEP weights animation.

use std::path::Path;

use serde_json::json;

use crate::clip::Clip;
use crate::error::{DataError, Result};
use crate::io::write_atomic;

/// Most frames [`write_gltf`] writes: its weights animation holds frames² floats (64 MiB at 4096 frames), which is
/// also what the reader's [`super::MAX_ACCESSOR_VALUES`] accepts back.
pub const MAX_WRITE_FRAMES: usize = 4096;

/// Write `clip` as `.gltf` (embedded base64 buffer) or `.glb` (by extension): the frame-0 mesh as base, one morph
/// target per frame (`frame_f − frame_0`) and a STEP weights animation whose key `f` at `f / fps` seconds is the
/// one-hot vector of target `f`, so frame `f` shows exactly target `f`. The caption goes to `asset.extras.caption`.
///
/// The weights animation holds frames² numbers, so at most [`MAX_WRITE_FRAMES`] frames are written.
pub fn write_gltf(path: &Path, clip: &Clip, fps: f32) -> Result<()> {
    if !(fps.is_finite() && fps > 0.0) {
        return Err(DataError::new(
            path,
            "fps",
            format!("{fps} is not a positive frame rate"),
        ));
    }
    clip.validate()?;
    if clip.frames > MAX_WRITE_FRAMES {
        return Err(DataError::new(
            path,
            "frames",
            format!(
                "{} frames: a glTF clip stores one morph target per frame and a weights animation of frames² \
                 numbers, so at most {MAX_WRITE_FRAMES} frames are written (cut the clip into windows)",
                clip.frames
            ),
        ));
    }
    let binary = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    let t = clip.frames;
    let mut buf: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut push = |bytes: Vec<u8>, accessor: serde_json::Value| -> usize {
        views.push(json!({"buffer": 0, "byteOffset": buf.len(), "byteLength": bytes.len()}));
        buf.extend(bytes);
        while !buf.len().is_multiple_of(4) {
            buf.push(0);
        }
        let mut a = accessor;
        a["bufferView"] = json!(views.len() - 1);
        accessors.push(a);
        accessors.len() - 1
    };
    let vec3 = |rows: &[[f32; 3]]| {
        let lo: Vec<f32> = (0..3)
            .map(|c| rows.iter().map(|r| r[c]).fold(f32::INFINITY, f32::min))
            .collect();
        let hi: Vec<f32> = (0..3)
            .map(|c| rows.iter().map(|r| r[c]).fold(f32::NEG_INFINITY, f32::max))
            .collect();
        let bytes = rows.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        (
            bytes,
            json!({"componentType": 5126, "count": rows.len(), "type": "VEC3", "min": lo, "max": hi}),
        )
    };
    let (b, a) = vec3(clip.frame(0));
    let position = push(b, a);
    let idx: Vec<u8> = clip.faces.iter().flatten().flat_map(|i| i.to_le_bytes()).collect();
    let indices = push(
        idx,
        json!({"componentType": 5125, "count": clip.faces.len() * 3, "type": "SCALAR"}),
    );
    let mut targets = Vec::with_capacity(t);
    for f in 0..t {
        let d: Vec<[f32; 3]> = clip
            .frame(f)
            .iter()
            .zip(clip.frame(0))
            .map(|(p, q)| [p[0] - q[0], p[1] - q[1], p[2] - q[2]])
            .collect();
        let (b, a) = vec3(&d);
        targets.push(json!({"POSITION": push(b, a)}));
    }
    let times: Vec<f32> = (0..t).map(|f| f as f32 / fps).collect();
    let times_acc = push(
        times.iter().flat_map(|x| x.to_le_bytes()).collect(),
        json!({"componentType": 5126, "count": t, "type": "SCALAR", "min": [times[0]], "max": [times[t - 1]]}),
    );
    let onehot: Vec<u8> = (0..t * t)
        .flat_map(|i| if i / t == i % t { 1.0f32 } else { 0.0 }.to_le_bytes())
        .collect();
    let weights_acc = push(onehot, json!({"componentType": 5126, "count": t * t, "type": "SCALAR"}));
    let mut buffer = json!({"byteLength": buf.len()});
    if !binary {
        buffer["uri"] = json!(format!("data:application/octet-stream;base64,{}", base64(&buf)));
    }
    let names: Vec<String> = (0..t).map(|f| format!("frame_{f:04}")).collect();
    let doc = json!({
        "asset": {"version": "2.0", "generator": "any4d", "extras": {"caption": clip.caption, "id": clip.id}},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": clip.id}],
        "meshes": [{
            "name": clip.id,
            "primitives": [{"attributes": {"POSITION": position}, "indices": indices, "mode": 4, "targets": targets}],
            "weights": vec![0.0; t],
            "extras": {"targetNames": names},
        }],
        "animations": [{
            "name": "frames",
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
            "samplers": [{"input": times_acc, "output": weights_acc, "interpolation": "STEP"}],
        }],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [buffer],
    });
    let text = serde_json::to_vec(&doc).map_err(|e| DataError::new(path, "gltf", e.to_string()))?;
    let bytes = if binary {
        glb(text, buf).map_err(|reason| DataError::new(path, "glb", reason))?
    } else {
        text
    };
    write_atomic(path, &bytes)
}

/// GLB container: 12-byte header, JSON chunk (space-padded), BIN chunk (zero-padded).
fn glb(mut json: Vec<u8>, mut bin: Vec<u8>) -> std::result::Result<Vec<u8>, String> {
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    if u32::try_from(total).is_err() {
        return Err(format!("{total} bytes do not fit a GLB file (at most 4 GiB)"));
    }
    let mut out = Vec::with_capacity(total);
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    Ok(out)
}

/// Standard base64 with padding.
fn base64(data: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(data.len().div_ceil(3) * 4);
    for c in data.chunks(3) {
        let w = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(w >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
        ];
        for (raw, enc) in cases {
            assert_eq!(base64(raw.as_bytes()), enc);
        }
    }
}

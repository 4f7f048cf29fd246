//! DyMesh `.bin` clips (docs/method.md §2.1): a pickled dict `{vertices: (T, N, 3), faces: (M, 3), caption: str}`.
//!
//! Reading goes through the restricted unpickler in [`super::pickle`]; nothing in the file is executed.
//! A missing caption becomes a single space " " (AAM loader); the empty string stays empty (unconditional).

use std::path::Path;

use super::pickle::{self, ArrayData, DType, NdArray, Value};
use crate::clip::Clip;
use crate::error::{DataError, Result};

/// Caption used when the file has none (docs/method.md §2.1, AAM code).
pub const MISSING_CAPTION: &str = " ";

/// Read a DyMesh `.bin` clip. The id is the file stem.
pub fn read_bin(path: &Path) -> Result<Clip> {
    let bytes = super::read_clip_file(path)?;
    read_bin_bytes(&bytes, &path.display().to_string())
}

/// Read a DyMesh pickle from memory; `source` is the path reported in errors and stored in [`Clip::source`].
pub fn read_bin_bytes(bytes: &[u8], source: &str) -> Result<Clip> {
    let value = pickle::loads(bytes, source)?;
    let err = |field: &str, reason: String| DataError::new(source, field, reason);
    if !matches!(value, Value::Dict(_)) {
        return Err(err(
            "pickle",
            format!("top-level object is a {}, expected a dict", value.kind()),
        ));
    }

    let v = array(&value, "vertices", source)?;
    let [frames, n_vertices, 3] = v.shape[..] else {
        return Err(err(
            "vertices",
            format!("shape {:?}, expected (frames, vertices, 3)", v.shape),
        ));
    };
    if frames == 0 {
        return Err(err("vertices", "zero frames".into()));
    }
    let (max_frames, max_rows) = (
        crate::limits::FRAMES.get_usize(),
        crate::limits::CLIP_VERTICES.get_usize(),
    );
    if frames > max_frames {
        let hint = crate::limits::FRAMES.hint();
        return Err(err(
            "vertices",
            format!("{frames} frames, more than the limit of {max_frames}{hint}"),
        ));
    }
    if frames.saturating_mul(n_vertices) > max_rows {
        let hint = crate::limits::CLIP_VERTICES.hint();
        return Err(err(
            "vertices",
            format!("{frames} × {n_vertices} vertex rows, more than the limit of {max_rows}{hint}"),
        ));
    }
    let coords: Vec<f32> = match &v.data {
        ArrayData::Float(x) => x.iter().map(|&c| c as f32).collect(),
        ArrayData::Int(x) if v.dtype != DType::Bool => x.iter().map(|&c| c as f32).collect(),
        ArrayData::Int(_) => return Err(err("vertices", "dtype bool, expected numbers".into())),
    };
    let vertices = coords.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();

    let f = array(&value, "faces", source)?;
    let [_, 3] = f.shape[..] else {
        return Err(err("faces", format!("shape {:?}, expected (faces, 3)", f.shape)));
    };
    let ArrayData::Int(idx) = &f.data else {
        return Err(err("faces", format!("dtype {}, expected integers", f.dtype.descr())));
    };
    let idx = idx
        .iter()
        .enumerate()
        .map(|(i, &x)| {
            u32::try_from(x).map_err(|_| err("faces", format!("index {x} in face {} is not a vertex index", i / 3)))
        })
        .collect::<Result<Vec<u32>>>()?;
    let faces = idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();

    let caption = match value.get("caption") {
        None => MISSING_CAPTION.to_string(),
        Some(Value::Str(s)) => s.clone(),
        Some(Value::Bytes(b)) => {
            String::from_utf8(b.clone()).map_err(|e| err("caption", format!("bytes are not valid UTF-8: {e}")))?
        }
        Some(other) => {
            return Err(err("caption", format!("is a {}, expected str", other.kind())));
        }
    };

    let id = Path::new(source)
        .file_stem()
        .map_or_else(|| source.to_string(), |s| s.to_string_lossy().into_owned());
    Clip::new(id, vertices, frames, n_vertices, faces, caption, source)
}

fn array<'a>(dict: &'a Value, key: &str, source: &str) -> Result<&'a NdArray> {
    match dict.get(key) {
        Some(Value::NdArray(a)) => Ok(a),
        Some(other) => Err(DataError::new(
            source,
            key,
            format!("is a {}, expected a numpy array", other.kind()),
        )),
        None => Err(DataError::new(source, key, "missing key")),
    }
}

/// The pickle bytes of `clip`: float32 vertices (T, N, 3), int64 faces (M, 3), str caption.
pub fn bin_bytes(clip: &Clip) -> Result<Vec<u8>> {
    let vertices = NdArray {
        shape: vec![clip.frames, clip.n_vertices, 3],
        dtype: DType::F4,
        data: ArrayData::Float(clip.vertices.iter().flatten().map(|&c| c as f64).collect()),
    };
    let faces = NdArray {
        shape: vec![clip.faces.len(), 3],
        dtype: DType::I8,
        data: ArrayData::Int(clip.faces.iter().flatten().map(|&i| i as i64).collect()),
    };
    let dict = Value::Dict(vec![
        (Value::Str("vertices".into()), Value::NdArray(vertices)),
        (Value::Str("faces".into()), Value::NdArray(faces)),
        (Value::Str("caption".into()), Value::Str(clip.caption.clone())),
    ]);
    pickle::dumps(&dict)
}

/// Write `clip` as a DyMesh `.bin` that Python's `pickle.load` reads into numpy arrays. Atomic (temp + rename).
pub fn write_bin(path: &Path, clip: &Clip) -> Result<()> {
    clip.validate()?;
    let bytes = bin_bytes(clip).map_err(|e| e.at(path))?;
    crate::io::write_atomic(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clip() -> Clip {
        let v = (0..2)
            .flat_map(|f| [[0.1, 0.0, f as f32], [1.0, 0.3, 0.0], [0.0, 1.0, -2.5]])
            .collect();
        Clip::new("c", v, 2, 3, vec![[0, 1, 2]], "a caption", "c.bin").unwrap()
    }

    #[test]
    fn bytes_round_trip_exactly() {
        let c = clip();
        let back = read_bin_bytes(&bin_bytes(&c).unwrap(), "dir/c.bin").unwrap();
        assert_eq!(
            (back.vertices, back.faces, back.caption),
            (c.vertices, c.faces, c.caption)
        );
        assert_eq!(back.id, "c");
    }

    #[test]
    fn bad_dicts_name_the_field() {
        let dict = |items: Vec<(&str, Value)>| {
            Value::Dict(items.into_iter().map(|(k, v)| (Value::Str(k.into()), v)).collect())
        };
        let v3 = Value::NdArray(NdArray {
            shape: vec![2, 3, 3],
            dtype: DType::F8,
            data: ArrayData::Float(vec![0.0; 18]),
        });
        let faces = |d: Vec<i64>| {
            Value::NdArray(NdArray {
                shape: vec![d.len() / 3, 3],
                dtype: DType::I8,
                data: ArrayData::Int(d),
            })
        };
        let read = |v: Value| read_bin_bytes(&pickle::dumps(&v).unwrap(), "x.bin").unwrap_err();
        assert_eq!(read(dict(vec![("faces", faces(vec![0, 1, 2]))])).field, "vertices");
        assert_eq!(read(dict(vec![("vertices", v3.clone())])).field, "faces");
        let e = read(dict(vec![("vertices", v3.clone()), ("faces", faces(vec![0, -1, 2]))]));
        assert!(e.field == "faces" && e.reason.contains("-1"), "{e}");
        let e = read(dict(vec![
            ("vertices", v3),
            ("faces", faces(vec![0, 1, 2])),
            ("caption", Value::Bytes(vec![0xff])),
        ]));
        assert_eq!((e.path.as_str(), e.field.as_str()), ("x.bin", "caption"));
    }
}

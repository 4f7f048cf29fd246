//! The pickle writer: protocol 4 that Python's `pickle.load` reads back into real numpy arrays.

use super::{ArrayData, DType, NdArray, Value};
use crate::error::{DataError, Result};

/// Encode `value` as a protocol-4 pickle that Python's `pickle.load` reads back into real numpy arrays
/// (arrays use numpy's own `_reconstruct` + BUILD path). float16 arrays are not written.
pub fn dumps(value: &Value) -> Result<Vec<u8>> {
    let mut out = vec![0x80, 4];
    write_value(&mut out, value)?;
    out.push(b'.');
    Ok(out)
}

fn write_str(out: &mut Vec<u8>, s: &str) {
    if s.len() < 256 {
        out.push(0x8c);
        out.push(s.len() as u8);
    } else {
        out.push(0x8d);
        out.extend((s.len() as u64).to_le_bytes());
    }
    out.extend(s.as_bytes());
}

fn write_bytes(out: &mut Vec<u8>, b: &[u8]) {
    if b.len() < 256 {
        out.push(b'C');
        out.push(b.len() as u8);
    } else {
        out.push(0x8e);
        out.extend((b.len() as u64).to_le_bytes());
    }
    out.extend(b);
}

fn write_int(out: &mut Vec<u8>, i: i64) {
    if (0..256).contains(&i) {
        out.extend([b'K', i as u8]);
    } else if let Ok(v) = i32::try_from(i) {
        out.push(b'J');
        out.extend(v.to_le_bytes());
    } else {
        out.extend([0x8a, 8]);
        out.extend(i.to_le_bytes());
    }
}

fn write_value(out: &mut Vec<u8>, value: &Value) -> Result<()> {
    match value {
        Value::None => out.push(b'N'),
        Value::Bool(b) => out.push(if *b { 0x88 } else { 0x89 }),
        Value::Int(i) => write_int(out, *i),
        Value::Float(f) => {
            out.push(b'G');
            out.extend(f.to_be_bytes());
        }
        Value::Str(s) => write_str(out, s),
        Value::Bytes(b) => write_bytes(out, b),
        Value::List(items) => {
            out.extend([b']', b'(']);
            for v in items {
                write_value(out, v)?;
            }
            out.push(b'e');
        }
        Value::Tuple(items) => {
            out.push(b'(');
            for v in items {
                write_value(out, v)?;
            }
            out.push(b't');
        }
        Value::Dict(items) => {
            out.extend([b'}', b'(']);
            for (k, v) in items {
                write_value(out, k)?;
                write_value(out, v)?;
            }
            out.push(b'u');
        }
        Value::NdArray(a) => write_array(out, a)?,
    }
    Ok(())
}

fn write_array(out: &mut Vec<u8>, a: &NdArray) -> Result<()> {
    let count: usize = a.shape.iter().product();
    if count != a.data.len() {
        return Err(DataError::new(
            "pickle",
            "ndarray",
            format!("shape {:?} but {} elements", a.shape, a.data.len()),
        ));
    }
    let raw = encode_elements(a)?;
    // _reconstruct(ndarray, (0,), b'b')
    out.extend(b"cnumpy.core.multiarray\n_reconstruct\ncnumpy\nndarray\n");
    out.extend([b'K', 0, 0x85, b'C', 1, b'b', 0x87, b'R']);
    // BUILD state: (1, shape, dtype, is_fortran=False, raw)
    out.extend([b'(', b'K', 1, b'(']);
    for &d in &a.shape {
        write_int(out, d as i64);
    }
    out.push(b't');
    out.extend(b"cnumpy\ndtype\n");
    write_str(out, a.dtype.descr());
    out.extend([0x89, 0x88, 0x87, b'R']);
    // dtype state: (3, byteorder, None, None, None, -1, -1, 0)
    out.extend([b'(', b'K', 3]);
    write_str(out, if a.dtype.item_size() == 1 { "|" } else { "<" });
    out.extend([b'N', b'N', b'N']);
    write_int(out, -1);
    write_int(out, -1);
    write_int(out, 0);
    out.extend([b't', b'b', 0x89]);
    write_bytes(out, &raw);
    out.extend([b't', b'b']);
    Ok(())
}

fn encode_elements(a: &NdArray) -> Result<Vec<u8>> {
    let mut raw = Vec::with_capacity(a.data.len() * a.dtype.item_size());
    let mismatch = || {
        DataError::new(
            "pickle",
            "ndarray",
            format!("dtype {} does not match the element kind", a.dtype.descr()),
        )
    };
    match (&a.data, a.dtype) {
        (ArrayData::Float(v), DType::F4) => v.iter().for_each(|&x| raw.extend((x as f32).to_le_bytes())),
        (ArrayData::Float(v), DType::F8) => v.iter().for_each(|&x| raw.extend(x.to_le_bytes())),
        (ArrayData::Float(_), _) => return Err(mismatch()),
        (ArrayData::Int(_), d) if d.is_float() => return Err(mismatch()),
        (ArrayData::Int(v), d) => {
            let size = d.item_size();
            for &x in v {
                raw.extend(&x.to_le_bytes()[..size]);
            }
        }
    }
    Ok(raw)
}

//! numpy's pickled objects as data: the calls of the allowed globals (`_reconstruct`, `dtype`, `_frombuffer`,
//! `_codecs.encode`), BUILD of arrays and dtypes, and the decoding of raw array bytes.

use std::rc::Rc;

use super::item::{Global, Item, Step};
use super::{ArrayData, ByteOrder, DType, NdArray};

fn shape_of(item: &Item) -> Step<Vec<usize>> {
    let Item::Tuple(dims) = item else {
        return Err(format!("array shape is a {}, not a tuple", item.kind()));
    };
    dims.iter()
        .map(|d| match d {
            Item::Int(n) if *n >= 0 => Ok(*n as usize),
            other => Err(format!("array dimension {other:?} is not a non-negative int")),
        })
        .collect()
}

/// Interpret a call of an allowed global as data. Nothing is executed.
pub(super) fn call(g: Global, args: Vec<Item>) -> Step<Item> {
    match (g, args.as_slice()) {
        (Global::Reconstruct, [Item::Global(Global::NdArrayType), _, _]) => Ok(Item::EmptyArray),
        (Global::DTypeType, [Item::Str(descr), ..]) => {
            let (dtype, order) = DType::parse(descr).ok_or(format!("unsupported dtype `{descr}`"))?;
            Ok(Item::DTypeObj(dtype, order))
        }
        (Global::CodecsEncode, [Item::Str(s), Item::Str(enc)]) => {
            if !matches!(enc.to_ascii_lowercase().as_str(), "latin1" | "latin-1" | "iso-8859-1") {
                return Err(format!("_codecs.encode with encoding `{enc}`; only latin1 is data"));
            }
            s.chars()
                .map(|c| u8::try_from(c as u32).map_err(|_| format!("_codecs.encode: {c:?} is not latin1")))
                .collect::<Step<Vec<u8>>>()
                .map(|b| Item::Bytes(Rc::new(b)))
        }
        (Global::FromBuffer, [Item::Bytes(buf), Item::DTypeObj(dtype, order), shape, Item::Str(o)]) => {
            let fortran = match o.as_str() {
                "C" => false,
                "F" => true,
                _ => return Err(format!("_frombuffer order `{o}`")),
            };
            decode_array(
                shape_of(shape)?,
                *dtype,
                order.unwrap_or(ByteOrder::native()),
                fortran,
                buf,
            )
            .map(|a| Item::Array(Rc::new(a)))
        }
        (g, args) => Err(format!(
            "unsupported call of {g:?} with arguments ({})",
            args.iter().map(Item::kind).collect::<Vec<_>>().join(", ")
        )),
    }
}

/// BUILD: numpy `__setstate__` of an array or a dtype.
pub(super) fn build(obj: Item, state: Item) -> Step<Item> {
    let Item::Tuple(state) = state else {
        return Err(format!("BUILD state is a {}, not a tuple", state.kind()));
    };
    match obj {
        Item::EmptyArray => {
            // (version, shape, dtype, is_fortran, raw data); numpy ≤ 1.x may omit the version.
            let s = if state.len() == 5 { &state[1..] } else { &state[..] };
            let [shape, Item::DTypeObj(dtype, order), Item::Bool(fortran), raw] = s else {
                return Err(format!(
                    "ndarray state of {} items is not (version, shape, dtype, fortran, data)",
                    state.len()
                ));
            };
            let Item::Bytes(raw) = raw else {
                return Err(format!(
                    "ndarray data is a {} (object arrays are not supported)",
                    raw.kind()
                ));
            };
            decode_array(
                shape_of(shape)?,
                *dtype,
                order.unwrap_or(ByteOrder::native()),
                *fortran,
                raw,
            )
            .map(|a| Item::Array(Rc::new(a)))
        }
        Item::DTypeObj(dtype, _) => {
            let order = match state.get(1) {
                Some(Item::Str(s)) if s.as_str() == "<" => Some(ByteOrder::Little),
                Some(Item::Str(s)) if s.as_str() == ">" => Some(ByteOrder::Big),
                Some(Item::Str(s)) if s.as_str() == "|" || s.as_str() == "=" => Some(ByteOrder::native()),
                other => return Err(format!("dtype state byte order {other:?}")),
            };
            if state.len() > 3 && !matches!(state[3], Item::None) {
                return Err("structured dtypes (with field names) are not supported".into());
            }
            Ok(Item::DTypeObj(dtype, order))
        }
        other => Err(format!("BUILD on a {} is not supported", other.kind())),
    }
}

/// Decode raw array bytes to C-order widened elements.
fn decode_array(shape: Vec<usize>, dtype: DType, order: ByteOrder, fortran: bool, raw: &[u8]) -> Step<NdArray> {
    let count = shape
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .ok_or("array shape overflows")?;
    let size = dtype.item_size();
    if count.checked_mul(size) != Some(raw.len()) {
        return Err(format!(
            "array of shape {shape:?} and dtype {} needs {} bytes, found {}",
            dtype.descr(),
            count.saturating_mul(size),
            raw.len()
        ));
    }
    let word = |chunk: &[u8]| -> u64 {
        let fold = |acc: u64, &x: &u8| (acc << 8) | x as u64;
        match order {
            ByteOrder::Little => chunk.iter().rev().fold(0, fold),
            ByteOrder::Big => chunk.iter().fold(0, fold),
        }
    };
    let chunks = raw.chunks_exact(size).map(word);
    let mut data = match dtype {
        DType::F2 => ArrayData::Float(chunks.map(|w| f16_to_f64(w as u16)).collect()),
        DType::F4 => ArrayData::Float(chunks.map(|w| f32::from_bits(w as u32) as f64).collect()),
        DType::F8 => ArrayData::Float(chunks.map(f64::from_bits).collect()),
        DType::I1 => ArrayData::Int(chunks.map(|w| w as u8 as i8 as i64).collect()),
        DType::I2 => ArrayData::Int(chunks.map(|w| w as u16 as i16 as i64).collect()),
        DType::I4 => ArrayData::Int(chunks.map(|w| w as u32 as i32 as i64).collect()),
        DType::I8 => ArrayData::Int(chunks.map(|w| w as i64).collect()),
        DType::U1 | DType::U2 | DType::U4 | DType::Bool => ArrayData::Int(chunks.map(|w| w as i64).collect()),
        DType::U8 => ArrayData::Int(
            chunks
                .map(|w| i64::try_from(w).map_err(|_| format!("u8 element {w} does not fit i64")))
                .collect::<Step<Vec<_>>>()?,
        ),
    };
    if fortran && shape.len() > 1 {
        data = match data {
            ArrayData::Float(v) => ArrayData::Float(fortran_to_c(&v, &shape)),
            ArrayData::Int(v) => ArrayData::Int(fortran_to_c(&v, &shape)),
        };
    }
    Ok(NdArray { shape, dtype, data })
}

/// Reorder column-major elements to row-major.
pub(super) fn fortran_to_c<T: Copy>(v: &[T], shape: &[usize]) -> Vec<T> {
    let mut index = vec![0usize; shape.len()];
    let mut out = Vec::with_capacity(v.len());
    for _ in 0..v.len() {
        let mut offset = 0;
        let mut stride = 1;
        for (i, d) in index.iter().zip(shape) {
            offset += i * stride;
            stride *= d;
        }
        out.push(v[offset]);
        for axis in (0..shape.len()).rev() {
            index[axis] += 1;
            if index[axis] < shape[axis] {
                break;
            }
            index[axis] = 0;
        }
    }
    out
}

/// IEEE half to f64 (exact).
pub(super) fn f16_to_f64(h: u16) -> f64 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = ((h >> 10) & 0x1f) as i32;
    let frac = (h & 0x3ff) as f64;
    sign * match exp {
        0 => frac * 2f64.powi(-24),
        31 if frac == 0.0 => f64::INFINITY,
        31 => f64::NAN,
        e => (1.0 + frac / 1024.0) * 2f64.powi(e - 15),
    }
}

//! Typed, bounds-checked accessor reads: every use states the element type and the component forms it accepts,
//! and every byte range (accessor, buffer view, sparse indices and values) is checked against its buffer first.

use gltf::json::accessor::{ComponentType, Type};
use gltf::json::validation::Checked;
use gltf::json::{self, Root};

use super::{Ctx, MAX_ACCESSOR_VALUES};
use crate::error::Result;

/// How an accessor's components may be stored for one use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Form {
    /// 32-bit float.
    Float,
    /// Integers mapped to [0, 1] or [−1, 1] (`normalized: true`).
    Normalized(ComponentType),
    /// Plain integers.
    Integer(ComponentType),
}

use ComponentType::{I8, I16, U8, U16, U32};

/// Positions, translations, scales, key times, inverse bind matrices.
pub(super) const FLOAT: &[Form] = &[Form::Float];
/// Rotations and morph weights.
pub(super) const FLOAT_OR_NORMALIZED: &[Form] = &[
    Form::Float,
    Form::Normalized(I8),
    Form::Normalized(U8),
    Form::Normalized(I16),
    Form::Normalized(U16),
];
/// Triangle indices.
pub(super) const INDICES: &[Form] = &[Form::Integer(U8), Form::Integer(U16), Form::Integer(U32)];
/// `JOINTS_n`.
pub(super) const JOINTS: &[Form] = &[Form::Integer(U8), Form::Integer(U16)];
/// `WEIGHTS_n`.
pub(super) const WEIGHTS: &[Form] = &[Form::Float, Form::Normalized(U8), Form::Normalized(U16)];

fn type_name(t: Type) -> &'static str {
    match t {
        Type::Scalar => "SCALAR",
        Type::Vec2 => "VEC2",
        Type::Vec3 => "VEC3",
        Type::Vec4 => "VEC4",
        Type::Mat2 => "MAT2",
        Type::Mat3 => "MAT3",
        Type::Mat4 => "MAT4",
    }
}

fn form_name(f: Form) -> String {
    let ct = |c: ComponentType| match c {
        I8 => "BYTE",
        U8 => "UNSIGNED_BYTE",
        I16 => "SHORT",
        U16 => "UNSIGNED_SHORT",
        U32 => "UNSIGNED_INT",
        ComponentType::F32 => "FLOAT",
    };
    match f {
        Form::Float => "FLOAT".into(),
        Form::Normalized(c) => format!("normalized {}", ct(c)),
        Form::Integer(c) => ct(c).into(),
    }
}

/// A component decoder: little-endian bytes of one component to its value.
fn component(form: Form) -> fn(&[u8]) -> f64 {
    match form {
        Form::Float => |b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        Form::Integer(I8) => |b| b[0] as i8 as f64,
        Form::Integer(U8) => |b| b[0] as f64,
        Form::Integer(I16) => |b| i16::from_le_bytes([b[0], b[1]]) as f64,
        Form::Integer(U16) => |b| u16::from_le_bytes([b[0], b[1]]) as f64,
        Form::Integer(_) => |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        // glTF 2.0 §3.11: signed c / (2^(n−1) − 1) clamped at −1, unsigned c / (2^n − 1).
        Form::Normalized(I8) => |b| (b[0] as i8 as f64 / 127.0).max(-1.0),
        Form::Normalized(U8) => |b| b[0] as f64 / 255.0,
        Form::Normalized(I16) => |b| (i16::from_le_bytes([b[0], b[1]]) as f64 / 32767.0).max(-1.0),
        Form::Normalized(_) => |b| u16::from_le_bytes([b[0], b[1]]) as f64 / 65535.0,
    }
}

fn size(form: Form) -> usize {
    match form {
        Form::Float => 4,
        Form::Normalized(c) | Form::Integer(c) => c.size(),
    }
}

/// The bytes `offset .. offset + len` of view `v`, checked against the view and its buffer.
fn view_bytes<'a>(
    ctx: Ctx,
    root: &Root,
    buffers: &'a [Vec<u8>],
    v: usize,
    offset: u64,
    len: u64,
    field: &str,
) -> Result<&'a [u8]> {
    let view = root
        .buffer_views
        .get(v)
        .ok_or_else(|| ctx.err(field, format!("buffer view {v} does not exist")))?;
    let b = view.buffer.value();
    let data = buffers
        .get(b)
        .ok_or_else(|| ctx.err(field, format!("buffer view {v} names buffer {b}, which does not exist")))?;
    let start = view.byte_offset.map_or(0, |o| o.0);
    let view_len = view.byte_length.0;
    if start.checked_add(view_len).is_none_or(|end| end > data.len() as u64) {
        return Err(ctx.err(
            field,
            format!(
                "buffer view {v} covers bytes {start}..{start}+{view_len} of buffer {b}, which has {} bytes",
                data.len()
            ),
        ));
    }
    if offset.checked_add(len).is_none_or(|end| end > view_len) {
        return Err(ctx.err(
            field,
            format!("needs bytes {offset}..{offset}+{len} of buffer view {v}, which has {view_len} bytes"),
        ));
    }
    let at = (start + offset) as usize;
    Ok(&data[at..at + len as usize])
}

/// Decode accessor `index` as `ty` elements whose components are stored in one of the `allowed` forms, flattened
/// (`count × components` numbers, normalised integers mapped to floats). `field` names the use in errors.
pub(super) fn read(
    ctx: Ctx,
    root: &Root,
    buffers: &[Vec<u8>],
    index: usize,
    field: &str,
    ty: Type,
    allowed: &[Form],
) -> Result<Vec<f64>> {
    let field = format!("{field} (accessors[{index}])");
    let field = field.as_str();
    let acc: &json::Accessor = root
        .accessors
        .get(index)
        .ok_or_else(|| ctx.err(field, "the accessor does not exist"))?;
    let Checked::Valid(acc_ty) = acc.type_ else {
        return Err(ctx.err(field, "invalid type"));
    };
    let Checked::Valid(json::accessor::GenericComponentType(ct)) = acc.component_type else {
        return Err(ctx.err(field, "invalid componentType"));
    };
    let form = match (ct, acc.normalized) {
        (ComponentType::F32, false) => Form::Float,
        (c, true) => Form::Normalized(c),
        (c, false) => Form::Integer(c),
    };
    if acc_ty != ty || !allowed.contains(&form) {
        return Err(ctx.err(
            field,
            format!(
                "is {} of {}, expected {} of {}",
                type_name(acc_ty),
                form_name(form),
                type_name(ty),
                allowed.iter().map(|&f| form_name(f)).collect::<Vec<_>>().join(" or ")
            ),
        ));
    }
    let comps = ty.multiplicity();
    let count = acc.count.0;
    let values = usize::try_from(count)
        .ok()
        .and_then(|c| c.checked_mul(comps))
        .filter(|&v| v <= MAX_ACCESSOR_VALUES)
        .ok_or_else(|| {
            ctx.err(
                field,
                format!("count {count} × {comps} components is more than {MAX_ACCESSOR_VALUES} numbers"),
            )
        })?;
    let count = count as usize;
    let csize = size(form);
    let elem = comps * csize; // no column padding: every allowed matrix form has 4-byte components
    let decode = component(form);
    let mut out = Vec::with_capacity(values);
    match acc.buffer_view {
        None => out.resize(values, 0.0),
        Some(v) => {
            let stride = root
                .buffer_views
                .get(v.value())
                .and_then(|view| view.byte_stride)
                .map_or(elem, |s| s.0);
            if stride < elem {
                return Err(ctx.err(
                    field,
                    format!(
                        "byteStride {stride} is smaller than one {} element ({elem} bytes)",
                        type_name(ty)
                    ),
                ));
            }
            let offset = acc.byte_offset.map_or(0, |o| o.0);
            let span = if count == 0 {
                0
            } else {
                ((count - 1) as u64) * stride as u64 + elem as u64
            };
            let bytes = view_bytes(ctx, root, buffers, v.value(), offset, span, field)?;
            for i in 0..count {
                let e = &bytes[i * stride..i * stride + elem];
                out.extend(e.chunks_exact(csize).map(decode));
            }
        }
    }
    if let Some(sparse) = &acc.sparse {
        let n = sparse.count.0;
        if n == 0 || n > count as u64 {
            return Err(ctx.err(field, format!("sparse count {n} is not in 1..={count}")));
        }
        let n = n as usize;
        let Checked::Valid(json::accessor::IndexComponentType(ict)) = sparse.indices.component_type else {
            return Err(ctx.err(field, "sparse indices have an invalid componentType"));
        };
        let iform = Form::Integer(ict);
        if !INDICES.contains(&iform) {
            return Err(ctx.err(
                field,
                format!(
                    "sparse indices are {}, expected an unsigned integer type",
                    form_name(iform)
                ),
            ));
        }
        let isize = size(iform);
        let ibytes = view_bytes(
            ctx,
            root,
            buffers,
            sparse.indices.buffer_view.value(),
            sparse.indices.byte_offset.0,
            (n * isize) as u64,
            &format!("{field} sparse indices"),
        )?;
        let vbytes = view_bytes(
            ctx,
            root,
            buffers,
            sparse.values.buffer_view.value(),
            sparse.values.byte_offset.0,
            (n * elem) as u64,
            &format!("{field} sparse values"),
        )?;
        let idecode = component(iform);
        let mut previous = None;
        for (k, (ib, vb)) in ibytes.chunks_exact(isize).zip(vbytes.chunks_exact(elem)).enumerate() {
            let i = idecode(ib) as usize;
            if i >= count || previous.is_some_and(|p| p >= i) {
                return Err(ctx.err(
                    field,
                    format!("sparse index {k} is {i}: indices must increase and stay below the count {count}"),
                ));
            }
            previous = Some(i);
            for (c, cb) in vb.chunks_exact(csize).enumerate() {
                out[i * comps + c] = decode(cb);
            }
        }
    }
    Ok(out)
}

/// [`read`] for integer uses (indices, joints): every value as u32.
pub(super) fn read_u32(
    ctx: Ctx,
    root: &Root,
    buffers: &[Vec<u8>],
    index: usize,
    field: &str,
    ty: Type,
    allowed: &[Form],
) -> Result<Vec<u32>> {
    // Integer forms decode exactly (at most u32) to f64.
    Ok(read(ctx, root, buffers, index, field, ty, allowed)?
        .into_iter()
        .map(|x| x as u32)
        .collect())
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    fn root(accessors: &str) -> Root {
        let json = format!(
            r#"{{"asset": {{"version": "2.0"}}, "buffers": [{{"byteLength": 24}}],
               "bufferViews": [{{"buffer": 0, "byteLength": 12}}, {{"buffer": 0, "byteOffset": 12, "byteLength": 2}},
                               {{"buffer": 0, "byteOffset": 16, "byteLength": 8}}],
               "accessors": [{accessors}]}}"#
        );
        gltf::json::deserialize::from_str(&json).unwrap()
    }

    fn buffer() -> Vec<Vec<u8>> {
        let mut b: Vec<u8> = [1.0f32, 2.0, 3.0].iter().flat_map(|x| x.to_le_bytes()).collect();
        b.extend([2, 0, 0, 0]); // sparse indices (u8): 2, 0
        b.extend(9.0f32.to_le_bytes());
        b.extend(7.0f32.to_le_bytes());
        vec![b]
    }

    fn read1(root: &Root, ty: Type, allowed: &[Form]) -> Result<Vec<f64>> {
        read(
            Ctx {
                path: Path::new("t.gltf"),
            },
            root,
            &buffer(),
            0,
            "x",
            ty,
            allowed,
        )
    }

    #[test]
    fn sparse_values_replace_the_base() {
        let sparse = r#""sparse": {"count": 2, "indices": {"bufferView": 1, "componentType": 5121},
                                  "values": {"bufferView": 2}}"#;
        let r = root(&format!(
            r#"{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "SCALAR", {sparse}}}"#
        ));
        // Indices 2, 0 are not increasing: refused.
        let e = read1(&r, Type::Scalar, FLOAT).unwrap_err();
        assert!(e.reason.contains("must increase"), "{e}");
        // Without a buffer view the base is zeros; one sparse value at index 2.
        let r = root(&format!(
            r#"{{"componentType": 5126, "count": 3, "type": "SCALAR", {}}}"#,
            sparse.replace(r#""count": 2"#, r#""count": 1"#)
        ));
        assert_eq!(read1(&r, Type::Scalar, FLOAT).unwrap(), vec![0.0, 0.0, 9.0]);
    }

    #[test]
    fn normalized_integers_map_to_unit_range_and_types_must_match() {
        // The first bytes of the buffer as normalised u8 (0x00 0x00 0x80 0x3f = 1.0f32) and as i8.
        let r = root(r#"{"bufferView": 0, "componentType": 5121, "normalized": true, "count": 4, "type": "SCALAR"}"#);
        assert_eq!(
            read1(&r, Type::Scalar, WEIGHTS).unwrap(),
            vec![0.0, 0.0, 128.0 / 255.0, 63.0 / 255.0]
        );
        let r = root(r#"{"bufferView": 0, "componentType": 5120, "normalized": true, "count": 4, "type": "SCALAR"}"#);
        assert_eq!(read1(&r, Type::Scalar, FLOAT_OR_NORMALIZED).unwrap()[2], -1.0);
        let e = read1(&r, Type::Scalar, WEIGHTS).unwrap_err();
        assert!(e.reason.contains("is SCALAR of normalized BYTE"), "{e}");
        let e = read1(&r, Type::Vec3, FLOAT_OR_NORMALIZED).unwrap_err();
        assert!(e.reason.contains("expected VEC3"), "{e}");
        // 4 elements of 4 bytes do not fit a 12-byte view.
        let r = root(r#"{"bufferView": 0, "componentType": 5126, "count": 4, "type": "SCALAR"}"#);
        let e = read1(&r, Type::Scalar, FLOAT).unwrap_err();
        assert!(e.reason.contains("which has 12 bytes"), "{e}");
    }
}

//! The binary FBX container (FBX 7.x): a tree of named nodes, each with a list of typed properties.
//!
//! After the 27-byte header (`Kaydara FBX Binary  \0`, `1A 00`, a u32 version) come node records: the absolute
//! offset where the record ends, its property count and property bytes (u32 each before version 7500, u64 from
//! 7500 on), a one-byte name length and the name, the properties, then the children, closed by an all-zero
//! record. A property is one type byte and its value: `Y` i16, `C` bool, `I` i32, `F` f32, `D` f64, `L` i64,
//! `S` string and `R` raw bytes (u32 length first), and the arrays `f d l i b c` (u32 element count, u32 encoding —
//! 0 raw, 1 zlib — and u32 stored byte count).
//!
//! Every offset and length is checked against the record that holds it before it is used; a compressed array
//! inflates to exactly its declared size, and the declared sizes of all arrays together may not exceed
//! [`INFLATE_RATIO`] × the file's length, so memory stays bounded by the file's size.

use std::io::Read as _;

use crate::bytes::Bytes;
use crate::error::{DataError, Result};

/// The first 23 bytes of every binary FBX file.
pub const MAGIC: &[u8; 23] = b"Kaydara FBX Binary  \0\x1a\0";

/// Oldest version read: FBX 7.0 (2010). Version 6 files keep their animation in a different layout.
pub const MIN_VERSION: u32 = 7000;

/// Most bytes all arrays of a file may inflate to, per byte of the file (real files compress 2–10×).
pub const INFLATE_RATIO: u64 = 64;

/// Deepest node nesting read (real files nest about 5 deep).
pub const MAX_DEPTH: usize = 64;

/// A property value.
#[derive(Debug, Clone, PartialEq)]
pub enum Prop {
    Int(i64),
    Float(f64),
    Str(String),
    Raw(Vec<u8>),
    Ints(Vec<i64>),
    Floats(Vec<f64>),
}

impl Prop {
    pub fn int(&self) -> Option<i64> {
        match self {
            Prop::Int(v) => Some(*v),
            _ => None,
        }
    }

    /// A number of either kind as f64.
    pub fn float(&self) -> Option<f64> {
        match self {
            Prop::Float(v) => Some(*v),
            Prop::Int(v) => Some(*v as f64),
            _ => None,
        }
    }

    pub fn str(&self) -> Option<&str> {
        match self {
            Prop::Str(s) => Some(s),
            _ => None,
        }
    }
}

/// A node: its name, properties and children.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Node {
    pub name: String,
    pub props: Vec<Prop>,
    pub children: Vec<Node>,
}

impl Node {
    /// The first child called `name`.
    pub fn child(&self, name: &str) -> Option<&Node> {
        self.children.iter().find(|c| c.name == name)
    }

    /// Every child called `name`.
    pub fn all<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a Node> + 'a {
        self.children.iter().filter(move |c| c.name == name)
    }
}

/// A parsed file: its version and top-level nodes.
#[derive(Debug)]
pub struct Document {
    pub version: u32,
    pub nodes: Vec<Node>,
}

/// Parse a binary FBX file; `path` names it in errors.
pub fn parse(path: &str, data: &[u8]) -> Result<Document> {
    if !data.starts_with(MAGIC) {
        let reason = if data.starts_with(b"; FBX") || data.starts_with(b"FBXHeaderExtension") {
            "an ASCII FBX file: only binary FBX is read (export as binary FBX 7)"
        } else {
            "not a binary FBX file (no `Kaydara FBX Binary` header)"
        };
        return Err(DataError::new(path, "header", reason));
    }
    let mut b = Bytes::new(path, data);
    b.seek(MAGIC.len(), "header")?;
    let version = b.u32("version")?;
    if version < MIN_VERSION {
        return Err(b.err(
            "version",
            format!("FBX version {version} is older than 7.0 and not read (export as FBX 7, 2011 or later)"),
        ));
    }
    let mut p = Parser {
        b,
        wide: version >= 7500,
        budget: INFLATE_RATIO.saturating_mul(data.len() as u64),
    };
    let nodes = p.list(data.len(), 0)?;
    Ok(Document { version, nodes })
}

struct Parser<'a> {
    b: Bytes<'a>,
    wide: bool,
    /// Bytes the remaining arrays may still inflate to.
    budget: u64,
}

impl Parser<'_> {
    fn word(&mut self, field: &str) -> Result<u64> {
        if self.wide {
            self.b.u64(field)
        } else {
            self.b.u32(field).map(u64::from)
        }
    }

    /// Records from the current position up to `end` or the closing all-zero record.
    fn list(&mut self, end: usize, depth: usize) -> Result<Vec<Node>> {
        if depth > MAX_DEPTH {
            return Err(self.b.err(
                "node",
                format!("nodes nested more than {MAX_DEPTH} deep at offset {}", self.b.pos()),
            ));
        }
        let mut nodes = Vec::new();
        while self.b.pos() < end {
            let start = self.b.pos();
            let record_end = self.word("node end offset")?;
            let n_props = self.word("node property count")?;
            let props_len = self.word("node property bytes")?;
            let name_len = usize::from(self.b.u8("node name length")?);
            if record_end == 0 {
                if n_props != 0 || props_len != 0 || name_len != 0 {
                    return Err(self
                        .b
                        .err("node", format!("a malformed closing record at offset {start}")));
                }
                return Ok(nodes);
            }
            let record_end = usize::try_from(record_end).unwrap_or(usize::MAX);
            if record_end > end || record_end <= start {
                return Err(self.b.err(
                    "node end offset",
                    format!("the record at offset {start} claims to end at {record_end}, outside [{start}, {end}]"),
                ));
            }
            let name = String::from_utf8_lossy(self.b.take(name_len, "node name")?).into_owned();
            let props_end = usize::try_from(props_len)
                .ok()
                .and_then(|l| l.checked_add(self.b.pos()))
                .filter(|&e| e <= record_end)
                .ok_or_else(|| {
                    self.b.err(
                        format!("node {name}"),
                        format!("{props_len} property bytes do not fit in the record at offset {start}"),
                    )
                })?;
            let mut props = Vec::new();
            for k in 0..n_props {
                if self.b.pos() >= props_end {
                    return Err(self.b.err(
                        format!("node {name}"),
                        format!("claims {n_props} properties but its property bytes end after {k}"),
                    ));
                }
                props.push(self.prop(&name)?);
            }
            if self.b.pos() != props_end {
                return Err(self.b.err(
                    format!("node {name}"),
                    format!("its properties end at offset {}, not at {props_end}", self.b.pos()),
                ));
            }
            let children = if props_end < record_end {
                self.list(record_end, depth + 1)?
            } else {
                Vec::new()
            };
            self.b.seek(record_end, "node end offset")?;
            nodes.push(Node { name, props, children });
        }
        if depth == 0 {
            return Err(self
                .b
                .err("node", "the file ends without the record that closes its node list"));
        }
        Ok(nodes)
    }

    fn prop(&mut self, node: &str) -> Result<Prop> {
        let field = format!("node {node}");
        let b = &mut self.b;
        let kind = b.u8(&field)?;
        Ok(match kind {
            b'Y' => Prop::Int(i64::from(b.i16(&field)?)),
            b'C' => Prop::Int(i64::from(b.u8(&field)?)),
            b'I' => Prop::Int(i64::from(b.i32(&field)?)),
            b'L' => Prop::Int(i64::from_le_bytes(b.take(8, &field)?.try_into().expect("8 bytes"))),
            b'F' => Prop::Float(f64::from(f32::from_le_bytes(b.take(4, &field)?.try_into().expect("4")))),
            b'D' => Prop::Float(f64::from_le_bytes(b.take(8, &field)?.try_into().expect("8 bytes"))),
            b'S' | b'R' => {
                let n = b.usize(&field)?;
                let raw = b.take(n, &field)?;
                if kind == b'S' {
                    Prop::Str(String::from_utf8_lossy(raw).into_owned())
                } else {
                    Prop::Raw(raw.to_vec())
                }
            }
            b'f' | b'd' | b'l' | b'i' | b'b' | b'c' => self.array(kind, &field)?,
            other => {
                return Err(b.err(
                    field,
                    format!("unknown property type {:?} at offset {}", other as char, b.pos() - 1),
                ));
            }
        })
    }

    fn array(&mut self, kind: u8, field: &str) -> Result<Prop> {
        let size = match kind {
            b'd' | b'l' => 8,
            b'f' | b'i' => 4,
            _ => 1,
        };
        let count = self.b.usize(field)?;
        let encoding = self.b.u32(field)?;
        let stored = self.b.usize(field)?;
        let raw = self.b.take(stored, field)?;
        let bytes = count as u64 * size as u64;
        let owned;
        let data: &[u8] = match encoding {
            0 if bytes == stored as u64 => raw,
            0 => {
                return Err(self.b.err(
                    field,
                    format!("an array of {count} × {size} bytes stored in {stored} bytes"),
                ));
            }
            1 => {
                if bytes > self.budget {
                    return Err(self.b.err(
                        field,
                        format!(
                            "a compressed array of {count} × {size} bytes: more than {INFLATE_RATIO} × the file's \
                             size inflated in all"
                        ),
                    ));
                }
                self.budget -= bytes;
                let mut out = Vec::new();
                flate2::read::ZlibDecoder::new(raw)
                    .take(bytes + 1)
                    .read_to_end(&mut out)
                    .map_err(|e| {
                        self.b
                            .err(field, format!("a compressed array that does not inflate: {e}"))
                    })?;
                if out.len() as u64 != bytes {
                    return Err(self.b.err(
                        field,
                        format!(
                            "a compressed array of {count} × {size} bytes inflates to {} bytes",
                            out.len()
                        ),
                    ));
                }
                owned = out;
                &owned
            }
            other => return Err(self.b.err(field, format!("array encoding {other} (expected 0 or 1)"))),
        };
        let words = |n: usize| data.chunks_exact(n);
        Ok(match kind {
            b'd' => Prop::Floats(words(8).map(|c| f64::from_le_bytes(c.try_into().expect("8"))).collect()),
            b'f' => Prop::Floats(
                words(4)
                    .map(|c| f64::from(f32::from_le_bytes(c.try_into().expect("4"))))
                    .collect(),
            ),
            b'l' => Prop::Ints(words(8).map(|c| i64::from_le_bytes(c.try_into().expect("8"))).collect()),
            b'i' => Prop::Ints(
                words(4)
                    .map(|c| i64::from(i32::from_le_bytes(c.try_into().expect("4"))))
                    .collect(),
            ),
            _ => Prop::Ints(data.iter().map(|&x| i64::from(x)).collect()),
        })
    }
}

/// Serialise `nodes` as a binary FBX file of `version`, arrays zlib-compressed when `compress` (for tests and
/// `bench data`). Integers are written as `L`, floats as `D`, arrays as `l` and `d`.
#[doc(hidden)]
pub fn write(version: u32, nodes: &[Node], compress: bool) -> Vec<u8> {
    let mut out = MAGIC.to_vec();
    out.extend_from_slice(&version.to_le_bytes());
    let wide = version >= 7500;
    write_list(&mut out, nodes, wide, compress);
    out.extend(std::iter::repeat_n(0u8, if wide { 25 } else { 13 }));
    out.extend_from_slice(&[0; 16]); // a footer the reader does not need
    out
}

fn write_list(out: &mut Vec<u8>, nodes: &[Node], wide: bool, compress: bool) {
    let word = |out: &mut Vec<u8>, at: usize, v: u64| {
        if wide {
            out[at..at + 8].copy_from_slice(&v.to_le_bytes());
        } else {
            out[at..at + 4].copy_from_slice(&(v as u32).to_le_bytes());
        }
    };
    let w = if wide { 8 } else { 4 };
    for n in nodes {
        let start = out.len();
        out.extend(std::iter::repeat_n(0u8, 3 * w));
        out.push(n.name.len() as u8);
        out.extend_from_slice(n.name.as_bytes());
        let props_start = out.len();
        for p in &n.props {
            write_prop(out, p, compress);
        }
        let props_len = (out.len() - props_start) as u64;
        if !n.children.is_empty() {
            write_list(out, &n.children, wide, compress);
            out.extend(std::iter::repeat_n(0u8, 3 * w + 1));
        }
        let end = out.len() as u64;
        word(out, start, end);
        word(out, start + w, n.props.len() as u64);
        word(out, start + 2 * w, props_len);
    }
}

fn write_prop(out: &mut Vec<u8>, p: &Prop, compress: bool) {
    let array = |out: &mut Vec<u8>, kind: u8, count: usize, raw: Vec<u8>| {
        out.push(kind);
        out.extend_from_slice(&(count as u32).to_le_bytes());
        let stored = if compress {
            use std::io::Write as _;
            let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
            z.write_all(&raw).expect("in memory");
            z.finish().expect("in memory")
        } else {
            raw
        };
        out.extend_from_slice(&u32::from(compress).to_le_bytes());
        out.extend_from_slice(&(stored.len() as u32).to_le_bytes());
        out.extend_from_slice(&stored);
    };
    match p {
        Prop::Int(v) => {
            out.push(b'L');
            out.extend_from_slice(&v.to_le_bytes());
        }
        Prop::Float(v) => {
            out.push(b'D');
            out.extend_from_slice(&v.to_le_bytes());
        }
        Prop::Str(s) => {
            out.push(b'S');
            out.extend_from_slice(&(s.len() as u32).to_le_bytes());
            out.extend_from_slice(s.as_bytes());
        }
        Prop::Raw(r) => {
            out.push(b'R');
            out.extend_from_slice(&(r.len() as u32).to_le_bytes());
            out.extend_from_slice(r);
        }
        Prop::Ints(v) => array(out, b'l', v.len(), v.iter().flat_map(|x| x.to_le_bytes()).collect()),
        Prop::Floats(v) => array(out, b'd', v.len(), v.iter().flat_map(|x| x.to_le_bytes()).collect()),
    }
}

//! Restricted unpickler and minimal pickler for DyMesh `.bin` clips: pickle bytes are data, never code.
//!
//! [`loads`] reads protocols 2–5 into a [`Value`] tree. The only globals accepted are the ones numpy itself emits
//! for plain arrays (`_reconstruct`, `ndarray`, `dtype`, protocol 5's `_frombuffer`) and
//! `_codecs.encode(str, 'latin1')`, which protocol 2 uses for `bytes`; each is interpreted as data. Any other global
//! (`os.system`, `builtins.eval`, …) is an error naming it, raised when the global opcode is read, before any
//! argument is looked at.
//!
//! The result is what Python's `pickle.load` gives: a dict keeps the value of the *last* occurrence of a key at the
//! position of its first (`1`, `1.0` and `True` are one key; an unhashable key is an error), and a `FRAME` must hold
//! the bytes it claims, with no opcode crossing its end and no frame starting inside another.
//!
//! Objects shared through the memo are copies: a memo reference to an object still on the stack sees its current
//! state (as in Python, where `pickle.dumps((x, x))` refers back to `x` before the tuple is built), one to an object
//! that has left the stack copies its final state. Self-referencing containers are not representable (the inner
//! reference is the copy made when it was read). Every copy is charged: [`MAX_VALUES`] bounds the values a pickle may create
//! (copies included) and [`MAX_SHARED_BYTES`] the array, bytes and text payload that sharing duplicates, so a small
//! file cannot ask for gigabytes (pickle bombs); [`MAX_DEPTH`] bounds nesting. [`dumps`] writes protocol 4.

mod item;
mod numpy;
mod read;
mod result;
mod write;

pub use read::loads;
pub use write::dumps;

/// Deepest container nesting accepted; deeper input is an error, not a stack overflow.
pub const MAX_DEPTH: usize = 256;
/// Most values (scalars, strings, containers, arrays; every memo or DUP copy counted again) one pickle may create:
/// a DyMesh clip holds about ten, and 2^18 values are about 10 MiB of tree, so copy bombs stop early.
pub const MAX_VALUES: u64 = 1 << 18;
/// Most payload bytes (array elements as decoded, bytes, text) that one object referenced several times (memo GET,
/// DUP) may add to the result when it is copied out: real clips share nothing; 256 MiB stops bombs built from one
/// large array.
pub const MAX_SHARED_BYTES: u64 = 1 << 28;

/// A decoded pickle value. Dicts keep insertion order.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    None,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    Bytes(Vec<u8>),
    List(Vec<Value>),
    Tuple(Vec<Value>),
    Dict(Vec<(Value, Value)>),
    NdArray(NdArray),
}

impl Value {
    /// Short type name for error messages.
    pub fn kind(&self) -> &'static str {
        match self {
            Value::None => "None",
            Value::Bool(_) => "bool",
            Value::Int(_) => "int",
            Value::Float(_) => "float",
            Value::Str(_) => "str",
            Value::Bytes(_) => "bytes",
            Value::List(_) => "list",
            Value::Tuple(_) => "tuple",
            Value::Dict(_) => "dict",
            Value::NdArray(_) => "ndarray",
        }
    }

    /// The value under string key `key` when `self` is a dict.
    pub fn get(&self, key: &str) -> Option<&Value> {
        match self {
            Value::Dict(items) => items
                .iter()
                .find(|(k, _)| matches!(k, Value::Str(s) if s == key))
                .map(|(_, v)| v),
            _ => None,
        }
    }
}

/// Element type of a numpy array as stored in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DType {
    F2,
    F4,
    F8,
    I1,
    I2,
    I4,
    I8,
    U1,
    U2,
    U4,
    U8,
    Bool,
}

impl DType {
    /// Parse numpy's type string (`f4`, `<i8`, …); returns the type and the byte order when the string names one.
    pub fn parse(descr: &str) -> Option<(DType, Option<ByteOrder>)> {
        let (order, code) = match descr.as_bytes().first() {
            Some(b'<') => (Some(ByteOrder::Little), &descr[1..]),
            Some(b'>') => (Some(ByteOrder::Big), &descr[1..]),
            Some(b'=' | b'|') => (None, &descr[1..]),
            _ => (None, descr),
        };
        let dtype = match code {
            "f2" | "e" => DType::F2,
            "f4" | "f" => DType::F4,
            "f8" | "d" => DType::F8,
            "i1" | "b" => DType::I1,
            "i2" | "h" => DType::I2,
            "i4" | "i" => DType::I4,
            "i8" | "q" | "l" => DType::I8,
            "u1" | "B" => DType::U1,
            "u2" | "H" => DType::U2,
            "u4" | "I" => DType::U4,
            "u8" | "Q" | "L" => DType::U8,
            "b1" | "?" => DType::Bool,
            _ => return None,
        };
        Some((dtype, order))
    }

    /// numpy's type string without byte order.
    pub fn descr(self) -> &'static str {
        match self {
            DType::F2 => "f2",
            DType::F4 => "f4",
            DType::F8 => "f8",
            DType::I1 => "i1",
            DType::I2 => "i2",
            DType::I4 => "i4",
            DType::I8 => "i8",
            DType::U1 => "u1",
            DType::U2 => "u2",
            DType::U4 => "u4",
            DType::U8 => "u8",
            DType::Bool => "b1",
        }
    }

    /// Bytes per element.
    pub fn item_size(self) -> usize {
        match self {
            DType::I1 | DType::U1 | DType::Bool => 1,
            DType::F2 | DType::I2 | DType::U2 => 2,
            DType::F4 | DType::I4 | DType::U4 => 4,
            DType::F8 | DType::I8 | DType::U8 => 8,
        }
    }

    /// Whether elements decode to [`ArrayData::Float`].
    pub fn is_float(self) -> bool {
        matches!(self, DType::F2 | DType::F4 | DType::F8)
    }
}

/// Byte order of array elements.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ByteOrder {
    Little,
    Big,
}

impl ByteOrder {
    pub(crate) fn native() -> Self {
        if cfg!(target_endian = "big") {
            ByteOrder::Big
        } else {
            ByteOrder::Little
        }
    }
}

/// Array elements in C (row-major) order, widened: floats to f64, integers and bools to i64.
#[derive(Debug, Clone, PartialEq)]
pub enum ArrayData {
    Float(Vec<f64>),
    Int(Vec<i64>),
}

impl ArrayData {
    pub fn len(&self) -> usize {
        match self {
            ArrayData::Float(v) => v.len(),
            ArrayData::Int(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A numpy array: `shape`, the file's element type, and the elements in C order.
#[derive(Debug, Clone, PartialEq)]
pub struct NdArray {
    pub shape: Vec<usize>,
    pub dtype: DType,
    pub data: ArrayData,
}

#[cfg(test)]
mod tests;

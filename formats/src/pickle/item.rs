//! The unpickler's stack items: values under construction and numpy's intermediate objects, and the globals it
//! accepts (each interpreted as data).

use std::rc::Rc;

use super::{ByteOrder, DType, NdArray};

/// The result of one step of the machine: an error is the reason, and the caller adds file and offset.
pub(super) type Step<T> = std::result::Result<T, String>;

/// The globals this unpickler knows; each is interpreted as data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Global {
    Reconstruct,
    NdArrayType,
    DTypeType,
    CodecsEncode,
    FromBuffer,
}

/// The (module, name) pairs accepted by GLOBAL and STACK_GLOBAL, and what each is read as.
pub(super) const ALLOWED_GLOBALS: &[(&str, &str, Global)] = &[
    ("numpy.core.multiarray", "_reconstruct", Global::Reconstruct),
    ("numpy._core.multiarray", "_reconstruct", Global::Reconstruct),
    ("numpy", "ndarray", Global::NdArrayType),
    ("numpy", "dtype", Global::DTypeType),
    ("_codecs", "encode", Global::CodecsEncode),
    ("numpy.core.numeric", "_frombuffer", Global::FromBuffer),
    ("numpy._core.numeric", "_frombuffer", Global::FromBuffer),
];

/// A stack item: a value under construction, or one of numpy's intermediate objects. Payloads are shared.
#[derive(Debug, Clone)]
pub(super) enum Item {
    None,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(Rc<String>),
    Bytes(Rc<Vec<u8>>),
    List(Vec<Item>),
    Tuple(Vec<Item>),
    Dict(Vec<(Item, Item)>),
    Array(Rc<NdArray>),
    Global(Global),
    /// `_reconstruct(ndarray, (0,), b'b')`: waits for BUILD with the array state.
    EmptyArray,
    /// `dtype('f4', False, True)`: BUILD sets the byte order.
    DTypeObj(DType, Option<ByteOrder>),
}

impl Item {
    pub(super) fn kind(&self) -> &'static str {
        match self {
            Item::None => "None",
            Item::Bool(_) => "bool",
            Item::Int(_) => "int",
            Item::Float(_) => "float",
            Item::Str(_) => "str",
            Item::Bytes(_) => "bytes",
            Item::List(_) => "list",
            Item::Tuple(_) => "tuple",
            Item::Dict(_) => "dict",
            Item::Array(_) => "ndarray",
            Item::Global(_) => "global",
            Item::EmptyArray => "unbuilt ndarray",
            Item::DTypeObj(..) => "dtype",
        }
    }
}

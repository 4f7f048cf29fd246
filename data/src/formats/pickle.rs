//! Restricted unpickler and minimal pickler for DyMesh `.bin` clips (docs/method.md §2.1): pickle bytes are data, never
//! code.
//!
//! Reads protocols 2–5 into a [`Value`] tree. The only globals accepted are the ones numpy itself emits for plain
//! arrays (`_reconstruct`, `ndarray`, `dtype`, protocol 5's `_frombuffer`) and `_codecs.encode(str, 'latin1')`, which
//! protocol 2 uses for `bytes`; each is interpreted here as data. Any other global (`os.system`, `builtins.eval`, …)
//! is an error naming it, raised when the global opcode is read, before any argument is looked at.
//!
//! Objects shared through the memo are copies; a memoised object mutated while on the stack (BUILD, SETITEMS,
//! APPENDS) updates its memo entry when it leaves the stack, which covers what pickle emits (self-referencing
//! containers are not representable). Nesting deeper than 256 containers and memo/DUP copies beyond 2^24 units
//! (pickle bombs) are errors.

use std::collections::HashMap;

use crate::error::{DataError, Result};

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
    fn native() -> Self {
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

/// The globals this unpickler knows; each is interpreted as data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Global {
    Reconstruct,
    NdArrayType,
    DTypeType,
    CodecsEncode,
    FromBuffer,
}

const ALLOWED_GLOBALS: &[(&str, &str, Global)] = &[
    ("numpy.core.multiarray", "_reconstruct", Global::Reconstruct),
    ("numpy._core.multiarray", "_reconstruct", Global::Reconstruct),
    ("numpy", "ndarray", Global::NdArrayType),
    ("numpy", "dtype", Global::DTypeType),
    ("_codecs", "encode", Global::CodecsEncode),
    ("numpy.core.numeric", "_frombuffer", Global::FromBuffer),
    ("numpy._core.numeric", "_frombuffer", Global::FromBuffer),
];

/// A stack item: a value under construction, or one of numpy's intermediate objects.
#[derive(Debug, Clone)]
enum Item {
    None,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    Bytes(Vec<u8>),
    List(Vec<Item>),
    Tuple(Vec<Item>),
    Dict(Vec<(Item, Item)>),
    Array(NdArray),
    Global(Global),
    /// `_reconstruct(ndarray, (0,), b'b')`: waits for BUILD with the array state.
    EmptyArray,
    /// `dtype('f4', False, True)`: BUILD sets the byte order.
    DTypeObj(DType, Option<ByteOrder>),
}

impl Item {
    fn kind(&self) -> &'static str {
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

    fn into_value(self) -> std::result::Result<Value, String> {
        let all = |items: Vec<Item>| {
            items
                .into_iter()
                .map(Item::into_value)
                .collect::<std::result::Result<Vec<_>, _>>()
        };
        Ok(match self {
            Item::None => Value::None,
            Item::Bool(b) => Value::Bool(b),
            Item::Int(i) => Value::Int(i),
            Item::Float(f) => Value::Float(f),
            Item::Str(s) => Value::Str(s),
            Item::Bytes(b) => Value::Bytes(b),
            Item::List(v) => Value::List(all(v)?),
            Item::Tuple(v) => Value::Tuple(all(v)?),
            Item::Dict(kv) => Value::Dict(
                kv.into_iter()
                    .map(|(k, v)| Ok((k.into_value()?, v.into_value()?)))
                    .collect::<std::result::Result<Vec<_>, String>>()?,
            ),
            Item::Array(a) => Value::NdArray(a),
            other => return Err(format!("a {} object is left in the data", other.kind())),
        })
    }
}

/// Nesting depth and size (items, array elements, 8-byte words of text) of a stack item, kept so that limits cost
/// nothing to check.
#[derive(Debug, Clone, Copy, Default)]
struct Meta {
    depth: usize,
    size: u64,
}

impl Meta {
    /// Meta of a non-container item.
    fn of(item: &Item) -> Meta {
        let size = match item {
            Item::Array(a) => 1 + a.data.len() as u64,
            Item::Str(t) => 1 + t.len() as u64 / 8,
            Item::Bytes(b) => 1 + b.len() as u64 / 8,
            _ => 1,
        };
        Meta { depth: 0, size }
    }

    /// Combined meta of several items (deepest depth, total size).
    fn all(metas: impl IntoIterator<Item = Meta>) -> Meta {
        metas.into_iter().fold(Meta::default(), |a, b| Meta {
            depth: a.depth.max(b.depth),
            size: a.size.saturating_add(b.size),
        })
    }
}

/// A stack slot remembers the memo key it came from, so that mutations reach the memo too.
struct Slot {
    item: Item,
    memo: Option<u64>,
    meta: Meta,
}

struct Machine<'a> {
    bytes: &'a [u8],
    pos: usize,
    stack: Vec<Slot>,
    marks: Vec<usize>,
    memo: HashMap<u64, (Item, Meta)>,
    /// Units copied by BINGET/DUP so far.
    copied: u64,
}

/// Deepest container nesting accepted; deeper input is an error, not a stack overflow.
const MAX_DEPTH: usize = 256;
/// Most units that memo references and DUP may copy (on top of the input size): stops exponential "pickle bombs".
const MAX_COPIED: u64 = 1 << 22;

type Step<T> = std::result::Result<T, String>;

/// Decode pickle `bytes`. Errors name `source`, field `pickle` and the byte offset of the failing opcode.
pub fn loads(bytes: &[u8], source: &str) -> Result<Value> {
    let mut m = Machine {
        bytes,
        pos: 0,
        stack: Vec::new(),
        marks: Vec::new(),
        memo: HashMap::new(),
        copied: 0,
    };
    let mut op_pos = 0;
    let result = (|| -> Step<Value> {
        loop {
            op_pos = m.pos;
            if m.pos >= m.bytes.len() {
                return Err("truncated: input ended before STOP".into());
            }
            if let Some(item) = m.step()? {
                return item.into_value();
            }
        }
    })();
    result.map_err(|reason| DataError::new(source, "pickle", format!("byte {op_pos}: {reason}")))
}

impl Machine<'_> {
    fn take(&mut self, n: usize, what: &str) -> Step<&[u8]> {
        let left = self.bytes.len() - self.pos;
        if n > left {
            return Err(format!("truncated: {what} needs {n} bytes, {left} left"));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn uint(&mut self, n: usize, what: &str) -> Step<u64> {
        let b = self.take(n, what)?;
        Ok(b.iter().rev().fold(0u64, |acc, &x| (acc << 8) | x as u64))
    }

    fn sized(&mut self, len_bytes: usize, what: &str) -> Step<Vec<u8>> {
        let n = self.uint(len_bytes, what)?;
        let n = usize::try_from(n).map_err(|_| format!("{what}: length {n} too large"))?;
        Ok(self.take(n, what)?.to_vec())
    }

    fn text(&mut self, len_bytes: usize, what: &str) -> Step<String> {
        String::from_utf8(self.sized(len_bytes, what)?).map_err(|e| format!("{what}: invalid UTF-8: {e}"))
    }

    fn line(&mut self, what: &str) -> Step<String> {
        let rest = &self.bytes[self.pos..];
        let end = rest
            .iter()
            .position(|&b| b == b'\n')
            .ok_or(format!("truncated: {what} has no newline"))?;
        let s = String::from_utf8(rest[..end].to_vec()).map_err(|e| format!("{what}: invalid UTF-8: {e}"))?;
        self.pos += end + 1;
        Ok(s)
    }

    /// Push a non-container item, or an empty container.
    fn push(&mut self, item: Item) {
        let meta = Meta::of(&item);
        self.stack.push(Slot { item, memo: None, meta });
    }

    /// Push a container holding children of combined meta `children`.
    fn push_container(&mut self, item: Item, children: Meta) -> Step<()> {
        let meta = Meta {
            depth: children.depth + 1,
            size: children.size.saturating_add(1),
        };
        if meta.depth > MAX_DEPTH {
            return Err(format!("containers nest deeper than {MAX_DEPTH}"));
        }
        self.stack.push(Slot { item, memo: None, meta });
        Ok(())
    }

    fn pop_meta(&mut self, what: &str) -> Step<(Item, Meta)> {
        let floor = self.marks.last().copied().unwrap_or(0);
        if self.stack.len() <= floor {
            return Err(format!("stack underflow in {what}"));
        }
        let slot = self.stack.pop().expect("checked above");
        Ok(self.release(slot))
    }

    fn pop(&mut self, what: &str) -> Step<Item> {
        self.pop_meta(what).map(|(item, _)| item)
    }

    fn top(&mut self, what: &str) -> Step<&mut Slot> {
        let floor = self.marks.last().copied().unwrap_or(0);
        if self.stack.len() <= floor {
            return Err(format!("stack underflow in {what}"));
        }
        Ok(self.stack.last_mut().expect("checked above"))
    }

    /// The items above the last MARK and their combined meta.
    fn pop_mark(&mut self, what: &str) -> Step<(Vec<Item>, Meta)> {
        let mark = self.marks.pop().ok_or(format!("{what} without MARK"))?;
        let slots = self.stack.split_off(mark);
        let (items, metas): (Vec<Item>, Vec<Meta>) = slots.into_iter().map(|s| self.release(s)).unzip();
        Ok((items, Meta::all(metas)))
    }

    /// Add children of combined meta `children` to the top container (SETITEMS, APPENDS).
    fn grow_top(&mut self, children: Meta) -> Step<()> {
        let slot = self.top("grow")?;
        slot.meta.depth = slot.meta.depth.max(children.depth + 1);
        slot.meta.size = slot.meta.size.saturating_add(children.size);
        if slot.meta.depth > MAX_DEPTH {
            return Err(format!("containers nest deeper than {MAX_DEPTH}"));
        }
        Ok(())
    }

    /// A slot leaves the stack: its memo entry gets the final state (after BUILD, SETITEMS, APPENDS on the stack).
    fn release(&mut self, slot: Slot) -> (Item, Meta) {
        if let Some(key) = slot.memo {
            self.memo.insert(key, (slot.item.clone(), slot.meta));
        }
        (slot.item, slot.meta)
    }

    fn memo_put(&mut self, key: u64) -> Step<()> {
        let slot = self.top("memo put")?;
        slot.memo = Some(key);
        let entry = (slot.item.clone(), slot.meta);
        self.memo.insert(key, entry);
        Ok(())
    }

    /// Account for copying an item of `size` units (BINGET, DUP).
    fn charge(&mut self, size: u64) -> Step<()> {
        self.copied = self.copied.saturating_add(size);
        if self.copied > MAX_COPIED + self.bytes.len() as u64 {
            return Err(format!(
                "memo references and DUP copy more than {MAX_COPIED} units (a pickle bomb?)"
            ));
        }
        Ok(())
    }

    fn memo_get(&mut self, key: u64) -> Step<()> {
        let size = self
            .memo
            .get(&key)
            .ok_or(format!("memo key {key} was never stored"))?
            .1
            .size;
        self.charge(size)?;
        let (item, meta) = self.memo[&key].clone();
        self.stack.push(Slot {
            item,
            memo: Some(key),
            meta,
        });
        Ok(())
    }

    fn global(module: &str, name: &str) -> Step<Item> {
        ALLOWED_GLOBALS
            .iter()
            .find(|(m, n, _)| *m == module && *n == name)
            .map(|(_, _, g)| Item::Global(*g))
            .ok_or(format!(
                "global `{module}.{name}` is not allowed (only numpy array reconstruction); nothing was executed"
            ))
    }

    /// One opcode; `Some(result)` at STOP.
    fn step(&mut self) -> Step<Option<Item>> {
        let op = self.take(1, "opcode")?[0];
        match op {
            0x80 => {
                let p = self.uint(1, "PROTO")?;
                if p > 5 {
                    return Err(format!("unsupported pickle protocol {p}"));
                }
            }
            0x95 => {
                self.uint(8, "FRAME")?;
            }
            b'.' => {
                let item = self.pop("STOP")?;
                if !self.stack.is_empty() || !self.marks.is_empty() {
                    return Err(format!("STOP with {} items left on the stack", self.stack.len()));
                }
                return Ok(Some(item));
            }
            b'(' => self.marks.push(self.stack.len()),
            b'0' => {
                self.pop("POP")?;
            }
            b'1' => {
                self.pop_mark("POP_MARK")?;
            }
            b'2' => {
                let top = self.top("DUP")?;
                let (item, meta) = (top.item.clone(), top.meta);
                self.charge(meta.size)?;
                self.stack.push(Slot { item, memo: None, meta });
            }
            b'N' => self.push(Item::None),
            0x88 => self.push(Item::Bool(true)),
            0x89 => self.push(Item::Bool(false)),
            b'J' => {
                let v = self.uint(4, "BININT")? as u32 as i32;
                self.push(Item::Int(v as i64));
            }
            b'K' => {
                let v = self.uint(1, "BININT1")?;
                self.push(Item::Int(v as i64));
            }
            b'M' => {
                let v = self.uint(2, "BININT2")?;
                self.push(Item::Int(v as i64));
            }
            0x8a | 0x8b => {
                let what = if op == 0x8a { "LONG1" } else { "LONG4" };
                let b = self.sized(if op == 0x8a { 1 } else { 4 }, what)?;
                if b.len() > 8 {
                    return Err(format!("{what}: integer of {} bytes does not fit i64", b.len()));
                }
                let mut v = b.iter().rev().fold(0i64, |acc, &x| (acc << 8) | x as i64);
                if let Some(&last) = b.last()
                    && last & 0x80 != 0
                    && b.len() < 8
                {
                    v -= 1i64 << (8 * b.len());
                }
                self.push(Item::Int(v));
            }
            b'G' => {
                let b: [u8; 8] = self.take(8, "BINFLOAT")?.try_into().expect("8 bytes");
                self.push(Item::Float(f64::from_be_bytes(b)));
            }
            b'X' => {
                let s = self.text(4, "BINUNICODE")?;
                self.push(Item::Str(s));
            }
            0x8c => {
                let s = self.text(1, "SHORT_BINUNICODE")?;
                self.push(Item::Str(s));
            }
            0x8d => {
                let s = self.text(8, "BINUNICODE8")?;
                self.push(Item::Str(s));
            }
            b'B' | b'T' => {
                let b = self.sized(4, "BINBYTES")?;
                self.push(Item::Bytes(b));
            }
            b'C' | b'U' => {
                let b = self.sized(1, "SHORT_BINBYTES")?;
                self.push(Item::Bytes(b));
            }
            0x8e | 0x96 => {
                let b = self.sized(8, "BINBYTES8")?;
                self.push(Item::Bytes(b));
            }
            0x98 => {
                self.top("READONLY_BUFFER")?;
            }
            b'}' => self.push(Item::Dict(Vec::new())),
            b']' => self.push(Item::List(Vec::new())),
            b')' => self.push(Item::Tuple(Vec::new())),
            0x85..=0x87 => {
                let n = (op - 0x84) as usize;
                let mut items = Vec::with_capacity(n);
                let mut metas = Vec::with_capacity(n);
                for _ in 0..n {
                    let (item, meta) = self.pop_meta("TUPLE1-3")?;
                    items.push(item);
                    metas.push(meta);
                }
                items.reverse();
                self.push_container(Item::Tuple(items), Meta::all(metas))?;
            }
            b't' => {
                let (items, meta) = self.pop_mark("TUPLE")?;
                self.push_container(Item::Tuple(items), meta)?;
            }
            b'l' => {
                let (items, meta) = self.pop_mark("LIST")?;
                self.push_container(Item::List(items), meta)?;
            }
            b'd' => {
                let (items, meta) = self.pop_mark("DICT")?;
                let pairs = pairs(items, "DICT")?;
                self.push_container(Item::Dict(pairs), meta)?;
            }
            b's' | b'u' => {
                let (items, meta) = if op == b's' {
                    let (v, mv) = self.pop_meta("SETITEM")?;
                    let (k, mk) = self.pop_meta("SETITEM")?;
                    (vec![k, v], Meta::all([mk, mv]))
                } else {
                    self.pop_mark("SETITEMS")?
                };
                let pairs = pairs(items, "SETITEMS")?;
                match &mut self.top("SETITEM")?.item {
                    Item::Dict(d) => d.extend(pairs),
                    other => return Err(format!("SETITEM on a {}", other.kind())),
                }
                self.grow_top(meta)?;
            }
            b'a' | b'e' => {
                let (items, meta) = if op == b'a' {
                    let (item, meta) = self.pop_meta("APPEND")?;
                    (vec![item], meta)
                } else {
                    self.pop_mark("APPENDS")?
                };
                match &mut self.top("APPEND")?.item {
                    Item::List(l) => l.extend(items),
                    other => return Err(format!("APPEND on a {}", other.kind())),
                }
                self.grow_top(meta)?;
            }
            b'c' => {
                let module = self.line("GLOBAL module")?;
                let name = self.line("GLOBAL name")?;
                let g = Self::global(&module, &name)?;
                self.push(g);
            }
            0x93 => {
                let name = self.pop("STACK_GLOBAL")?;
                let module = self.pop("STACK_GLOBAL")?;
                let (Item::Str(module), Item::Str(name)) = (module, name) else {
                    return Err("STACK_GLOBAL needs two strings".into());
                };
                let g = Self::global(&module, &name)?;
                self.push(g);
            }
            b'R' | 0x81 => {
                let what = if op == b'R' { "REDUCE" } else { "NEWOBJ" };
                let args = self.pop(what)?;
                let callable = self.pop(what)?;
                let Item::Tuple(args) = args else {
                    return Err(format!("{what} arguments are a {}, not a tuple", args.kind()));
                };
                let Item::Global(g) = callable else {
                    return Err(format!("{what} of a {}, not an allowed global", callable.kind()));
                };
                self.push(call(g, args)?);
            }
            b'b' => {
                let state = self.pop("BUILD")?;
                let slot = self.top("BUILD")?;
                let obj = std::mem::replace(&mut slot.item, Item::None);
                slot.item = build(obj, state)?;
                slot.meta = Meta::of(&slot.item);
            }
            b'q' => {
                let k = self.uint(1, "BINPUT")?;
                self.memo_put(k)?;
            }
            b'r' => {
                let k = self.uint(4, "LONG_BINPUT")?;
                self.memo_put(k)?;
            }
            0x94 => {
                let k = self.memo.len() as u64;
                self.memo_put(k)?;
            }
            b'p' => {
                let k = self
                    .line("PUT")?
                    .trim()
                    .parse::<u64>()
                    .map_err(|e| format!("PUT: {e}"))?;
                self.memo_put(k)?;
            }
            b'h' => {
                let k = self.uint(1, "BINGET")?;
                self.memo_get(k)?;
            }
            b'j' => {
                let k = self.uint(4, "LONG_BINGET")?;
                self.memo_get(k)?;
            }
            b'g' => {
                let k = self
                    .line("GET")?
                    .trim()
                    .parse::<u64>()
                    .map_err(|e| format!("GET: {e}"))?;
                self.memo_get(k)?;
            }
            b'P' | b'Q' => return Err("persistent ids are not supported".into()),
            0x82..=0x84 => return Err("extension registry codes are not supported".into()),
            0x92 => return Err("NEWOBJ_EX is not supported".into()),
            0x97 => return Err("out-of-band buffers (NEXT_BUFFER) are not supported".into()),
            other => return Err(format!("unknown or unsupported opcode 0x{other:02x}")),
        }
        Ok(None)
    }
}

fn pairs(items: Vec<Item>, what: &str) -> Step<Vec<(Item, Item)>> {
    if !items.len().is_multiple_of(2) {
        return Err(format!("{what} with an odd number ({}) of items", items.len()));
    }
    let mut it = items.into_iter();
    let mut out = Vec::new();
    while let (Some(k), Some(v)) = (it.next(), it.next()) {
        out.push((k, v));
    }
    Ok(out)
}

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
fn call(g: Global, args: Vec<Item>) -> Step<Item> {
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
                .map(Item::Bytes)
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
            .map(Item::Array)
        }
        (g, args) => Err(format!(
            "unsupported call of {g:?} with arguments ({})",
            args.iter().map(Item::kind).collect::<Vec<_>>().join(", ")
        )),
    }
}

/// BUILD: numpy `__setstate__` of an array or a dtype.
fn build(obj: Item, state: Item) -> Step<Item> {
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
            .map(Item::Array)
        }
        Item::DTypeObj(dtype, _) => {
            let order = match state.get(1) {
                Some(Item::Str(s)) if s == "<" => Some(ByteOrder::Little),
                Some(Item::Str(s)) if s == ">" => Some(ByteOrder::Big),
                Some(Item::Str(s)) if s == "|" || s == "=" => Some(ByteOrder::native()),
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
fn fortran_to_c<T: Copy>(v: &[T], shape: &[usize]) -> Vec<T> {
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
fn f16_to_f64(h: u16) -> f64 {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn err(bytes: &[u8]) -> DataError {
        loads(bytes, "t.bin").unwrap_err()
    }

    #[test]
    fn scalars_and_containers() {
        // protocol 2: {'a': [1, -2, 3.5, None, True], 'b': (b'xy',)}
        let mut p = vec![0x80, 2, b'}', b'(', b'X', 1, 0, 0, 0, b'a', b']', b'('];
        p.extend([b'K', 1, b'J', 0xfe, 0xff, 0xff, 0xff, b'G']);
        p.extend(3.5f64.to_be_bytes());
        p.extend([b'N', 0x88, b'e', 0x8c, 1, b'b', b'C', 2, b'x', b'y', 0x85, b'u', b'.']);
        let v = loads(&p, "t.bin").unwrap();
        assert_eq!(
            v.get("a"),
            Some(&Value::List(vec![
                Value::Int(1),
                Value::Int(-2),
                Value::Float(3.5),
                Value::None,
                Value::Bool(true)
            ]))
        );
        assert_eq!(v.get("b"), Some(&Value::Tuple(vec![Value::Bytes(b"xy".to_vec())])));
    }

    #[test]
    fn long1_is_twos_complement() {
        let v = loads(&[0x80, 2, 0x8a, 2, 0x00, 0xff, b'.'], "t").unwrap();
        assert_eq!(v, Value::Int(-256));
        let v = loads(&[0x80, 2, 0x8a, 2, 0x00, 0x01, b'.'], "t").unwrap();
        assert_eq!(v, Value::Int(256));
    }

    #[test]
    fn hostile_global_is_refused_by_name() {
        let e = err(b"\x80\x02cos\nsystem\nX\x04\x00\x00\x00echo\x85R.");
        assert_eq!(e.field, "pickle");
        assert!(e.reason.contains("`os.system`") && e.reason.contains("byte 2"), "{e}");
        let e = err(b"\x80\x04\x8c\x08builtins\x8c\x04eval\x93.");
        assert!(e.reason.contains("`builtins.eval`"), "{e}");
    }

    #[test]
    fn truncated_unknown_and_underflow() {
        assert!(err(&[0x80, 2, b'X', 9, 0, 0, 0, b'a']).reason.contains("truncated"));
        assert!(err(&[0x80, 2, b'N']).reason.contains("before STOP"));
        assert!(err(&[0x80, 2, 0xff]).reason.contains("opcode 0xff"));
        assert!(err(&[0x80, 2, b't', b'.']).reason.contains("without MARK"));
        assert!(err(&[0x80, 2, b'(', b'.']).reason.contains("underflow"));
        assert!(err(&[0x80, 2, b'h', 3]).reason.contains("memo key 3"));
    }

    #[test]
    fn bombs_and_deep_nesting_are_errors() {
        let mut bomb = vec![0x80, 4, b'N'];
        for _ in 0..40 {
            bomb.extend([b'2', 0x86]); // DUP, TUPLE2: doubles the size each time
        }
        bomb.push(b'.');
        assert!(err(&bomb).reason.contains("pickle bomb"), "{}", err(&bomb));
        let mut deep = vec![0x80, 4];
        deep.extend([b']'; 300]);
        deep.extend([b'a'; 299]);
        deep.push(b'.');
        assert!(err(&deep).reason.contains("deeper than 256"), "{}", err(&deep));
        // 200 levels are fine.
        let mut ok = vec![0x80, 4];
        ok.extend([b']'; 200]);
        ok.extend([b'a'; 199]);
        ok.push(b'.');
        assert!(loads(&ok, "t").is_ok());
    }

    #[test]
    fn half_floats_and_fortran_order() {
        assert_eq!(f16_to_f64(0x3c00), 1.0);
        assert_eq!(f16_to_f64(0xc000), -2.0);
        assert_eq!(f16_to_f64(0x0001), 2f64.powi(-24));
        // column-major [[0,1,2],[3,4,5]] stored as 0,3,1,4,2,5
        assert_eq!(fortran_to_c(&[0, 3, 1, 4, 2, 5], &[2, 3]), vec![0, 1, 2, 3, 4, 5]);
    }

    #[test]
    fn writer_round_trips_through_reader() {
        let v = Value::Dict(vec![
            (
                Value::Str("vertices".into()),
                Value::NdArray(NdArray {
                    shape: vec![2, 1, 3],
                    dtype: DType::F4,
                    data: ArrayData::Float(vec![0.5, -1.0, 2.0, 3.25, 1e-3f32 as f64, 7.0]),
                }),
            ),
            (
                Value::Str("faces".into()),
                Value::NdArray(NdArray {
                    shape: vec![1, 3],
                    dtype: DType::I8,
                    data: ArrayData::Int(vec![0, 1, -2]),
                }),
            ),
            (Value::Str("caption".into()), Value::Str("a cat ".repeat(60))),
            (
                Value::Str("n".into()),
                Value::List(vec![Value::Int(-70000), Value::Int(1 << 40), Value::Bool(false)]),
            ),
        ]);
        let bytes = dumps(&v).unwrap();
        assert_eq!(loads(&bytes, "t").unwrap(), v);
    }
}

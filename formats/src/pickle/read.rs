//! The restricted unpickler: a stack machine over pickle opcodes that builds [`Value`]s and executes nothing.
//!
//! Large payloads (text, bytes, arrays) are reference-counted while the machine runs, so memo and DUP copies cost
//! one tree node each; every node created or copied counts against [`MAX_VALUES`], and payloads still shared when
//! the result is built are copied out against [`MAX_SHARED_BYTES`].

use std::collections::{HashMap, HashSet};
use std::rc::Rc;

use super::item::{ALLOWED_GLOBALS, Item, Step};
use super::numpy::{build, call};
use super::result::value;
use super::{MAX_DEPTH, MAX_SHARED_BYTES, MAX_VALUES, Value};
use crate::error::{DataError, Result};

/// Nesting depth and node count of a stack item, kept so that limits cost nothing to check.
#[derive(Debug, Clone, Copy, Default)]
struct Meta {
    depth: usize,
    nodes: u64,
}

impl Meta {
    /// Meta of a non-container item.
    const LEAF: Meta = Meta { depth: 0, nodes: 1 };

    /// Combined meta of several items (deepest depth, total nodes).
    fn all(metas: impl IntoIterator<Item = Meta>) -> Meta {
        metas.into_iter().fold(Meta::default(), |a, b| Meta {
            depth: a.depth.max(b.depth),
            nodes: a.nodes.saturating_add(b.nodes),
        })
    }
}

/// A stack slot remembers the memo keys stored from it: while it is on the stack they refer to it (and see
/// BUILD, SETITEMS and APPENDS on it); when it leaves the stack they get a copy of its final state.
struct Slot {
    item: Item,
    meta: Meta,
    memo_keys: Vec<u64>,
}

impl Slot {
    fn new(item: Item, meta: Meta) -> Self {
        Self {
            item,
            meta,
            memo_keys: Vec::new(),
        }
    }
}

/// A memo entry: an object still on the stack (by slot index), or a stored copy.
enum Memo {
    Stack(usize),
    Stored(Item, Meta),
}

struct Machine<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// End of the current FRAME, while inside one.
    frame_end: Option<usize>,
    stack: Vec<Slot>,
    marks: Vec<usize>,
    memo: HashMap<u64, Memo>,
    /// Nodes created or copied so far (limit [`MAX_VALUES`]).
    values: u64,
}

const BOMB: &str = "(a pickle bomb?)";

/// Decode pickle `bytes`. Errors name `source`, field `pickle` and the byte offset of the failing opcode.
pub fn loads(bytes: &[u8], source: &str) -> Result<Value> {
    let mut m = Machine {
        bytes,
        pos: 0,
        frame_end: None,
        stack: Vec::new(),
        marks: Vec::new(),
        memo: HashMap::new(),
        values: 0,
    };
    let mut op_pos = 0;
    let result = (|| -> Step<Value> {
        loop {
            op_pos = m.pos;
            if m.frame_end == Some(m.pos) {
                m.frame_end = None;
            }
            if m.pos >= m.bytes.len() {
                return Err("truncated: input ended before STOP".into());
            }
            if let Some(item) = m.step()? {
                return m.finish(item);
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
        if let Some(end) = self.frame_end
            && self.pos + n > end
        {
            return Err(format!(
                "{what} needs {n} bytes but its FRAME ends after {} (an opcode may not cross a frame end)",
                end - self.pos
            ));
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
        let rest = &self.bytes[self.pos..self.frame_end.unwrap_or(self.bytes.len())];
        let end = rest.iter().position(|&b| b == b'\n').ok_or(format!(
            "truncated: {what} has no newline before the end of the input or its FRAME"
        ))?;
        let s = String::from_utf8(rest[..end].to_vec()).map_err(|e| format!("{what}: invalid UTF-8: {e}"))?;
        self.pos += end + 1;
        Ok(s)
    }

    /// FRAME: the next `len` bytes are one frame (Python: all present, no frame inside another).
    fn frame(&mut self) -> Step<()> {
        if self.frame_end.is_some() {
            return Err("FRAME starts before the end of the current frame".into());
        }
        let len = self.uint(8, "FRAME")?;
        let left = (self.bytes.len() - self.pos) as u64;
        if len > left {
            return Err(format!("FRAME claims {len} bytes, {left} left (truncated)"));
        }
        self.frame_end = Some(self.pos + len as usize);
        Ok(())
    }

    /// Count `nodes` new or copied values against [`MAX_VALUES`].
    fn charge(&mut self, nodes: u64) -> Step<()> {
        self.values = self.values.saturating_add(nodes);
        if self.values > MAX_VALUES {
            return Err(format!(
                "more than {MAX_VALUES} values, memo and DUP copies included {BOMB}"
            ));
        }
        Ok(())
    }

    /// Push a non-container item, or an empty container.
    fn push(&mut self, item: Item) -> Step<()> {
        self.charge(1)?;
        self.stack.push(Slot::new(item, Meta::LEAF));
        Ok(())
    }

    /// Push a container holding children of combined meta `children`.
    fn push_container(&mut self, item: Item, children: Meta) -> Step<()> {
        self.charge(1)?;
        let meta = Meta {
            depth: children.depth + 1,
            nodes: children.nodes.saturating_add(1),
        };
        if meta.depth > MAX_DEPTH {
            return Err(format!("containers nest deeper than {MAX_DEPTH}"));
        }
        self.stack.push(Slot::new(item, meta));
        Ok(())
    }

    fn pop_meta(&mut self, what: &str) -> Step<(Item, Meta)> {
        let floor = self.marks.last().copied().unwrap_or(0);
        if self.stack.len() <= floor {
            return Err(format!("stack underflow in {what}"));
        }
        let slot = self.stack.pop().expect("checked above");
        self.release(slot, self.stack.len())
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
        let mut items = Vec::with_capacity(slots.len());
        let mut metas = Vec::with_capacity(slots.len());
        for (i, slot) in slots.into_iter().enumerate() {
            let (item, meta) = self.release(slot, mark + i)?;
            items.push(item);
            metas.push(meta);
        }
        Ok((items, Meta::all(metas)))
    }

    /// Add children of combined meta `children` to the top container (SETITEMS, APPENDS).
    fn grow_top(&mut self, children: Meta) -> Step<()> {
        let slot = self.top("grow")?;
        slot.meta.depth = slot.meta.depth.max(children.depth + 1);
        slot.meta.nodes = slot.meta.nodes.saturating_add(children.nodes);
        if slot.meta.depth > MAX_DEPTH {
            return Err(format!("containers nest deeper than {MAX_DEPTH}"));
        }
        Ok(())
    }

    /// Slot `index` leaves the stack: the memo keys still referring to it get a (charged) copy of its final state.
    fn release(&mut self, slot: Slot, index: usize) -> Step<(Item, Meta)> {
        for &key in &slot.memo_keys {
            if matches!(self.memo.get(&key), Some(Memo::Stack(i)) if *i == index) {
                self.charge(slot.meta.nodes)?;
                self.memo.insert(key, Memo::Stored(slot.item.clone(), slot.meta));
            }
        }
        Ok((slot.item, slot.meta))
    }

    /// PUT, BINPUT, LONG_BINPUT, MEMOIZE: the key refers to the top item.
    fn memo_put(&mut self, key: u64) -> Step<()> {
        let index = self.stack.len().wrapping_sub(1);
        self.top("memo put")?.memo_keys.push(key);
        self.memo.insert(key, Memo::Stack(index));
        Ok(())
    }

    /// GET, BINGET, LONG_BINGET: push a (charged) copy of the object stored under `key`, in its current state.
    fn memo_get(&mut self, key: u64) -> Step<()> {
        let (item, meta) = match self.memo.get(&key) {
            None => return Err(format!("memo key {key} was never stored")),
            Some(Memo::Stack(i)) => (&self.stack[*i].item, self.stack[*i].meta),
            Some(Memo::Stored(item, meta)) => (item, *meta),
        };
        let nodes = meta.nodes;
        let values = self.values.saturating_add(nodes);
        if values > MAX_VALUES {
            return Err(format!(
                "more than {MAX_VALUES} values, memo and DUP copies included {BOMB}"
            ));
        }
        let item = item.clone();
        self.values = values;
        self.stack.push(Slot::new(item, meta));
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

    /// Bytes that building the result would copy: every reference to a shared payload after its first.
    fn shared_copies(item: &Item, seen: &mut HashSet<usize>) -> u64 {
        let mut once = |ptr: usize, bytes: u64| if seen.insert(ptr) { 0 } else { bytes };
        match item {
            Item::Str(s) => once(Rc::as_ptr(s) as usize, s.len() as u64),
            Item::Bytes(b) => once(Rc::as_ptr(b) as usize, b.len() as u64),
            Item::Array(a) => once(Rc::as_ptr(a) as usize, 8 * a.data.len() as u64),
            Item::List(v) | Item::Tuple(v) => v
                .iter()
                .fold(0u64, |acc, i| acc.saturating_add(Self::shared_copies(i, seen))),
            Item::Dict(kv) => kv.iter().fold(0u64, |acc, (k, v)| {
                acc.saturating_add(Self::shared_copies(k, seen))
                    .saturating_add(Self::shared_copies(v, seen))
            }),
            _ => 0,
        }
    }

    /// Convert the finished item, refusing it when shared payloads would copy more than [`MAX_SHARED_BYTES`].
    fn finish(&mut self, item: Item) -> Step<Value> {
        // Drop the memo first: a payload referenced only by the result then moves out without a copy.
        self.memo.clear();
        let copies = Self::shared_copies(&item, &mut HashSet::new());
        if copies > MAX_SHARED_BYTES {
            return Err(format!(
                "objects referenced several times would copy {copies} bytes, more than {MAX_SHARED_BYTES} {BOMB}"
            ));
        }
        value(item)
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
            0x95 => self.frame()?,
            b'.' => {
                self.top("STOP")?;
                if self.stack.len() > 1 || !self.marks.is_empty() {
                    return Err(format!("STOP with {} items left on the stack", self.stack.len() - 1));
                }
                // The memo is dropped next, so the result leaves the stack without updating it.
                let slot = self.stack.pop().expect("checked above");
                return Ok(Some(slot.item));
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
                self.charge(meta.nodes)?;
                self.stack.push(Slot::new(item, meta));
            }
            b'N' => self.push(Item::None)?,
            0x88 => self.push(Item::Bool(true))?,
            0x89 => self.push(Item::Bool(false))?,
            b'J' => {
                let v = self.uint(4, "BININT")? as u32 as i32;
                self.push(Item::Int(v as i64))?;
            }
            b'K' => {
                let v = self.uint(1, "BININT1")?;
                self.push(Item::Int(v as i64))?;
            }
            b'M' => {
                let v = self.uint(2, "BININT2")?;
                self.push(Item::Int(v as i64))?;
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
                self.push(Item::Int(v))?;
            }
            b'G' => {
                let b: [u8; 8] = self.take(8, "BINFLOAT")?.try_into().expect("8 bytes");
                self.push(Item::Float(f64::from_be_bytes(b)))?;
            }
            b'X' => {
                let s = self.text(4, "BINUNICODE")?;
                self.push(Item::Str(Rc::new(s)))?;
            }
            0x8c => {
                let s = self.text(1, "SHORT_BINUNICODE")?;
                self.push(Item::Str(Rc::new(s)))?;
            }
            0x8d => {
                let s = self.text(8, "BINUNICODE8")?;
                self.push(Item::Str(Rc::new(s)))?;
            }
            b'B' | b'T' => {
                let b = self.sized(4, "BINBYTES")?;
                self.push(Item::Bytes(Rc::new(b)))?;
            }
            b'C' | b'U' => {
                let b = self.sized(1, "SHORT_BINBYTES")?;
                self.push(Item::Bytes(Rc::new(b)))?;
            }
            0x8e | 0x96 => {
                let b = self.sized(8, "BINBYTES8")?;
                self.push(Item::Bytes(Rc::new(b)))?;
            }
            0x98 => {
                self.top("READONLY_BUFFER")?;
            }
            b'}' => self.push(Item::Dict(Vec::new()))?,
            b']' => self.push(Item::List(Vec::new()))?,
            b')' => self.push(Item::Tuple(Vec::new()))?,
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
                self.push(g)?;
            }
            0x93 => {
                let name = self.pop("STACK_GLOBAL")?;
                let module = self.pop("STACK_GLOBAL")?;
                let (Item::Str(module), Item::Str(name)) = (module, name) else {
                    return Err("STACK_GLOBAL needs two strings".into());
                };
                let g = Self::global(&module, &name)?;
                self.push(g)?;
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
                let item = call(g, args)?;
                self.push(item)?;
            }
            b'b' => {
                let state = self.pop("BUILD")?;
                let slot = self.top("BUILD")?;
                let obj = std::mem::replace(&mut slot.item, Item::None);
                slot.item = build(obj, state)?;
                slot.meta = Meta::LEAF;
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

//! The text layer of the `.x` reader: the `xof` header, tokens (`,` and `;` separate values like white space,
//! `//` and `#` start comments, GUIDs are dropped), the tree of data objects (templates skipped) and a reader of
//! an object's values that checks every count against the values that follow before anything is allocated.

use std::path::Path;

use super::MAX_DEPTH;
use crate::error::{DataError, Result};
use crate::skeletal::Mat;

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Tok<'a> {
    Open,
    Close,
    Word(&'a str),
    Str(&'a str),
}

/// Split the text after the header into tokens; `,` and `;` separate values like white space, `//` and `#` start
/// comments, GUIDs (`<…>`) are dropped.
fn tokenize<'a>(path: &Path, text: &'a str) -> Result<Vec<Tok<'a>>> {
    let mut toks = Vec::new();
    let bytes = text.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        let c = bytes[i];
        match c {
            b' ' | b'\t' | b'\r' | b'\n' | b',' | b';' => i += 1,
            b'#' => i = line_end(bytes, i),
            b'/' if bytes.get(i + 1) == Some(&b'/') => i = line_end(bytes, i),
            b'{' => {
                toks.push(Tok::Open);
                i += 1;
            }
            b'}' => {
                toks.push(Tok::Close);
                i += 1;
            }
            b'"' => {
                let end = text[i + 1..]
                    .find('"')
                    .ok_or_else(|| DataError::new(path, "text", format!("a string at byte {i} is not closed")))?;
                toks.push(Tok::Str(&text[i + 1..i + 1 + end]));
                i += end + 2;
            }
            b'<' => {
                let end = text[i..]
                    .find('>')
                    .ok_or_else(|| DataError::new(path, "text", format!("a GUID at byte {i} is not closed")))?;
                i += end + 1;
            }
            _ => {
                let start = i;
                while i < bytes.len() && !b" \t\r\n,;{}\"<".contains(&bytes[i]) {
                    i += 1;
                }
                toks.push(Tok::Word(&text[start..i]));
            }
        }
    }
    Ok(toks)
}

fn line_end(bytes: &[u8], from: usize) -> usize {
    bytes[from..]
        .iter()
        .position(|&b| b == b'\n')
        .map_or(bytes.len(), |p| from + p)
}

/// A data object: its template name, its own name (may be empty), values, child objects and references.
#[derive(Debug, Default)]
pub(super) struct Obj<'a> {
    pub kind: &'a str,
    pub name: &'a str,
    pub values: Vec<Tok<'a>>,
    pub children: Vec<Obj<'a>>,
    pub refs: Vec<&'a str>,
}

fn is_identifier(w: &str) -> bool {
    w.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_')
}

struct Parser<'p, 'a> {
    path: &'p Path,
    toks: Vec<Tok<'a>>,
    at: usize,
}

impl<'a> Parser<'_, 'a> {
    fn err(&self, field: &str, reason: impl Into<String>) -> DataError {
        DataError::new(self.path, field, reason)
    }

    fn peek(&self, k: usize) -> Option<Tok<'a>> {
        self.toks.get(self.at + k).copied()
    }

    /// The top-level objects, templates skipped.
    fn file(&mut self) -> Result<Vec<Obj<'a>>> {
        let mut objs = Vec::new();
        while let Some(t) = self.peek(0) {
            match t {
                Tok::Word("template") => self.template()?,
                Tok::Word(w) if is_identifier(w) => objs.push(self.object(0)?),
                other => return Err(self.err("text", format!("expected a data object, found {other:?}"))),
            }
        }
        Ok(objs)
    }

    fn template(&mut self) -> Result<()> {
        self.at += 1;
        while let Some(t) = self.peek(0) {
            self.at += 1;
            if t == Tok::Close {
                return Ok(());
            }
        }
        Err(self.err("template", "the file ends inside a template"))
    }

    /// `Type [name] { … }` starting at the current token.
    fn object(&mut self, depth: usize) -> Result<Obj<'a>> {
        if depth >= MAX_DEPTH {
            return Err(self.err("text", format!("data objects nested deeper than {MAX_DEPTH}")));
        }
        let Some(Tok::Word(kind)) = self.peek(0) else {
            return Err(self.err("text", "expected a data object"));
        };
        let mut obj = Obj { kind, ..Obj::default() };
        self.at += 1;
        if let Some(Tok::Word(name)) = self.peek(0) {
            obj.name = name;
            self.at += 1;
        }
        if self.peek(0) != Some(Tok::Open) {
            return Err(self.err(kind, "expected `{` after the object's type and name"));
        }
        self.at += 1;
        loop {
            match self.peek(0) {
                None => return Err(self.err(kind, "the file ends inside this object")),
                Some(Tok::Close) => {
                    self.at += 1;
                    return Ok(obj);
                }
                Some(Tok::Open) => match (self.peek(1), self.peek(2)) {
                    (Some(Tok::Word(name)), Some(Tok::Close)) => {
                        obj.refs.push(name);
                        self.at += 3;
                    }
                    _ => return Err(self.err(kind, "a `{` that opens neither an object nor a `{ name }` reference")),
                },
                Some(Tok::Word(w)) if is_identifier(w) => {
                    let opens = self.peek(1) == Some(Tok::Open)
                        || (matches!(self.peek(1), Some(Tok::Word(_))) && self.peek(2) == Some(Tok::Open));
                    if !opens {
                        return Err(self.err(kind, format!("`{w}` is neither a number nor a data object")));
                    }
                    obj.children.push(self.object(depth + 1)?);
                }
                Some(value) => {
                    obj.values.push(value);
                    self.at += 1;
                }
            }
        }
    }
}

/// Reads an object's values in order.
pub(super) struct Vals<'o, 'a> {
    path: &'o Path,
    obj: &'o Obj<'a>,
    at: usize,
}

impl<'o, 'a> Vals<'o, 'a> {
    pub(super) fn new(path: &'o Path, obj: &'o Obj<'a>) -> Self {
        Self { path, obj, at: 0 }
    }

    pub(super) fn err(&self, reason: impl Into<String>) -> DataError {
        let field = if self.obj.name.is_empty() {
            self.obj.kind.to_owned()
        } else {
            format!("{} {}", self.obj.kind, self.obj.name)
        };
        DataError::new(self.path, field, reason)
    }

    fn next(&mut self) -> Result<Tok<'a>> {
        let t = self
            .obj
            .values
            .get(self.at)
            .copied()
            .ok_or_else(|| self.err(format!("ends after {} values, more were expected", self.at)))?;
        self.at += 1;
        Ok(t)
    }

    fn word(&mut self) -> Result<&'a str> {
        match self.next()? {
            Tok::Word(w) => Ok(w),
            other => Err(self.err(format!("value {} is {other:?}, expected a number", self.at - 1))),
        }
    }

    pub(super) fn uint(&mut self) -> Result<u64> {
        let w = self.word()?;
        w.parse()
            .map_err(|_| self.err(format!("`{w}` is not a non-negative whole number")))
    }

    /// A vertex index below `n`; `what` names the entry in the error (built only then).
    pub(super) fn vertex(&mut self, n: usize, what: impl Fn() -> String) -> Result<usize> {
        let i = self.uint()?;
        if i >= n as u64 {
            return Err(self.err(format!("{} names vertex {i}, but the mesh has {n}", what())));
        }
        Ok(i as usize)
    }

    /// A count of items of `each` values that must still be there.
    pub(super) fn count(&mut self, each: usize) -> Result<usize> {
        let n = self.uint()?;
        let left = (self.obj.values.len() - self.at) as u64;
        if n.saturating_mul(each as u64) > left {
            return Err(self.err(format!(
                "claims {n} entries of {each} values, but only {left} values follow"
            )));
        }
        Ok(n as usize)
    }

    pub(super) fn float(&mut self) -> Result<f64> {
        let w = self.word()?;
        match w.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.err(format!("`{w}` is not a finite number"))),
        }
    }

    pub(super) fn string(&mut self) -> Result<&'a str> {
        match self.next()? {
            Tok::Str(s) => Ok(s),
            other => Err(self.err(format!("value {} is {other:?}, expected a quoted string", self.at - 1))),
        }
    }

    pub(super) fn vec3(&mut self) -> Result<[f64; 3]> {
        Ok([self.float()?, self.float()?, self.float()?])
    }

    /// A DirectX (row-vector) matrix in this crate's column convention: the transpose.
    pub(super) fn matrix(&mut self) -> Result<Mat> {
        let mut v = [0.0; 16];
        for x in &mut v {
            *x = self.float()?;
        }
        Ok(std::array::from_fn(|r| std::array::from_fn(|c| v[4 * c + r])))
    }
}

pub(super) fn header<'a>(path: &Path, text: &'a str) -> Result<&'a str> {
    let field = "header";
    let b = text.as_bytes();
    if b.len() < 16 || !b.starts_with(b"xof ") {
        return Err(DataError::new(path, field, "not a DirectX .x file (no `xof ` header)"));
    }
    match &b[8..12] {
        b"txt " => {}
        b"bin " => {
            return Err(DataError::new(
                path,
                field,
                "a binary .x file: only the text form is read (re-export it as text)",
            ));
        }
        b"tzip" | b"bzip" => {
            return Err(DataError::new(
                path,
                field,
                "a compressed .x file: only the text form is read (re-export it as text)",
            ));
        }
        other => {
            return Err(DataError::new(
                path,
                field,
                format!("unknown .x format `{}`", String::from_utf8_lossy(other)),
            ));
        }
    }
    if !matches!(&b[12..16], b"0032" | b"0064") {
        return Err(DataError::new(
            path,
            field,
            format!(
                "float size `{}` is neither 0032 nor 0064",
                String::from_utf8_lossy(&b[12..16])
            ),
        ));
    }
    text.get(16..)
        .ok_or_else(|| DataError::new(path, field, "the header is not followed by text"))
}

/// The data objects of a text `.x` file (its header checked, templates skipped).
pub(super) fn objects<'a>(path: &Path, text: &'a str) -> Result<Vec<Obj<'a>>> {
    let mut parser = Parser {
        path,
        toks: tokenize(path, header(path, text)?)?,
        at: 0,
    };
    parser.file()
}

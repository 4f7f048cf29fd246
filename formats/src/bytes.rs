//! A bounds-checked little-endian reader over a file's bytes, shared by the binary game formats (IQM, MD2, MD3,
//! 0 A.D. PMD/PSA, `.anime`, FBX).
//!
//! Every count a file claims goes through [`Bytes::check_count`] (count × element size against the bytes that
//! remain, or against a named limit) before anything is allocated from it, so memory stays bounded by the file's
//! length. Errors name the file and the field.

use crate::error::{DataError, Result};

/// A cursor over `data`; `path` names the file in errors.
pub struct Bytes<'a> {
    path: &'a str,
    data: &'a [u8],
    pos: usize,
}

impl<'a> Bytes<'a> {
    pub fn new(path: &'a str, data: &'a [u8]) -> Self {
        Self { path, data, pos: 0 }
    }

    /// An error about `field` in this file.
    pub fn err(&self, field: impl Into<String>, reason: impl Into<String>) -> DataError {
        DataError::new(self.path, field, reason)
    }

    pub fn len(&self) -> usize {
        self.data.len()
    }

    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    pub fn pos(&self) -> usize {
        self.pos
    }

    pub fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    /// Move to absolute offset `ofs` (the file's offset field `field`).
    pub fn seek(&mut self, ofs: usize, field: &str) -> Result<()> {
        if ofs > self.data.len() {
            return Err(self.err(
                field,
                format!("offset {ofs} lies past the end of the {}-byte file", self.data.len()),
            ));
        }
        self.pos = ofs;
        Ok(())
    }

    /// The next `n` bytes.
    pub fn take(&mut self, n: usize, field: &str) -> Result<&'a [u8]> {
        if n > self.remaining() {
            return Err(self.err(
                field,
                format!(
                    "needs {n} bytes at offset {} but the file ends after {}",
                    self.pos,
                    self.remaining()
                ),
            ));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    pub fn u8(&mut self, field: &str) -> Result<u8> {
        Ok(self.take(1, field)?[0])
    }

    pub fn u16(&mut self, field: &str) -> Result<u16> {
        Ok(u16::from_le_bytes(self.take(2, field)?.try_into().expect("2 bytes")))
    }

    pub fn i16(&mut self, field: &str) -> Result<i16> {
        Ok(i16::from_le_bytes(self.take(2, field)?.try_into().expect("2 bytes")))
    }

    pub fn u32(&mut self, field: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.take(4, field)?.try_into().expect("4 bytes")))
    }

    pub fn i32(&mut self, field: &str) -> Result<i32> {
        Ok(i32::from_le_bytes(self.take(4, field)?.try_into().expect("4 bytes")))
    }

    pub fn u64(&mut self, field: &str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.take(8, field)?.try_into().expect("8 bytes")))
    }

    /// A u32 count or offset as usize.
    pub fn usize(&mut self, field: &str) -> Result<usize> {
        Ok(self.u32(field)? as usize)
    }

    /// A signed 32-bit count that must not be negative.
    pub fn count_i32(&mut self, field: &str) -> Result<usize> {
        let v = self.i32(field)?;
        usize::try_from(v).map_err(|_| self.err(field, format!("negative count {v}")))
    }

    /// A finite f32.
    pub fn f32(&mut self, field: &str) -> Result<f32> {
        let v = f32::from_le_bytes(self.take(4, field)?.try_into().expect("4 bytes"));
        if !v.is_finite() {
            return Err(self.err(field, format!("non-finite value {v} at offset {}", self.pos - 4)));
        }
        Ok(v)
    }

    pub fn f32s<const N: usize>(&mut self, field: &str) -> Result<[f32; N]> {
        let mut out = [0.0; N];
        for x in &mut out {
            *x = self.f32(field)?;
        }
        Ok(out)
    }

    /// Check that `count` elements of `size` bytes fit in what remains of the file from the current position;
    /// returns `count` for allocation.
    pub fn check_count(&self, count: usize, size: usize, field: &str) -> Result<usize> {
        self.check_count_at(self.pos, count, size, field)
    }

    /// Check that `count` elements of `size` bytes starting at absolute offset `ofs` fit inside the file.
    pub fn check_count_at(&self, ofs: usize, count: usize, size: usize, field: &str) -> Result<usize> {
        let need = count.checked_mul(size).and_then(|b| b.checked_add(ofs));
        match need {
            Some(end) if end <= self.data.len() => Ok(count),
            _ => Err(self.err(
                field,
                format!(
                    "claims {count} elements of {size} bytes at offset {ofs}, more than the {}-byte file holds",
                    self.data.len()
                ),
            )),
        }
    }

    /// A fixed-size, NUL-padded name.
    pub fn name(&mut self, n: usize, field: &str) -> Result<String> {
        let raw = self.take(n, field)?;
        let end = raw.iter().position(|&b| b == 0).unwrap_or(n);
        Ok(String::from_utf8_lossy(&raw[..end]).into_owned())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_little_endian_and_refuses_overruns() {
        let data = [1u8, 0, 0, 0, 0xff, 0xff, 0, 0, 0x80];
        let mut b = Bytes::new("f.bin", &data);
        assert_eq!(b.u32("a").unwrap(), 1);
        assert_eq!(b.i16("b").unwrap(), -1);
        let e = b.u32("c").unwrap_err();
        assert_eq!((e.path.as_str(), e.field.as_str()), ("f.bin", "c"));
        assert!(e.reason.contains("needs 4 bytes"), "{e}");
        // A count the file cannot hold is refused before any allocation.
        let e = b.check_count(usize::MAX / 2, 12, "num_vertexes").unwrap_err();
        assert!(e.reason.contains("more than the 9-byte file"), "{e}");
        assert_eq!(b.check_count(1, 3, "x").unwrap(), 1);
        assert!(b.seek(10, "ofs").is_err());
    }

    #[test]
    fn rejects_non_finite_floats() {
        let data = f32::NAN.to_le_bytes();
        let e = Bytes::new("f", &data).f32("scale").unwrap_err();
        assert!(e.reason.contains("non-finite"), "{e}");
    }
}

//! The one error type of the data crate: every failure names the file, the field and the reason.

use std::fmt;
use std::path::Path;

/// A data error: `path: field: reason`. `field` is the dictionary key, glTF accessor, OBJ line, … that was wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DataError {
    /// File (or clip id when no file is involved).
    pub path: String,
    /// The field, key or location inside the file.
    pub field: String,
    /// Why it is rejected.
    pub reason: String,
}

impl DataError {
    pub fn new(path: impl AsRef<Path>, field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self {
            path: path.as_ref().display().to_string(),
            field: field.into(),
            reason: reason.into(),
        }
    }

    /// Wrap an IO error on `path`.
    pub fn io(path: impl AsRef<Path>, err: std::io::Error) -> Self {
        Self::new(path, "file", err.to_string())
    }

    /// The same error reported against another path (e.g. when a reader works on bytes and the caller knows the file).
    pub fn at(mut self, path: impl AsRef<Path>) -> Self {
        self.path = path.as_ref().display().to_string();
        self
    }
}

impl fmt::Display for DataError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}: {}", self.path, self.field, self.reason)
    }
}

impl std::error::Error for DataError {}

pub type Result<T, E = DataError> = std::result::Result<T, E>;

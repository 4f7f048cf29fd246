//! Writing a file so that nothing is lost when a run is killed: the one `write_atomic` every crate uses.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use crate::error::{DataError, Result};

/// Writes `bytes` to `path` so that a reader sees the old file or the new one, never a torn one, and a crash right
/// after the call leaves the new one on disk: the bytes go to a hidden sibling `.NAME.tmp`, which is synced to disk
/// and renamed over `path`; the folder is then synced so the rename itself lasts. The sibling is removed when a
/// step fails.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |out, tmp| out.write_all(bytes).map_err(|e| DataError::io(tmp, e)))
}

/// [`write_atomic`] of what `write` streams into the (buffered) hidden sibling, whose path it is given for its
/// errors: for files too large to build in memory first. Nothing is at `path` until `write` has succeeded.
pub fn write_atomic_with(path: &Path, write: impl FnOnce(&mut BufWriter<File>, &Path) -> Result<()>) -> Result<()> {
    let name = path
        .file_name()
        .ok_or_else(|| DataError::new(path, "file", "path has no file name"))?;
    let tmp = path.with_file_name(format!(".{}.tmp", name.to_string_lossy()));
    let written = (|| {
        let mut out = BufWriter::new(File::create(&tmp).map_err(|e| DataError::io(&tmp, e))?);
        write(&mut out, &tmp)?;
        let file = out.into_inner().map_err(|e| DataError::io(&tmp, e.into_error()))?;
        file.sync_all().map_err(|e| DataError::io(&tmp, e))?;
        std::fs::rename(&tmp, path).map_err(|e| DataError::io(path, e))
    })();
    if written.is_err() {
        // Best effort: the error that matters is the one above.
        let _ = std::fs::remove_file(&tmp);
        return written;
    }
    sync_parent(path);
    Ok(())
}

/// Syncs the folder holding `path`, so a rename into it survives a power cut. Best effort: some platforms cannot
/// open a folder for syncing, and the file itself is already on disk.
fn sync_parent(path: &Path) {
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if let Ok(dir) = File::open(parent) {
        let _ = dir.sync_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_the_file_and_leaves_no_sibling() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.txt");
        write_atomic(&path, b"old").unwrap();
        write_atomic(&path, b"new bytes").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new bytes");
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("a.txt")]);
    }

    #[test]
    fn a_failed_write_keeps_the_old_file_and_names_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b.txt");
        write_atomic(&path, b"kept").unwrap();
        // A folder where the temporary sibling would go makes the write fail before anything is renamed.
        std::fs::create_dir(dir.path().join(".b.txt.tmp")).unwrap();
        let err = write_atomic(&path, b"lost").unwrap_err();
        assert!(err.to_string().contains(".b.txt.tmp"), "{err}");
        assert_eq!(std::fs::read(&path).unwrap(), b"kept");
        let no_name = write_atomic(Path::new("/"), b"x").unwrap_err();
        assert_eq!(no_name.field, "file");
    }
}

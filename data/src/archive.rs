//! Extracting chosen members of zip archives (`.zip`, `.pk3`) into a folder, refusing members whose path would
//! land outside it.
//!
//! A member is written only when its name is a relative path of plain components (no `..`, no root, no drive,
//! no backslash) and its size fits [`MAX_MEMBER_BYTES`]; anything else is listed as refused, never written.

use std::io::Read;
use std::path::{Component, Path, PathBuf};

use crate::error::{DataError, Result};

/// Largest member extracted, in bytes (uncompressed).
pub const MAX_MEMBER_BYTES: u64 = 256 << 20;

/// What an extraction did.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Extracted {
    /// Files written (paths under the output folder).
    pub written: Vec<PathBuf>,
    /// Members refused, with the reason.
    pub refused: Vec<(String, String)>,
}

/// `name` as a relative path of plain components, or why not.
pub fn safe_member_path(name: &str) -> std::result::Result<PathBuf, String> {
    if name.contains('\\') {
        return Err("contains a backslash".into());
    }
    let p = Path::new(name);
    let mut out = PathBuf::new();
    for c in p.components() {
        match c {
            Component::Normal(x) => out.push(x),
            Component::CurDir => {}
            Component::ParentDir => return Err("escapes the output folder (`..`)".into()),
            Component::RootDir | Component::Prefix(_) => return Err("is an absolute path".into()),
        }
    }
    if out.as_os_str().is_empty() {
        return Err("is empty".into());
    }
    Ok(out)
}

/// Extract the members of `archive` for which `choose(name)` gives a relative destination, into `out`. The
/// destination goes through the same checks as the member name.
pub fn extract(archive: &Path, out: &Path, choose: impl Fn(&str) -> Option<String>) -> Result<Extracted> {
    let file = std::fs::File::open(archive).map_err(|e| DataError::io(archive, e))?;
    let mut zip = zip::ZipArchive::new(file).map_err(|e| DataError::new(archive, "zip", e.to_string()))?;
    let mut done = Extracted::default();
    for i in 0..zip.len() {
        let mut member = zip
            .by_index(i)
            .map_err(|e| DataError::new(archive, format!("member {i}"), e.to_string()))?;
        let name = member.name().to_owned();
        if member.is_dir() {
            continue;
        }
        if let Err(why) = safe_member_path(&name) {
            done.refused.push((name, why));
            continue;
        }
        let Some(dest) = choose(&name) else { continue };
        let rel = match safe_member_path(&dest) {
            Ok(r) => r,
            Err(why) => {
                done.refused.push((name, format!("destination {dest:?} {why}")));
                continue;
            }
        };
        if member.size() > MAX_MEMBER_BYTES {
            done.refused
                .push((name, format!("{} bytes, more than {MAX_MEMBER_BYTES}", member.size())));
            continue;
        }
        let mut bytes = Vec::new();
        (&mut member)
            .take(MAX_MEMBER_BYTES + 1)
            .read_to_end(&mut bytes)
            .map_err(|e| DataError::new(archive, &name, e.to_string()))?;
        if bytes.len() as u64 > MAX_MEMBER_BYTES {
            done.refused
                .push((name, format!("inflates past {MAX_MEMBER_BYTES} bytes")));
            continue;
        }
        let path = out.join(rel);
        if let Some(d) = path.parent() {
            std::fs::create_dir_all(d).map_err(|e| DataError::io(d, e))?;
        }
        std::fs::write(&path, &bytes).map_err(|e| DataError::io(&path, e))?;
        done.written.push(path);
    }
    Ok(done)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn make_zip(path: &Path, members: &[(&str, &[u8])]) {
        let mut w = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
        for (name, data) in members {
            w.start_file(*name, zip::write::SimpleFileOptions::default()).unwrap();
            w.write_all(data).unwrap();
        }
        w.finish().unwrap();
    }

    #[test]
    fn refuses_members_that_escape_and_extracts_the_rest() {
        let dir = tempfile::tempdir().unwrap();
        let pk3 = dir.path().join("models.pk3");
        make_zip(
            &pk3,
            &[
                ("models/a/body.md2", b"x"),
                ("../../evil.md2", b"y"),
                ("/abs/evil.md2", b"z"),
                ("models/skip.png", b"p"),
            ],
        );
        let out = dir.path().join("out");
        let got = extract(&pk3, &out, |n| n.ends_with(".md2").then(|| n.to_owned())).unwrap();
        assert_eq!(got.written, vec![out.join("models/a/body.md2")]);
        let refused: Vec<&str> = got.refused.iter().map(|r| r.0.as_str()).collect();
        assert_eq!(refused, ["../../evil.md2", "/abs/evil.md2"]);
        assert!(got.refused[0].1.contains("escapes"));
        assert!(!dir.path().join("evil.md2").exists() && !out.join("models/skip.png").exists());
        // A destination that escapes is refused too.
        let got = extract(&pk3, &out, |n| n.ends_with("body.md2").then(|| "../x.md2".into())).unwrap();
        assert!(got.written.is_empty() && got.refused.iter().any(|r| r.1.contains("destination")));
        assert_eq!(safe_member_path("a\\..\\b").unwrap_err(), "contains a backslash");
    }
}

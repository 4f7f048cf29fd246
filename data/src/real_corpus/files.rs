//! Packages whose animated files stand alone ([`ANIMATED_FILES`]): each file with a take is one staged asset (with
//! the buffers a glTF names, and the XML files that name a SuperTuxKart mesh).

use std::path::Path;

use super::{Dep5, StageReport, copy, files_with, rel, walk_dirs, write_provenance};
use crate::caption;
use crate::error::{DataError, Result};

/// Packages staged file by file: (package, folder under the package root, extensions of the animated files).
pub const ANIMATED_FILES: &[(&str, &str, &[&str])] = &[
    (
        "gambas3-examples",
        "usr/share/doc/gambas3-examples/examples/OpenGL",
        &["md2"],
    ),
    ("blobandconquer-data", "usr/share/games/blobAndConquer/gfx", &["md2"]),
    (
        "castle-game-engine-doc",
        "usr/share/doc/castle-game-engine-doc/examples",
        &["gltf", "glb"],
    ),
    ("supertuxkart-data", "usr/share/games/supertuxkart/data", &["spm"]),
];

/// Every file of `exts` under a package's `root` that has at least one take, one folder per file stem (a stem met
/// again — the same example copied into several folders — is staged once, so one object cannot land in both
/// splits), a glTF with the `.bin` buffers beside it that it names. A file that cannot be listed is reported, not
/// staged.
pub(super) struct AnimatedFiles {
    pub(super) root: &'static str,
    pub(super) exts: &'static [&'static str],
}

impl AnimatedFiles {
    pub(super) fn stage(
        &self,
        dir: &Path,
        dest: &Path,
        package: &str,
        c: &Dep5,
        report: &mut StageReport,
    ) -> Result<usize> {
        let root = dir.join(self.root);
        if !root.is_dir() {
            return Ok(0);
        }
        let mut folders = Vec::new();
        walk_dirs(&root, &mut folders);
        let mut n = 0;
        for (folder, file) in folders.iter().flat_map(|d| {
            self.exts
                .iter()
                .flat_map(move |e| files_with(d, e).into_iter().map(move |f| (d, f)))
        }) {
            match crate::formats::list_takes(&file) {
                Ok(Some(takes)) if !takes.is_empty() => {}
                Ok(_) => continue,
                Err(e) => {
                    report.refused.push((rel(dir, &file), e.to_string()));
                    continue;
                }
            }
            let stem = crate::formats::skeletal::stem(&file);
            let to = dest.join(&stem);
            if to.exists() {
                continue;
            }
            copy(&file, &to.join(file.file_name().unwrap_or_default()))?;
            // A `.bin` beside it is its buffer only when its text names it (one with its buffers inside, as a
            // `data:` URI, leaves a stale `.bin` that would be read as a clip of its own).
            let buffers = files_with(folder, "bin");
            if !buffers.is_empty() {
                let bytes = std::fs::read(&file).map_err(|e| DataError::io(&file, e))?;
                let text = String::from_utf8_lossy(&bytes);
                for buffer in buffers {
                    let name = buffer.file_name().unwrap_or_default().to_string_lossy().into_owned();
                    if text.contains(&format!("\"{name}\"")) {
                        copy(&buffer, &to.join(&name))?;
                    }
                }
            }
            // The game's XML beside a SuperTuxKart mesh says which frame ranges it plays (`formats::spm`).
            if file.extension().is_some_and(|e| e.eq_ignore_ascii_case("spm")) {
                let name = file.file_name().unwrap_or_default().to_string_lossy().into_owned();
                for xml in files_with(folder, "xml") {
                    let bytes = std::fs::read(&xml).map_err(|e| DataError::io(&xml, e))?;
                    if String::from_utf8_lossy(&bytes).contains(&name) {
                        copy(&xml, &to.join(xml.file_name().unwrap_or_default()))?;
                    }
                }
            }
            let asset = caption::asset_words(&stem).join(" ");
            write_provenance(&to, package, &c.licence(&rel(dir, &file)), asset.trim())?;
            n += 1;
        }
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use base64::Engine;

    use super::super::stage;
    use crate::Clip;
    use crate::store::PROVENANCE_FILE;

    #[test]
    fn each_animated_file_is_one_asset_once_with_its_own_buffer() {
        let dir = tempfile::tempdir().unwrap();
        let examples = dir
            .path()
            .join("in/castle-game-engine-doc/usr/share/doc/castle-game-engine-doc/examples");
        let v = (0..3)
            .flat_map(|f| [[0.1 * f as f32, 0.0, 0.0], [1.0, 0.3, 0.0], [0.0, 1.0, -2.5]])
            .collect();
        let clip = Clip::new("gears", v, 3, 3, vec![[0, 1, 2]], "", "gears.gltf").unwrap();
        for copy in ["a", "b"] {
            // The same example in two folders: staged once.
            let folder = examples.join(copy);
            std::fs::create_dir_all(&folder).unwrap();
            crate::formats::write_clip(&folder.join("gears.gltf"), &clip).unwrap();
        }
        // `a/gears.gltf` keeps its buffer in `gears.bin`; `a/road.bin` is not its, and `b/gears.gltf` keeps its
        // buffer inside.
        let a = examples.join("a/gears.gltf");
        let mut json: serde_json::Value = serde_json::from_slice(&std::fs::read(&a).unwrap()).unwrap();
        let uri = json["buffers"][0]["uri"].as_str().unwrap().to_owned();
        let data = base64::engine::general_purpose::STANDARD
            .decode(uri.split_once(',').unwrap().1)
            .unwrap();
        std::fs::write(examples.join("a/gears.bin"), data).unwrap();
        json["buffers"][0]["uri"] = "gears.bin".into();
        std::fs::write(&a, serde_json::to_vec(&json).unwrap()).unwrap();
        std::fs::write(examples.join("a/road.bin"), b"another model's buffer").unwrap();
        std::fs::write(examples.join("b/gears.bin"), b"a stale buffer").unwrap();
        std::fs::write(examples.join("a/broken.gltf"), b"{ not json").unwrap();
        let out = dir.path().join("out");
        let report = stage(&dir.path().join("in"), &out).unwrap();
        assert_eq!(report.assets["castle-game-engine-doc"], 1);
        let staged = out.join("castle-game-engine-doc/gears");
        let mut names: Vec<String> = std::fs::read_dir(&staged)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, [PROVENANCE_FILE, "gears.bin", "gears.gltf"]);
        let takes = crate::formats::list_takes(&staged.join("gears.gltf")).unwrap().unwrap();
        assert_eq!(takes.len(), 1, "the staged copy reads its buffer");
        assert_eq!(report.refused.len(), 1, "{:?}", report.refused);
        assert!(report.refused[0].0.ends_with("broken.gltf"), "{:?}", report.refused);
    }
}

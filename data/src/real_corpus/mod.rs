//! The staging step of the real corpus: from Debian packages unpacked with `dpkg -x` (one folder per package)
//! to one folder per animated asset, holding the mesh, its animation files and an [`PROVENANCE_FILE`] naming the
//! package, the licence (from the package's machine-readable `copyright`) and a readable asset name. `data
//! import` then turns every take into clips (`scripts/real_corpus.sh` runs both).
//!
//! Per package (anything else under the input folder is ignored):
//! - `redeclipse-data`: the male and female player `.iqm` meshes with the animation-only `.iqm` files of
//!   `actors/player`, and every folder holding a `.md5mesh` with its `.md5anim` files;
//! - `0ad-data`: from `public.zip`, every actor XML under `art/actors/fauna` and `art/actors/units` (with the
//!   variant files it names): its first skeletal mesh and its animations (`*.dae.cached.pmd/.psa`); actors
//!   share meshes (horses of many coats, units of many civilisations), so each mesh is staged once, with the
//!   animations of the first actor naming it; a unit mesh keeps at most [`MAX_UNIT_ANIMS`] animations, and at
//!   most [`MAX_UNIT_MESHES`] unit meshes are staged;
//! - `ufoai-data`: from `base/0models.pk3`, every `.md2` model with an `.anm` animation table beside it;
//! - `assimp-testmodels`: the animated `.iqm` sample and the two skinned, animated DirectX `.x` files. Its MD2
//!   models are never staged;
//! - `cube2-data` (Cube 2: Sauerbraten): every model folder with a mesh and its animation files (`.iqm` with
//!   animation-only `.iqm`, `.md5mesh` with `.md5anim`): the snoutx10k player, the Frankie squirrel,
//!   first-person hands and guns, a flag;
//! - `minetest-data` and `minetest-mod-*`: every `.b3d` under `usr/share/games/minetest` that has node keys (the
//!   player character, mobs), one folder per file, the asset named after the file;
//! - `minetest-mod-homedecor` is one of those mods (its desk fan turns);
//! - [`ANIMATED_FILES`]: packages whose animated files stand alone, each file with at least one take staged as
//!   its own folder (a glTF with its buffer): `gambas3-examples` (seven Quake II-style MD2 monsters and a weapon of
//!   its OpenGL example), `blobandconquer-data` (an MD2 spider), `castle-game-engine-doc` (the glTF characters,
//!   cars and gears of the engine's examples), `supertuxkart-data` (the karts with their drivers, the track
//!   library's characters and animals, cutscene actors and animated items, `.spm` with the XML files that give
//!   their frame ranges);
//! - `redeclipse-data` and `assimp-testmodels` (folder [`MOCAP_FOLDER`]): the `.bvh` motion capture of
//!   `assimp-testmodels` beside copies of the Red Eclipse player meshes, retargeted at import
//!   ([`crate::formats::bvh`]); `cube2-data` and `assimp-testmodels` (folder [`CUBE2_MOCAP_FOLDER`]): the same
//!   beside a copy of Cube 2's snoutx10k player.
//!
//! Packages held out for evaluation (OpenArena, MegaGlest, Nexuiz, Xonotic) are refused by name.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::archive;
use crate::caption;
use crate::error::{DataError, Result};
use crate::store::PROVENANCE_FILE;

mod dep5;
mod files;
pub use dep5::Dep5;
pub use files::ANIMATED_FILES;
use files::AnimatedFiles;

/// Unit (human) body meshes staged from 0 A.D. at most.
pub const MAX_UNIT_MESHES: usize = 40;
/// Animations staged per 0 A.D. unit mesh at most.
pub const MAX_UNIT_ANIMS: usize = 12;

/// Package name prefixes never staged (the held-out evaluation is drawn from them).
pub const HELD_OUT: &[&str] = &["openarena", "megaglest", "nexuiz", "xonotic", "qt3d"];

/// What staging did per package.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct StageReport {
    /// Package → asset folders staged.
    pub assets: BTreeMap<String, usize>,
    /// Archive members refused (path escapes, sizes).
    pub refused: Vec<(String, String)>,
}

/// Stage every known package under `extracted` (`extracted/<package>/usr/...`) into `out`.
pub fn stage(extracted: &Path, out: &Path) -> Result<StageReport> {
    let mut report = StageReport::default();
    let mut entries: Vec<PathBuf> = std::fs::read_dir(extracted)
        .map_err(|e| DataError::io(extracted, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    entries.sort();
    for dir in entries {
        let package = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if HELD_OUT.iter().any(|h| package.starts_with(h)) {
            return Err(DataError::new(
                &dir,
                "package",
                format!("{package} is held out for evaluation and must not enter a training store"),
            ));
        }
        let copyright = Dep5::read(&dir.join(format!("usr/share/doc/{package}/copyright")));
        let dest = out.join(&package);
        let n = match package.as_str() {
            "redeclipse-data" => stage_redeclipse(&dir, &dest, &package, &copyright)?,
            "0ad-data" => stage_0ad(&dir, &dest, &package, &copyright, &mut report)?,
            "ufoai-data" => stage_ufoai(&dir, &dest, &package, &copyright, &mut report)?,
            "assimp-testmodels" => stage_assimp(&dir, &dest, &package, &copyright)?,
            "cube2-data" => stage_cube2(&dir, &dest, &package, &copyright)?,
            p if p == "minetest-data" || p.starts_with("minetest-mod-") => {
                stage_minetest(&dir, &dest, &package, &copyright, &mut report)?
            }
            p => match ANIMATED_FILES.iter().find(|(name, _, _)| *name == p) {
                Some(&(_, root, exts)) => {
                    let files = AnimatedFiles { root, exts };
                    files.stage(&dir, &dest, &package, &copyright, &mut report)?
                }
                None => continue,
            },
        };
        report.assets.insert(package, n);
    }
    let (re, assimp) = (extracted.join("redeclipse-data"), extracted.join("assimp-testmodels"));
    if re.is_dir() && assimp.is_dir() {
        let n = stage_mocap(&re, &assimp, &out.join(MOCAP_FOLDER))?;
        report.assets.insert(MOCAP_FOLDER.to_owned(), n);
    }
    let cube2 = extracted.join("cube2-data");
    if cube2.is_dir() && assimp.is_dir() {
        let n = stage_cube2_mocap(&cube2, &assimp, &out.join(CUBE2_MOCAP_FOLDER))?;
        report.assets.insert(CUBE2_MOCAP_FOLDER.to_owned(), n);
    }
    Ok(report)
}

/// Staging folder (and `source_package`) of the motion capture retargeted onto the Red Eclipse players.
pub const MOCAP_FOLDER: &str = "redeclipse-data+assimp-testmodels";

/// Staging folder (and `source_package`) of the motion capture retargeted onto Cube 2's snoutx10k player.
pub const CUBE2_MOCAP_FOLDER: &str = "cube2-data+assimp-testmodels";

/// The BVH files of `assimp-testmodels` beside a copy of Cube 2's snoutx10k player mesh, in a folder whose last
/// names match the player's own staging (`cube2-data/snoutx10k/`), so that its clips share the player's object
/// uid and split. The licence records both sources.
fn stage_cube2_mocap(cube2: &Path, assimp: &Path, dest: &Path) -> Result<usize> {
    let motions = files_with(&assimp.join("usr/share/assimp/models/BVH"), "bvh");
    let mesh = cube2.join("usr/share/games/cube2/packages/models/snoutx10k/snoutx10k.iqm");
    if motions.is_empty() || !mesh.is_file() {
        return Ok(0);
    }
    let to = dest.join("cube2-data/snoutx10k");
    copy(&mesh, &to.join("snoutx10k.iqm"))?;
    for m in &motions {
        copy(m, &to.join(m.file_name().expect("file")))?;
    }
    let licence = format!(
        "{} (mesh) AND {} (motion)",
        Dep5::read(&cube2.join("usr/share/doc/cube2-data/copyright")).licence(&rel(cube2, &mesh)),
        Dep5::read(&assimp.join("usr/share/doc/assimp-testmodels/copyright")).licence(&rel(assimp, &motions[0]))
    );
    write_provenance(&to, CUBE2_MOCAP_FOLDER, &licence, "snout player")?;
    Ok(1)
}

/// The CMU and Biovision BVH files of `assimp-testmodels` beside copies of the Red Eclipse player meshes, in
/// folders whose last two names match the players' own staging (`player_male/male/`), so that their clips share
/// the players' object uid and split. The licence records both sources.
fn stage_mocap(re: &Path, assimp: &Path, dest: &Path) -> Result<usize> {
    let bvh_dir = assimp.join("usr/share/assimp/models/BVH");
    let motions = files_with(&bvh_dir, "bvh");
    let player = re.join("usr/share/games/redeclipse/data/actors/player");
    if motions.is_empty() {
        return Ok(0);
    }
    let (c_re, c_assimp) = (
        Dep5::read(&re.join("usr/share/doc/redeclipse-data/copyright")),
        Dep5::read(&assimp.join("usr/share/doc/assimp-testmodels/copyright")),
    );
    let mut n = 0;
    for who in ["male", "female"] {
        let mesh = player.join(who).join(format!("RE_Player_{who}.iqm"));
        if !mesh.is_file() {
            continue;
        }
        let to = dest.join(format!("player_{who}")).join(who);
        copy(&mesh, &to.join(mesh.file_name().expect("file")))?;
        for m in &motions {
            copy(m, &to.join(m.file_name().expect("file")))?;
        }
        let licence = format!(
            "{} (mesh) AND {} (motion)",
            c_re.licence(&rel(re, &mesh)),
            c_assimp.licence(&rel(assimp, &motions[0]))
        );
        write_provenance(&to, MOCAP_FOLDER, &licence, &format!("{who} player"))?;
        n += 1;
    }
    Ok(n)
}

fn write_provenance(dir: &Path, package: &str, licence: &str, asset: &str) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| DataError::io(dir, e))?;
    let json = serde_json::json!({"source_package": package, "licence": licence, "asset": asset});
    let path = dir.join(PROVENANCE_FILE);
    std::fs::write(&path, json.to_string()).map_err(|e| DataError::io(&path, e))
}

fn copy(from: &Path, to: &Path) -> Result<()> {
    if let Some(d) = to.parent() {
        std::fs::create_dir_all(d).map_err(|e| DataError::io(d, e))?;
    }
    std::fs::copy(from, to).map_err(|e| DataError::io(from, e))?;
    Ok(())
}

fn files_with(dir: &Path, ext: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| rd.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    v.retain(|p| p.is_file() && p.extension().is_some_and(|e| e.eq_ignore_ascii_case(ext)));
    v.sort();
    v
}

fn walk_dirs(dir: &Path, out: &mut Vec<PathBuf>) {
    out.push(dir.to_path_buf());
    let mut subs: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_dir())
                .collect()
        })
        .unwrap_or_default();
    subs.sort();
    for s in subs {
        walk_dirs(&s, out);
    }
}

fn rel(root: &Path, p: &Path) -> String {
    p.strip_prefix(root).unwrap_or(p).to_string_lossy().into_owned()
}

fn stage_redeclipse(dir: &Path, dest: &Path, package: &str, c: &Dep5) -> Result<usize> {
    let data = dir.join("usr/share/games/redeclipse/data");
    let mut n = 0;
    let player = data.join("actors/player");
    for who in ["male", "female"] {
        let mesh = player.join(who).join(format!("RE_Player_{who}.iqm"));
        if !mesh.is_file() {
            continue;
        }
        let to = dest.join(format!("player_{who}"));
        copy(&mesh, &to.join(who).join(mesh.file_name().expect("file")))?;
        for anim in files_with(&player, "iqm") {
            copy(&anim, &to.join(anim.file_name().expect("file")))?;
        }
        write_provenance(&to, package, &c.licence(&rel(dir, &mesh)), &format!("{who} player"))?;
        n += 1;
    }
    Ok(n + stage_model_folders(dir, &data, dest, package, c)?)
}

/// Every folder under `root` holding a mesh with its animation files — `.md5mesh` with `.md5anim`, or two or more
/// `.iqm` (a mesh and animation-only files) — staged whole as `dest/<path below root, '/' → '_'>`.
fn stage_model_folders(dir: &Path, root: &Path, dest: &Path, package: &str, c: &Dep5) -> Result<usize> {
    let mut dirs = Vec::new();
    walk_dirs(root, &mut dirs);
    let mut n = 0;
    for d in dirs {
        let (anims, meshes, iqms) = (
            files_with(&d, "md5anim"),
            files_with(&d, "md5mesh"),
            files_with(&d, "iqm"),
        );
        // The files to copy and the mesh that names the asset.
        let (files, mesh): (Vec<&PathBuf>, &PathBuf) = if !anims.is_empty() && !meshes.is_empty() {
            (meshes.iter().chain(&anims).collect(), &meshes[0])
        } else if let (true, Some(mesh)) = (iqms.len() >= 2, iqms.iter().find(|f| crate::formats::is_source(f))) {
            (iqms.iter().collect(), mesh)
        } else {
            continue;
        };
        let name = rel(root, &d).replace('/', "_");
        let to = dest.join(&name);
        for f in files {
            copy(f, &to.join(f.file_name().expect("file")))?;
        }
        let asset = caption::asset_of_path(mesh);
        write_provenance(&to, package, &c.licence(&rel(dir, mesh)), &asset)?;
        n += 1;
    }
    Ok(n)
}

/// Cube 2: Sauerbraten's model folders ([`stage_model_folders`] under `packages/models`): the snoutx10k player
/// and the Frankie squirrel with their moves, first-person hands and guns, a waving flag.
fn stage_cube2(dir: &Path, dest: &Path, package: &str, c: &Dep5) -> Result<usize> {
    let models = dir.join("usr/share/games/cube2/packages/models");
    if !models.is_dir() {
        return Ok(0);
    }
    stage_model_folders(dir, &models, dest, package, c)
}

/// Mesh and animation files named by an 0 A.D. actor (following `variant file=` references).
fn actor_refs(
    zip_names: &BTreeSet<String>,
    read: &mut dyn FnMut(&str) -> Option<String>,
    actor: &str,
) -> (Vec<String>, Vec<String>) {
    let (mut meshes, mut anims) = (Vec::new(), Vec::new());
    let mut queue = vec![actor.to_owned()];
    let mut seen = BTreeSet::new();
    while let Some(file) = queue.pop() {
        if !seen.insert(file.clone()) || seen.len() > 32 {
            continue;
        }
        let Some(text) = read(&file) else { continue };
        let Ok(doc) = roxmltree::Document::parse(&text) else {
            continue;
        };
        for node in doc.descendants() {
            match node.tag_name().name() {
                "mesh" => meshes.extend(node.text().map(|t| t.trim().to_owned())),
                "animation" => anims.extend(node.attribute("file").map(str::to_owned)),
                "variant" => {
                    if let Some(f) = node.attribute("file") {
                        let v = format!("art/variants/{f}");
                        if zip_names.contains(&v) {
                            queue.push(v);
                        }
                    }
                }
                _ => {}
            }
        }
    }
    anims.sort();
    anims.dedup();
    (meshes, anims)
}

fn stage_0ad(dir: &Path, dest: &Path, package: &str, c: &Dep5, report: &mut StageReport) -> Result<usize> {
    let zip_path = dir.join("usr/share/games/0ad/mods/public/public.zip");
    if !zip_path.is_file() {
        return Ok(0);
    }
    let file = std::fs::File::open(&zip_path).map_err(|e| DataError::io(&zip_path, e))?;
    let mut zip = zip::ZipArchive::new(file).map_err(|e| DataError::new(&zip_path, "zip", e.to_string()))?;
    let names: BTreeSet<String> = zip.file_names().map(str::to_owned).collect();
    let mut read = |name: &str| -> Option<String> {
        use std::io::Read;
        let mut m = zip.by_name(name).ok()?;
        if m.size() > 1 << 20 {
            return None;
        }
        let mut s = String::new();
        m.read_to_string(&mut s).ok()?;
        Some(s)
    };
    // destination relative path → archive member
    let mut plan: BTreeMap<String, String> = BTreeMap::new();
    let mut assets: Vec<(String, String)> = Vec::new(); // (folder, asset name)
    let mut unit_meshes: BTreeSet<String> = BTreeSet::new();
    let mut staged_meshes: BTreeSet<String> = BTreeSet::new();
    let actors: Vec<String> = names
        .iter()
        .filter(|n| (n.starts_with("art/actors/fauna/") || n.starts_with("art/actors/units/")) && n.ends_with(".xml"))
        .cloned()
        .collect();
    for actor in actors {
        let unit = actor.starts_with("art/actors/units/");
        let (meshes, anims) = actor_refs(&names, &mut read, &actor);
        let Some(mesh) = meshes.iter().find(|m| m.starts_with("skeletal/")) else {
            continue;
        };
        let mesh_member = format!("art/meshes/{mesh}.cached.pmd");
        if anims.is_empty() || !names.contains(&mesh_member) {
            continue;
        }
        let base = mesh.rsplit('/').next().unwrap_or(mesh).trim_end_matches(".dae");
        let mesh_stem = caption::words(base).join("_");
        // Actors differing only in textures share a mesh: stage each mesh once (the first actor in name order).
        if !staged_meshes.insert(mesh.clone()) {
            continue;
        }
        let (folder, asset, anims) = if unit {
            if unit_meshes.len() >= MAX_UNIT_MESHES || !unit_meshes.insert(mesh.clone()) {
                continue;
            }
            let asset = match base.get(..2) {
                Some("m_") => "man".to_owned(),
                Some("f_") => "woman".to_owned(),
                _ => caption::asset_words(base).join(" "),
            };
            (
                format!("unit_{mesh_stem}"),
                asset,
                &anims[..anims.len().min(MAX_UNIT_ANIMS)],
            )
        } else {
            let stem = actor
                .rsplit('/')
                .next()
                .unwrap_or(&actor)
                .trim_end_matches(".xml")
                .to_owned();
            let asset = caption::asset_words(&stem).join(" ");
            (stem, asset, &anims[..])
        };
        let folder = folder.replace(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '-'), "_");
        plan.insert(format!("{folder}/{folder}.pmd"), mesh_member.clone());
        for a in anims {
            let member = format!("art/animation/{a}.cached.psa");
            if names.contains(&member) {
                let stem = a.rsplit('/').next().unwrap_or(a).trim_end_matches(".dae");
                plan.insert(format!("{folder}/{stem}.psa"), member);
            }
        }
        assets.push((folder, asset));
    }
    let by_member: BTreeMap<&str, Vec<&str>> = plan.iter().fold(BTreeMap::new(), |mut m, (d, s)| {
        m.entry(s.as_str()).or_insert_with(Vec::new).push(d.as_str());
        m
    });
    // One pass over the archive, then copies for members used by several actors.
    let first = archive::extract(&zip_path, dest, |name| by_member.get(name).map(|d| d[0].to_owned()))?;
    report.refused.extend(first.refused);
    for dests in by_member.values() {
        for extra in &dests[1..] {
            copy(&dest.join(dests[0]), &dest.join(extra))?;
        }
    }
    for (folder, asset) in &assets {
        let mesh = plan.get(&format!("{folder}/{folder}.pmd")).cloned().unwrap_or_default();
        write_provenance(&dest.join(folder), package, &c.licence(&mesh), asset)?;
    }
    Ok(assets.len())
}

fn stage_ufoai(dir: &Path, dest: &Path, package: &str, c: &Dep5, report: &mut StageReport) -> Result<usize> {
    let pk3 = dir.join("usr/share/games/ufoai/base/0models.pk3");
    if !pk3.is_file() {
        return Ok(0);
    }
    let file = std::fs::File::open(&pk3).map_err(|e| DataError::io(&pk3, e))?;
    let zip = zip::ZipArchive::new(file).map_err(|e| DataError::new(&pk3, "zip", e.to_string()))?;
    let names: BTreeSet<String> = zip.file_names().map(str::to_owned).collect();
    let wanted: BTreeSet<String> = names
        .iter()
        .filter(|n| n.ends_with(".anm"))
        .flat_map(|anm| {
            let md2 = format!("{}.md2", anm.trim_end_matches(".anm"));
            names.contains(&md2).then(|| [anm.clone(), md2]).into_iter().flatten()
        })
        .collect();
    let got = archive::extract(&pk3, dest, |name| wanted.contains(name).then(|| name.to_owned()))?;
    report.refused.extend(got.refused);
    let mut n = 0;
    for md2 in wanted.iter().filter(|w| w.ends_with(".md2")) {
        // One folder per model: models/<kind>/<name>/<file>.md2 → asset "<name> <kind without plural s>".
        let parts: Vec<&str> = md2.split('/').collect();
        let (kind, name) = (parts.get(1).copied().unwrap_or(""), parts.get(2).copied().unwrap_or(""));
        let kind = kind.trim_end_matches('s');
        let asset = match kind {
            "animal" | "object" | "" => caption::asset_words(name).join(" "),
            k => format!("{} {k}", caption::asset_words(name).join(" ")),
        };
        let folder = Path::new(md2).parent().unwrap_or(Path::new(""));
        let licence = c.licence(&format!("base/{md2}"));
        let to = dest.join(folder);
        let path = to.join(PROVENANCE_FILE);
        if !path.exists() {
            write_provenance(&to, package, &licence, asset.trim())?;
        }
        n += 1;
    }
    Ok(n)
}

/// Minetest and its mods: every `.b3d` with node keys, one folder per file ([`AnimatedFiles`]); static models
/// (doors, carts without keys, scenery) have no take and are skipped.
fn stage_minetest(dir: &Path, dest: &Path, package: &str, c: &Dep5, report: &mut StageReport) -> Result<usize> {
    let files = AnimatedFiles {
        root: "usr/share/games/minetest",
        exts: &["b3d"],
    };
    files.stage(dir, dest, package, c, report)
}

fn stage_assimp(dir: &Path, dest: &Path, package: &str, c: &Dep5) -> Result<usize> {
    // (file under usr/share/assimp/models, staged folder, asset name). The DirectX files are the two skinned,
    // animated ones; `anim_test.x` is left out: its mesh names bones its frames lack (its own notes say so).
    const FILES: &[(&str, &str, &str)] = &[
        ("IQM/mrfixit.iqm", "mrfixit", "robot"),
        ("X/BCN_Epileptic.X", "bcn_epileptic", "person"),
        ("X/Testwuson.X", "wuson", "pig"),
    ];
    let mut n = 0;
    for (file, folder, asset) in FILES {
        let mesh = dir.join("usr/share/assimp/models").join(file);
        if !mesh.is_file() {
            continue;
        }
        let to = dest.join(folder);
        copy(&mesh, &to.join(mesh.file_name().unwrap_or_default()))?;
        write_provenance(&to, package, &c.licence(&rel(dir, &mesh)), asset)?;
        n += 1;
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn held_out_packages_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        for package in [
            "openarena-data",
            "qt3d5-examples",
            "xonotic-data",
            "megaglest-data",
            "nexuiz-data",
        ] {
            let root = dir.path().join(package);
            std::fs::create_dir_all(root.join("in").join(package)).unwrap();
            let e = stage(&root.join("in"), &root.join("out")).unwrap_err();
            assert!(e.reason.contains("held out"), "{package}: {e}");
        }
    }
}

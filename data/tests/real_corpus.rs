//! The staging + import stages of `scripts/real_corpus.sh` on small package trees made here (an IQM player in
//! the Red Eclipse layout, an MD2 soldier with its `.anm` table inside a UFO:AI-style `.pk3`).

use std::io::Write;
use std::path::Path;

use any4d_data::formats::{iqm, md2};
use any4d_data::preprocess::VertexFilter;
use any4d_data::real_corpus::{CUBE2_MOCAP_FOLDER, MOCAP_FOLDER, stage};
use any4d_data::store::{self, ImportOptions, Status, read_index};

fn write(path: &Path, bytes: &[u8]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, bytes).unwrap();
}

/// A strip of `n` quads in the z = 0 plane, vertex `v` on joint `v % 2`.
fn strip(n: usize) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let pos: Vec<[f32; 3]> = (0..2 * n).map(|v| [(v / 2) as f32, (v % 2) as f32, 0.0]).collect();
    let faces = (0..n as u32 - 1)
        .flat_map(|q| [[2 * q, 2 * q + 2, 2 * q + 1], [2 * q + 1, 2 * q + 2, 2 * q + 3]])
        .collect();
    (pos, faces)
}

fn fake_packages(root: &Path) {
    let re = root.join("redeclipse-data");
    write(
        &re.join("usr/share/doc/redeclipse-data/copyright"),
        b"Format: dep5\n\nFiles: *\nCopyright: RE team\nLicense: CC-BY-SA-3.0\n\nFiles: data/actors/turret/*\nLicense: Other\n",
    );
    let player = re.join("usr/share/games/redeclipse/data/actors/player");
    let (pos, faces) = strip(20);
    let skin: Vec<u8> = (0..pos.len()).map(|v| (v % 2) as u8).collect();
    let joints = [("hips", -1, [0.0; 3]), ("head", 0, [0.0, 1.0, 0.0])];
    write(
        &player.join("male/RE_Player_male.iqm"),
        &iqm::write_test_iqm(&pos, &faces, &skin, &joints, "", &[], true),
    );
    let walk: Vec<Vec<[f32; 3]>> = (0..20)
        .map(|f| vec![[0.1 * f as f32, 0.0, 0.0], [0.0, 1.0, 0.05 * f as f32]])
        .collect();
    write(
        &player.join("walk_forward.iqm"),
        &iqm::write_test_iqm(&[], &[], &[], &joints, "Armature", &walk, false),
    );

    let ufo = root.join("ufoai-data");
    write(
        &ufo.join("usr/share/doc/ufoai-data/copyright"),
        b"Format: dep5\n\nFiles: *\nLicense: GPL-2+\n\nFiles: base/models/aliens/*\nLicense: CC-BY-SA-3.0\n",
    );
    let frames: Vec<(String, Vec<[u8; 3]>)> = (0..18)
        .map(|f| {
            (
                format!("walk{f}"),
                (0..12).map(|v| [v * 10, (v % 3) * 20 + f, v * 5]).collect(),
            )
        })
        .collect();
    let frames: Vec<(&str, Vec<[u8; 3]>)> = frames.iter().map(|(n, v)| (n.as_str(), v.clone())).collect();
    let faces: Vec<[u16; 3]> = (0..10).map(|i| [i, i + 1, i + 2]).collect();
    let mut pk3 = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts = zip::write::SimpleFileOptions::default();
    for (name, data) in [
        ("models/soldiers/female/body.md2", md2::write_md2(&frames, &faces)),
        (
            "models/soldiers/female/body.anm",
            b"// name start end fps\nwalk0 0 17 24\nstand0 0 0 1\n".to_vec(),
        ),
        ("models/soldiers/female/head.md2", md2::write_md2(&frames[..1], &faces)),
        ("../../escape.anm", b"x".to_vec()),
    ] {
        pk3.start_file(name, opts).unwrap();
        pk3.write_all(&data).unwrap();
    }
    write(
        &ufo.join("usr/share/games/ufoai/base/0models.pk3"),
        &pk3.finish().unwrap().into_inner(),
    );
}

#[test]
fn stage_and_import_record_takes_captions_and_licences() {
    let dir = tempfile::tempdir().unwrap();
    fake_packages(&dir.path().join("extracted"));
    let staged = dir.path().join("staged");
    let report = stage(&dir.path().join("extracted"), &staged).unwrap();
    assert_eq!(report.assets.get("redeclipse-data"), Some(&1), "{report:?}");
    assert_eq!(report.assets.get("ufoai-data"), Some(&1));
    assert!(
        report
            .refused
            .iter()
            .any(|(m, why)| m == "../../escape.anm" && why.contains("escapes"))
    );
    assert!(!dir.path().join("escape.anm").exists());

    let out = dir.path().join("store");
    let opts = ImportOptions {
        filter: VertexFilter { min: 3, max: 4096 },
        frames: 16,
        stride: 2,
        ..ImportOptions::default()
    };
    let rep = store::import(&[staged], &out, &opts).unwrap();
    let rows = read_index(&out).unwrap();
    let ok: Vec<_> = rows.iter().filter(|r| r.status == Status::Ok).collect();
    // IQM take: 20 frames → windows at 0, 2, 4; MD2 take walk0: 18 frames → windows at 0, 2.
    assert_eq!(ok.len(), 5, "{rep}");
    let player: Vec<_> = ok.iter().filter(|r| r.format == "iqm").collect();
    assert_eq!(player.len(), 3);
    for r in &player {
        assert_eq!(r.caption, "a male player walking forward");
        assert_eq!(
            (r.licence.as_str(), r.source_package.as_str()),
            ("CC-BY-SA-3.0", "redeclipse-data")
        );
        assert!(r.source.ends_with("RE_Player_male.iqm#walk_forward"), "{}", r.source);
    }
    assert_eq!(player[0].object, player[2].object);
    let soldier: Vec<_> = ok.iter().filter(|r| r.format == "md2").collect();
    assert_eq!(soldier.len(), 2);
    assert_eq!(soldier[0].caption, "a female soldier walking");
    assert_eq!(
        (soldier[0].licence.as_str(), soldier[0].source_package.as_str()),
        ("GPL-2+", "ufoai-data")
    );
    assert!(soldier[0].source.ends_with("body.md2#walk0"));
    // The one-frame head model is not staged (no .anm); nothing else is rejected.
    assert!(rep.rejected.is_empty(), "{rep}");

    // Re-importing replaces the takes of the same files instead of duplicating them.
    let again = store::import(&[dir.path().join("staged")], &out, &opts).unwrap();
    assert_eq!((again.total, again.kept), (5, 0));
}

/// An `.md5mesh` whose vertex 0 has 5 weights summing to 0.9 (vertices 1–3: one full weight each).
const FIVE_WEIGHT_MESH: &str = r#"MD5Version 10
commandline ""
numJoints 2
numMeshes 1
joints {
	"root" -1 ( 0 0 0 ) ( 0 0 0 )
	"tip" 0 ( 0 0 1 ) ( 0 0 0 )
}
mesh {
	numverts 4
	vert 0 ( 0 0 ) 0 5
	vert 1 ( 0 0 ) 5 1
	vert 2 ( 0 0 ) 6 1
	vert 3 ( 0 0 ) 7 1
	numtris 2
	tri 0 0 1 2
	tri 1 0 2 3
	numweights 8
	weight 0 0 0.2 ( 0 0 0 )
	weight 1 0 0.2 ( 0 0 0 )
	weight 2 1 0.2 ( 0 0 0 )
	weight 3 1 0.2 ( 0 0 0 )
	weight 4 1 0.1 ( 0 0 0 )
	weight 5 0 1 ( 1 0 0 )
	weight 6 1 1 ( 1 0 0 )
	weight 7 1 1 ( 0 1 0 )
}
"#;

/// An `.md5anim` for [`FIVE_WEIGHT_MESH`]: the root slides along x by 0.1 per frame.
fn md5_slide(frames: usize) -> String {
    let mut s = format!(
        "MD5Version 10\ncommandline \"\"\nnumFrames {frames}\nnumJoints 2\nframeRate 24\nnumAnimatedComponents 1\n\
         hierarchy {{\n\"root\" -1 1 0\n\"tip\" 0 0 1\n}}\nbounds {{\n"
    );
    s += &"( 0 0 0 ) ( 1 1 1 )\n".repeat(frames);
    s += "}\nbaseframe {\n( 0 0 0 ) ( 0 0 0 )\n( 0 0 1 ) ( 0 0 0 )\n}\n";
    for f in 0..frames {
        s += &format!("frame {f} {{\n{}\n}}\n", f as f32 * 0.1);
    }
    s
}

/// The bad inputs a real corpus meets, each through `data import`: the store keeps the good take, counts the
/// skin weights it had to fix, and rejects every other file with a reason naming what is wrong.
#[test]
fn import_counts_skin_fixes_and_rejects_bad_files_with_reasons() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src");
    // Good: five weights on vertex 0, summing to 0.9 (kept, renormalised, both counted).
    write(&src.join("fan/fan.md5mesh"), FIVE_WEIGHT_MESH.as_bytes());
    write(&src.join("fan/spin.md5anim"), md5_slide(20).as_bytes());
    let (pos, faces) = strip(4);
    let joints = [("root", -1, [0.0f32; 3])];
    let moving: Vec<Vec<[f32; 3]>> = (0..20).map(|f| vec![[0.1 * f as f32, 0.0, 0.0]]).collect();
    // A static mesh: no animation in the file and none beside it.
    write(
        &src.join("statue/statue.iqm"),
        &iqm::write_test_iqm(&pos, &faces, &[0; 8], &joints, "", &[], true),
    );
    // A weight naming joint 5 of a one-joint skeleton.
    write(
        &src.join("broken/broken.iqm"),
        &iqm::write_test_iqm(&pos, &faces, &[0, 0, 5, 0, 0, 0, 0, 0], &joints, "wave", &moving, true),
    );
    // A take longer than the configured maximum (40 > 30 frames).
    let long: Vec<Vec<[f32; 3]>> = (0..40).map(|f| vec![[0.1 * f as f32, 0.0, 0.0]]).collect();
    write(
        &src.join("long/long.iqm"),
        &iqm::write_test_iqm(&pos, &faces, &[0; 8], &joints, "dance", &long, true),
    );
    // A header claiming 2³¹ frames: refused from the file's length, nothing allocated for them.
    let mut huge = iqm::write_test_iqm(&pos, &faces, &[0; 8], &joints, "run", &moving, true);
    huge[16 + 4 * 19..16 + 4 * 20].copy_from_slice(&(1u32 << 31).to_le_bytes());
    write(&src.join("huge/huge.iqm"), &huge);

    let out = dir.path().join("store");
    let opts = ImportOptions {
        filter: VertexFilter { min: 3, max: 4096 },
        frames: 16,
        stride: 4,
        max_frames: 30,
        ..ImportOptions::default()
    };
    let rep = store::import(&[src], &out, &opts).unwrap();
    // The fan's 20-frame take gives windows at 0 and 4.
    assert_eq!(rep.added, 2, "{rep}");
    assert_eq!(
        (rep.skin.vertices, rep.skin.over_four_weights, rep.skin.renormalised),
        (4, 1, 1),
        "{rep}"
    );
    assert!(
        rep.to_string().contains("1 with more than 4 weights, 1 renormalised"),
        "{rep}"
    );
    let why = |name: &str| -> String {
        let r = rep.rejected.iter().find(|r| r.source.contains(name));
        r.unwrap_or_else(|| panic!("{name} not rejected: {rep}")).reason.clone()
    };
    assert!(why("statue.iqm").contains("static mesh is not a clip"), "{rep}");
    assert!(why("broken.iqm").contains("joint 5"), "{rep}");
    let long = why("long.iqm");
    assert!(long.contains("40 frames, more than the maximum of 30"), "{long}");
    // The field comes first (the store summary groups reasons by it), then the take by name.
    assert!(
        long.starts_with("takes: none of 1 became a clip (dance: frames: "),
        "{long}"
    );
    let huge = why("huge.iqm");
    assert!(
        huge.contains("more than the") && huge.contains("-byte file holds"),
        "{huge}"
    );
    assert_eq!(rep.rejected.len(), 4, "{rep}");
    // The index records them with their reasons.
    let rows = read_index(&out).unwrap();
    let rejected = rows.iter().filter(|r| r.status == Status::Rejected).count();
    assert_eq!(rejected, 4);
    // A maximum below the window length is refused before anything is read.
    let e = store::import(
        &[dir.path().join("src")],
        &dir.path().join("other"),
        &ImportOptions { max_frames: 8, ..opts },
    )
    .unwrap_err();
    assert_eq!(e.field, "max_frames", "{e}");
}

/// The motion capture of `assimp-testmodels` is staged beside copies of the Red Eclipse players with both
/// licences; a BVH whose joints do not map onto the rig is a rejected take naming the joints of both.
#[test]
fn mocap_is_staged_beside_the_players_with_both_licences() {
    let dir = tempfile::tempdir().unwrap();
    let extracted = dir.path().join("extracted");
    fake_packages(&extracted);
    let assimp = extracted.join("assimp-testmodels");
    write(
        &assimp.join("usr/share/doc/assimp-testmodels/copyright"),
        b"Format: dep5\n\nFiles: *\nLicense: BSD-3-clause\n",
    );
    let bvh = "HIERARCHY\nROOT Pelvis\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n\
               End Site\n{\nOFFSET 0 1 0\n}\n}\nMOTION\nFrames: 2\nFrame Time: 0.0333\n0 0 0\n0 1 0\n";
    write(&assimp.join("usr/share/assimp/models/BVH/01_01.bvh"), bvh.as_bytes());
    let staged = dir.path().join("staged");
    let report = stage(&extracted, &staged).unwrap();
    assert_eq!(report.assets.get(MOCAP_FOLDER), Some(&1), "{report:?}");
    let to = staged.join(MOCAP_FOLDER).join("player_male/male");
    assert!(to.join("RE_Player_male.iqm").is_file() && to.join("01_01.bvh").is_file());
    let provenance: serde_json::Value =
        serde_json::from_slice(&std::fs::read(to.join(store::PROVENANCE_FILE)).unwrap()).unwrap();
    assert_eq!(provenance["licence"], "CC-BY-SA-3.0 (mesh) AND BSD-3-clause (motion)");
    assert_eq!(provenance["source_package"], MOCAP_FOLDER);
    // No Cube 2 package, no snoutx10k copy; with it, the player gets the same motions.
    assert_eq!(report.assets.get(CUBE2_MOCAP_FOLDER), None, "{report:?}");
    let cube2 = extracted.join("cube2-data");
    write(
        &cube2.join("usr/share/games/cube2/packages/models/snoutx10k/snoutx10k.iqm"),
        b"IQM",
    );
    write(
        &cube2.join("usr/share/doc/cube2-data/copyright"),
        b"Format: dep5\n\nFiles: *\nLicense: CC-BY-3.0\n",
    );
    let staged2 = dir.path().join("staged2");
    let report = stage(&extracted, &staged2).unwrap();
    assert_eq!(report.assets.get(CUBE2_MOCAP_FOLDER), Some(&1), "{report:?}");
    let snout = staged2.join(CUBE2_MOCAP_FOLDER).join("cube2-data/snoutx10k");
    assert!(snout.join("snoutx10k.iqm").is_file() && snout.join("01_01.bvh").is_file());
    let provenance: serde_json::Value =
        serde_json::from_slice(&std::fs::read(snout.join(store::PROVENANCE_FILE)).unwrap()).unwrap();
    assert_eq!(provenance["licence"], "CC-BY-3.0 (mesh) AND BSD-3-clause (motion)");

    let opts = ImportOptions {
        filter: VertexFilter { min: 3, max: 4096 },
        frames: 16,
        stride: 2,
        ..ImportOptions::default()
    };
    let rep = store::import(&[staged.join(MOCAP_FOLDER)], &dir.path().join("store"), &opts).unwrap();
    assert_eq!(rep.added, 0, "{rep}");
    let reason = &rep.rejected[0].reason;
    assert!(
        reason.contains("01_01: joints: 1 body parts map")
            && reason.contains("BVH joints [Pelvis]")
            && reason.contains("rig joints [hips, head]"),
        "{reason}"
    );
}

/// Minetest packages: every `.b3d` with node keys is staged (one folder each, asset named after the file), static
/// ones are not, an unreadable one is listed as refused, and the staged take imports with its package and licence.
#[test]
fn minetest_b3d_models_with_keys_are_staged_and_imported() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("extracted/minetest-mod-walker");
    write(
        &pkg.join("usr/share/doc/minetest-mod-walker/copyright"),
        b"Format: dep5\n\nFiles: *\nLicense: CC-BY-SA-4.0+\n",
    );
    let models = pkg.join("usr/share/games/minetest/mods/walker/models");
    let (pos, faces) = strip(4);
    let keys: Vec<(i32, [f32; 3])> = (1..=20).map(|f| (f, [0.0, 0.1 * f as f32, 0.0])).collect();
    let moving: Vec<u32> = (0..pos.len() as u32).filter(|v| v % 2 == 1).collect();
    write(
        &models.join("walker_mob.b3d"),
        &any4d_data::formats::b3d::write_test_b3d(&pos, &faces, [0.0; 3], &moving, &keys),
    );
    write(
        &models.join("fence.b3d"),
        &any4d_data::formats::b3d::write_test_b3d(&pos, &faces, [0.0; 3], &moving, &[]),
    );
    write(&models.join("broken.b3d"), b"BB3D\x10\0\0\0truncated");
    let staged = dir.path().join("staged");
    let report = stage(&dir.path().join("extracted"), &staged).unwrap();
    assert_eq!(report.assets.get("minetest-mod-walker"), Some(&1), "{report:?}");
    assert!(
        report
            .refused
            .iter()
            .any(|(path, why)| path.ends_with("broken.b3d") && !why.is_empty()),
        "an unreadable model is listed, not dropped: {report:?}"
    );
    assert!(staged.join("minetest-mod-walker/walker_mob/walker_mob.b3d").is_file());
    // 20 key frames → windows at 0 and 4.
    import_two_windows(
        &staged,
        &dir.path().join("store"),
        "b3d",
        ("CC-BY-SA-4.0+", "minetest-mod-walker"),
        "a walker mob",
    );
}

/// `supertuxkart-data`: a skinned `.spm` is staged with the XML that names it (which gives its takes), a static one
/// and an unrelated XML are not, and the staged kart imports its takes with the package's licence.
#[test]
fn supertuxkart_meshes_are_staged_with_the_xml_that_names_them() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("extracted/supertuxkart-data");
    write(
        &pkg.join("usr/share/doc/supertuxkart-data/copyright"),
        b"Format: dep5\n\nFiles: *\nLicense: GPL-3+\n",
    );
    let kart = pkg.join("usr/share/games/supertuxkart/data/karts/puffer");
    let (pos, faces) = strip(4);
    let skin: Vec<u8> = (0..pos.len()).map(|v| if v % 2 == 1 { 0 } else { 255 }).collect();
    let keys: Vec<(u16, Vec<[f32; 3]>)> = [0u16, 40]
        .iter()
        .map(|&f| (f, vec![[0.0, f32::from(f), 0.0]]))
        .collect();
    let spm = any4d_data::formats::spm::write_test_spm(&pos, &faces, &skin, &[("body", -1)], 1, &keys);
    write(&kart.join("puffer.spm"), &spm);
    // Takes 0–21 and 21–40 (a mark runs to the next): 16-frame windows every 4 frames give two of each.
    let xml = r#"<kart model-file="puffer.spm"><animations start-losing="0" start-winning="21"/></kart>"#;
    write(&kart.join("kart.xml"), xml.as_bytes());
    write(&kart.join("materials.xml"), b"<materials/>");
    let mut rock = spm.clone();
    rock[2] = 1 << 3 | 2;
    write(&kart.join("rock.spm"), &rock[..28]);
    let staged = dir.path().join("staged");
    let report = stage(&dir.path().join("extracted"), &staged).unwrap();
    assert_eq!(report.assets.get("supertuxkart-data"), Some(&1), "{report:?}");
    let folder = staged.join("supertuxkart-data/puffer");
    assert!(folder.join("puffer.spm").is_file() && folder.join("kart.xml").is_file());
    assert!(!folder.join("materials.xml").exists());
    let opts = ImportOptions {
        filter: VertexFilter { min: 3, max: 4096 },
        frames: 16,
        stride: 4,
        ..ImportOptions::default()
    };
    let out = dir.path().join("store");
    let rep = store::import(&[staged], &out, &opts).unwrap();
    let rows = read_index(&out).unwrap();
    let ok: Vec<_> = rows.iter().filter(|r| r.status == Status::Ok).collect();
    assert_eq!(ok.len(), 4, "{rep}");
    for r in &ok {
        assert_eq!((r.format.as_str(), r.licence.as_str()), ("spm", "GPL-3+"));
    }
    assert!(
        ok.iter().any(|r| r.caption == "a puffer sulking"),
        "{:?}",
        ok.iter().map(|r| &r.caption).collect::<Vec<_>>()
    );
    assert!(ok.iter().any(|r| r.caption == "a puffer celebrating"));
}

/// Import `staged` in 16-frame windows every 4 frames and check that it gives exactly two clips, each of `format`
/// with `(licence, package)` and a caption starting with `caption`.
fn import_two_windows(staged: &Path, out: &Path, format: &str, source: (&str, &str), caption: &str) {
    let opts = ImportOptions {
        filter: VertexFilter { min: 3, max: 4096 },
        frames: 16,
        stride: 4,
        ..ImportOptions::default()
    };
    let rep = store::import(&[staged.to_path_buf()], out, &opts).unwrap();
    let rows = read_index(out).unwrap();
    let ok: Vec<_> = rows.iter().filter(|r| r.status == Status::Ok).collect();
    assert_eq!(ok.len(), 2, "{rep}");
    for r in &ok {
        assert_eq!(r.format, format);
        assert_eq!((r.licence.as_str(), r.source_package.as_str()), source);
        assert!(r.caption.starts_with(caption), "{}", r.caption);
    }
}

/// `assimp-testmodels`: its two skinned DirectX characters are staged (the pig under its own asset name) and
/// import with the package's licence; its MD2 models (held out) never are.
#[test]
fn assimp_directx_characters_are_staged_and_imported_but_not_its_md2() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("extracted/assimp-testmodels");
    write(
        &pkg.join("usr/share/doc/assimp-testmodels/copyright"),
        b"Format: dep5\n\nFiles: *\nLicense: BSD-3-clause\n",
    );
    let models = pkg.join("usr/share/assimp/models");
    let (pos, faces) = strip(4);
    let skin: Vec<u8> = (0..pos.len()).map(|v| (v % 2) as u8).collect();
    let keys: Vec<Vec<[f32; 3]>> = (0..20).map(|f| vec![[0.0; 3], [0.0, 0.1 * f as f32, 0.0]]).collect();
    write(
        &models.join("X/Testwuson.X"),
        any4d_data::formats::x::write_test_x(&pos, &faces, &skin, &keys).as_bytes(),
    );
    write(&models.join("MD2/faerie.md2"), b"IDP2 held out");
    let staged = dir.path().join("staged");
    let report = stage(&dir.path().join("extracted"), &staged).unwrap();
    assert_eq!(report.assets.get("assimp-testmodels"), Some(&1), "{report:?}");
    assert!(staged.join("assimp-testmodels/wuson/Testwuson.X").is_file());
    let md2_staged = walk(&staged)
        .iter()
        .any(|p| p.to_string_lossy().to_lowercase().ends_with(".md2"));
    assert!(!md2_staged, "an MD2 of assimp-testmodels was staged");
    // 20 key times → windows at 0 and 4.
    import_two_windows(
        &staged,
        &dir.path().join("store"),
        "x",
        ("BSD-3-clause", "assimp-testmodels"),
        "a pig",
    );
}

/// `cube2-data`: a model folder with an IQM mesh and animation-only IQM files beside it is staged whole under
/// the mesh's name and imports with the package's licence; a folder with a lone mesh (nothing moves it) is not.
#[test]
fn cube2_iqm_models_with_animation_files_are_staged_and_imported() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("extracted/cube2-data");
    write(
        &pkg.join("usr/share/doc/cube2-data/copyright"),
        b"Format: dep5\n\nFiles: *\nLicense: CC-BY-3.0\n\nFiles: packages/models/armor/*\nLicense: GPL-2+\n",
    );
    let models = pkg.join("usr/share/games/cube2/packages/models");
    let (pos, faces) = strip(20);
    let skin: Vec<u8> = (0..pos.len()).map(|v| (v % 2) as u8).collect();
    let joints = [("hips", -1, [0.0; 3]), ("head", 0, [0.0, 1.0, 0.0])];
    let mesh = iqm::write_test_iqm(&pos, &faces, &skin, &joints, "", &[], true);
    write(&models.join("squirrel/Squirrel.iqm"), &mesh);
    write(&models.join("nut/Nut.iqm"), &mesh);
    let run: Vec<Vec<[f32; 3]>> = (0..20)
        .map(|f| vec![[0.1 * f as f32, 0.0, 0.0], [0.0, 1.0, 0.05 * f as f32]])
        .collect();
    // Sorted before the mesh: the asset is still named after the mesh.
    write(
        &models.join("squirrel/Run.md5anim.iqm"),
        &iqm::write_test_iqm(&[], &[], &[], &joints, "Armature", &run, false),
    );
    let staged = dir.path().join("staged");
    let report = stage(&dir.path().join("extracted"), &staged).unwrap();
    assert_eq!(report.assets.get("cube2-data"), Some(&1), "{report:?}");
    assert!(staged.join("cube2-data/squirrel/Squirrel.iqm").is_file());
    assert!(staged.join("cube2-data/squirrel/Run.md5anim.iqm").is_file());
    assert!(!staged.join("cube2-data/nut").exists());
    import_two_windows(
        &staged,
        &dir.path().join("store"),
        "iqm",
        ("CC-BY-3.0", "cube2-data"),
        "a squirrel",
    );
}

fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

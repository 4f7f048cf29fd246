//! The SuperTuxKart reader on files made by its test writer: baking worked out by hand, and hostile files.

use super::*;

/// Offsets in [`triangle`]'s file (see [`write_test_spm`]'s layout): the buffer's vertex count, the armature's
/// used-joint count, its parents and its key-frame count.
const VERTICES_AT: usize = 41;
const USED_AT: usize = 171;
const PARENTS_AT: usize = 264;
const FRAMES_AT: usize = 268;

/// A triangle whose third vertex rides on joint 0, `tip`, the child of joint 1, `root` (listed after it, as the
/// game's exporter orders used joints first). Keys are given out of order: frame 4 (root at x = 1, tip 3 above
/// it), then frame 0 (both at rest, tip 1 above the root).
fn triangle() -> Vec<u8> {
    let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 1.0]];
    write_test_spm(
        &pos,
        &[[0, 1, 2]],
        &[255, 255, 0],
        &[("tip", 1), ("root", -1)],
        1,
        &[
            (4, vec![[0.0, 3.0, 0.0], [1.0, 0.0, 0.0]]),
            (0, vec![[0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]),
        ],
    )
}

fn read_bytes(bytes: &[u8]) -> Result<crate::clip::Clip> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("kart.spm");
    std::fs::write(&path, bytes).unwrap();
    read(&path, &ReadOptions::default()).map(|(clip, _, _)| clip)
}

#[test]
fn bakes_the_bind_frame_relative_pose_through_parents_listed_after_children() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("kart.spm");
    std::fs::write(&path, triangle()).unwrap();
    let takes = list_takes(&path).unwrap();
    assert_eq!((takes.len(), takes[0].frames, takes[0].fps), (1, 5, 0.0));
    let (clip, stats, _) = read(&path, &ReadOptions::default()).unwrap();
    assert_eq!((clip.frames, clip.n_vertices, stats.vertices), (5, 3, 3));
    // Mirrored to right-handed: z negated, winding reversed.
    assert_eq!(clip.faces, vec![[0, 2, 1]]);
    for f in 0..5 {
        // At frame f the root is at x = f/4 and the tip f/2 higher than at the bind frame.
        let t = f as f32 / 4.0;
        let v = clip.frame(f)[2];
        assert!(
            (v[0] - t).abs() < 1e-6 && (v[1] - (1.0 + 2.0 * t)).abs() < 1e-6 && v[2] == -1.0,
            "{f}: {v:?}"
        );
        // Vertices without a joint stay put.
        assert_eq!(clip.frame(f)[1], [1.0, 0.0, 0.0]);
    }
}

#[test]
fn a_static_mesh_has_no_take() {
    let mut s = b"SP".to_vec();
    s.push(VERSION << 3 | 2);
    s.push(0);
    s.extend([0u8; 24]);
    s.extend(1u16.to_le_bytes());
    s.extend([0, 0]);
    s.extend(1u16.to_le_bytes());
    s.extend(1u16.to_le_bytes());
    s.extend(3u32.to_le_bytes());
    s.extend(3u32.to_le_bytes());
    s.extend(0u16.to_le_bytes());
    for v in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        v.iter().for_each(|x| s.extend(x.to_le_bytes()));
    }
    s.extend([0, 1, 2]);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rock.spm");
    std::fs::write(&path, &s).unwrap();
    assert!(list_takes(&path).unwrap().is_empty());
    let e = read(&path, &ReadOptions::default()).unwrap_err();
    assert!(e.reason.contains("static mesh"), "{e}");
}

#[test]
fn refuses_truncated_and_hostile_files() {
    let good = triangle();
    assert!(read_bytes(&good).is_ok());
    for cut in 0..good.len() {
        assert!(read_bytes(&good[..cut]).is_err(), "cut {cut}");
    }
    let with = |at: usize, bytes: &[u8]| {
        let mut b = good.clone();
        b[at..at + bytes.len()].copy_from_slice(bytes);
        read_bytes(&b).unwrap_err()
    };
    let cases: [(usize, Vec<u8>, &str); 9] = [
        (2, vec![2 << 3 | 1], "version 2"),
        (2, vec![VERSION << 3], "space-partitioned"),
        // A buffer of more vertices than 16-bit indices reach, and one claiming more than the file holds.
        (VERTICES_AT, 70_000u32.to_le_bytes().to_vec(), "70000 vertices"),
        (VERTICES_AT, 60_000u32.to_le_bytes().to_vec(), "more than the"),
        (USED_AT, 3u16.to_le_bytes().to_vec(), "3 used of 2 joints"),
        // tip → root → tip.
        (PARENTS_AT + 2, 0i16.to_le_bytes().to_vec(), "cycle"),
        (PARENTS_AT, 9i16.to_le_bytes().to_vec(), "parent 9"),
        (FRAMES_AT, 0u16.to_le_bytes().to_vec(), "without key frames"),
        // 65,535 key frames of 82 bytes: refused before anything is allocated for them.
        (FRAMES_AT, u16::MAX.to_le_bytes().to_vec(), "more than the"),
    ];
    for (at, bytes, want) in cases {
        let e = with(at, &bytes);
        assert!(e.to_string().contains(want), "{want}: {e}");
    }
    // A triangle index past its buffer, and a NaN in a key frame.
    let index_at = FRAMES_AT - 100 - 3;
    assert!(with(index_at, &[3]).reason.contains("index 3"));
    let e = with(FRAMES_AT + 4, &f32::NAN.to_le_bytes());
    assert!(e.reason.contains("non-finite"), "{e}");
}

#[test]
fn refuses_a_vertex_on_a_joint_the_armatures_do_not_use() {
    let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 1.0]];
    let keys = [(0, vec![[0.0; 3], [0.0; 3]]), (2, vec![[0.0; 3], [0.0; 3]])];
    // Joint 1 exists but only the first joint is used: the game's index 1 would be the identity slot here.
    let bytes = write_test_spm(&pos, &[[0, 1, 2]], &[0, 1, 0], &[("a", -1), ("b", 0)], 1, &keys);
    let e = read_bytes(&bytes).unwrap_err();
    assert!(e.reason.contains("joint 1"), "{e}");
}

#[test]
fn takes_come_from_the_xml_that_names_the_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tux.spm");
    let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 1.0]];
    let keys: Vec<(u16, Vec<[f32; 3]>)> = [0, 40].iter().map(|&f| (f, vec![[0.0, f32::from(f), 0.0]])).collect();
    std::fs::write(
        &path,
        write_test_spm(&pos, &[[0, 1, 2]], &[255, 255, 0], &[("a", -1)], 1, &keys),
    )
    .unwrap();
    // An XML that does not name the mesh is not read (even when broken).
    std::fs::write(dir.path().join("materials.xml"), "<materials><broken").unwrap();
    assert_eq!(list_takes(&path).unwrap()[0].name, "all");
    // A kart: each mark runs to the next; `end-…` closes an animation; the last runs to the last key frame.
    let kart = r#"<kart name="Tux" model-file="tux.spm"><animations left="0" straight="10" start-winning="20"
        end-winning="30" start-jump="32"/></kart>"#;
    std::fs::write(dir.path().join("kart.xml"), kart).unwrap();
    let takes = list_takes(&path).unwrap();
    let got: Vec<(&str, usize)> = takes.iter().map(|t| (t.name.as_str(), t.frames)).collect();
    assert_eq!(
        got,
        [("left", 11), ("straight", 11), ("start-winning", 11), ("start-jump", 9)]
    );
    // The take starts at its mark: frame 32 of the key frames 0 → 40 (y = frame).
    let opts = ReadOptions {
        take: skeletal::TakeSel::Name("start-jump".into()),
        ..ReadOptions::default()
    };
    let (clip, _, _) = read(&path, &opts).unwrap();
    assert!((clip.frame(0)[2][1] - 33.0).abs() < 1e-5, "{:?}", clip.frame(0)[2]);
    // A library object: paired frame-start / frame-end lists.
    std::fs::remove_file(dir.path().join("kart.xml")).unwrap();
    let node = r#"<scene><object model="tux.spm" frame-start="0 12" frame-end="8 20"/></scene>"#;
    std::fs::write(dir.path().join("node.xml"), node).unwrap();
    let got: Vec<(String, usize)> = list_takes(&path)
        .unwrap()
        .into_iter()
        .map(|t| (t.name, t.frames))
        .collect();
    assert_eq!(got, [("0-8".to_owned(), 9), ("12-20".to_owned(), 9)]);
    // A frame that is not one, and broken XML that names the mesh: errors naming the XML file.
    std::fs::write(dir.path().join("node.xml"), node.replace("12", "-3")).unwrap();
    let e = list_takes(&path).unwrap_err();
    assert!(
        e.path.ends_with("node.xml") && e.reason.contains("\"-3\" is not a frame"),
        "{e}"
    );
    std::fs::write(dir.path().join("node.xml"), "<scene model=\"tux.spm\"").unwrap();
    assert!(list_takes(&path).unwrap_err().path.ends_with("node.xml"));
}

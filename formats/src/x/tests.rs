//! The `.x` reader on hand-written files: baking, conventions, and broken or hostile input.

use super::*;

/// A triangle in frame `root` (rest at the origin) whose vertex 2 is skinned to child frame `bone` (rest at
/// y = 1, offset = its inverse), and one animation set `lift` moving `bone` with `keys` (tick, position) and
/// optionally turning it with a rotation key.
fn triangle_x(keys: &[(u64, [f64; 3])], rotation: Option<[f64; 4]>) -> String {
    let mut s = String::from(
        "xof 0303txt 0032\n\
         template Frame {\n <3d82ab46-62da-11cf-ab39-0020af71e433>\n [...]\n}\n\
         // a comment\n\
         AnimTicksPerSecond { 4800; }\n\
         Frame root {\n\
          FrameTransformMatrix { 1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1;; }\n\
          Mesh tri {\n  3;\n  0;0;0;, 1;0;0;, 0;1;1;;\n  1;\n  3;0,1,2;;\n\
           SkinWeights { \"bone\"; 1; 2; 1.0; 1,0,0,0, 0,1,0,0, 0,0,1,0, 0,-1,0,1;; }\n\
          }\n\
          Frame bone {\n   FrameTransformMatrix { 1,0,0,0, 0,1,0,0, 0,0,1,0, 0,1,0,1;; }\n  }\n\
         }\n",
    );
    s += "AnimationSet lift {\n Animation {\n  { bone }\n";
    s += &format!("  AnimationKey {{ 2; {};", keys.len());
    for (t, p) in keys {
        s += &format!(" {t};3;{},{},{};;,", p[0], p[1], p[2]);
    }
    s += " }\n";
    if let Some([w, x, y, z]) = rotation {
        s += &format!("  AnimationKey {{ 0; 1; 0;4;{w},{x},{y},{z};;; }}\n");
    }
    s += " }\n}\n";
    s
}

fn write(dir: &Path, text: &str) -> std::path::PathBuf {
    let path = dir.join("guy.x");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn bakes_skinned_keys_at_the_key_step_mirrors_z_and_reverses_winding() {
    let dir = tempfile::tempdir().unwrap();
    // The bone rises from y = 1 to y = 3 between ticks 160 and 800 (keys every 320 ticks: Δ = 320, 3 frames).
    let keys = [(160, [0.0, 1.0, 0.0]), (480, [0.0, 2.0, 0.0]), (800, [0.0, 3.0, 0.0])];
    let path = write(dir.path(), &triangle_x(&keys, None));
    let takes = list_takes(&path).unwrap();
    assert_eq!(
        (takes.len(), takes[0].name.as_str(), takes[0].frames, takes[0].fps),
        (1, "lift", 3, 15.0)
    );
    let (clip, stats, _) = read(&path, &ReadOptions::default()).unwrap();
    assert_eq!((clip.frames, clip.n_vertices, stats.vertices), (3, 3, 3));
    assert_eq!(clip.faces, vec![[0, 2, 1]]);
    for (f, y) in [(0, 1.0), (1, 2.0), (2, 3.0)] {
        assert_eq!(clip.frame(f)[2], [0.0, y, -1.0], "frame {f}");
        // The unweighted vertices follow the mesh's frame, which does not move.
        assert_eq!(clip.frame(f)[1], [1.0, 0.0, 0.0], "frame {f}");
    }
}

#[test]
fn weights_on_a_joint_that_is_not_a_frame_hold_their_vertices_to_the_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let keys = [(160, [0.0, 1.0, 0.0]), (480, [0.0, 2.0, 0.0])];
    // Vertex 1 weighted to `ghost`, which no frame of the file is (assimp-testmodels' anim_test.x does this).
    let text = triangle_x(&keys, None).replace(
        "SkinWeights { \"bone\";",
        "SkinWeights { \"ghost\"; 1; 1; 1.0; 1,0,0,0, 0,1,0,0, 0,0,1,0, 5,5,5,1;; }\n SkinWeights { \"bone\";",
    );
    let (clip, _, _) = read(&write(dir.path(), &text), &ReadOptions::default()).unwrap();
    for f in 0..2 {
        assert_eq!(clip.frame(f)[1], [1.0, 0.0, 0.0], "frame {f}");
    }
    assert_eq!(clip.frame(1)[2], [0.0, 2.0, -1.0]);
}

#[test]
fn the_test_writer_round_trips_mirrored() {
    let dir = tempfile::tempdir().unwrap();
    let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]];
    let keys = vec![vec![[0.0; 3], [0.0; 3]], vec![[0.5, 0.0, 0.0], [0.0, 0.25, 0.0]]];
    let path = write(dir.path(), &write_test_x(&pos, &[[0, 1, 2]], &[0, 1, 1], &keys));
    let (clip, stats, info) = read(&path, &ReadOptions::default()).unwrap();
    assert_eq!(
        (info.name.as_str(), info.frames, info.fps, stats.vertices),
        ("walk", 2, 30.0, 3)
    );
    assert_eq!(clip.frame(0), &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, -0.5]]);
    assert_eq!(clip.frame(1), &[[0.5, 0.0, 0.0], [1.0, 0.25, 0.0], [0.0, 1.25, -0.5]]);
}

#[test]
fn a_rotation_key_and_the_matching_frame_matrix_give_the_same_transform() {
    // From a real exporter's file (assimp-testmodels' BCN_Epileptic.X, frame `Torso`): its rest matrix and
    // its rotation key at tick 0 hold the same turn, written once as a row-vector matrix and once as a
    // DirectX quaternion (w, x, y, z); read in this crate's convention both must give one transform.
    let text = "xof 0303txt 0032\n\
                Frame Torso {\n FrameTransformMatrix relative {\n  \
                1.000000,0.000000,0.000000,0.000000,0.000000,0.000000,1.000000,0.000000,\
                0.000000,-1.000000,0.000000,0.000000,0.000000,0.000000,0.000000,1.000000;;\n }\n}\n\
                AnimationSet s {\n Animation a {\n  { Torso }\n  AnimationKey rot {\n   0;\n   1;\n   \
                0;4;0.707107,-0.707107,0.000000,0.000000;;;\n  }\n }\n}\n";
    let path = Path::new("Torso.x");
    let file = parse(path, text).unwrap();
    let rest = file.frames[0].rest;
    // The matrix turns y to z and z to −y in column form: (x, y, z) → (x, −z, y).
    assert_eq!(skeletal::apply(&rest, [0.0, 1.0, 2.0]), [0.0, -2.0, 1.0]);
    let local = file.sets[0].tracks[0].1.local(0, &IDENTITY);
    let got = skeletal::apply(&local, [0.0, 1.0, 2.0]);
    assert!(
        got.iter().zip([0.0, -2.0, 1.0]).all(|(a, b)| (a - b).abs() < 1e-5),
        "{got:?}"
    );
    // The decomposition that fills a missing key kind gives the rest matrix back.
    let (t, q, s) = decompose(&rest);
    let again = trs(t, q, s);
    assert!(
        (0..4).all(|r| (0..4).all(|c| (again[r][c] - rest[r][c]).abs() < 1e-9)),
        "{again:?}"
    );
}

#[test]
fn refuses_static_truncated_lying_deep_and_overlong_files() {
    let dir = tempfile::tempdir().unwrap();
    let keys = [(0, [0.0, 1.0, 0.0]), (160, [0.0, 2.0, 0.0])];
    let good = triangle_x(&keys, None);
    let good = good.trim_end();
    let path = write(dir.path(), good);
    assert!(read(&path, &ReadOptions::default()).is_ok());
    // Every truncation is an error, never a panic or a shorter clip.
    for cut in 0..good.len() {
        std::fs::write(&path, &good[..cut]).unwrap();
        assert!(read(&path, &ReadOptions::default()).is_err(), "cut {cut}");
    }
    let err = |text: &str| {
        std::fs::write(&path, text).unwrap();
        read(&path, &ReadOptions::default()).unwrap_err()
    };
    // No animation: a static mesh.
    let e = err(&good.replace("AnimationSet lift", "AnimationSetX lift"));
    assert!(e.reason.contains("static mesh"), "{e}");
    // A vertex count far beyond the values that follow is refused before anything is allocated.
    let e = err(&good.replace("  3;\n  0;0;0;", "  3000000000;\n  0;0;0;"));
    assert!(e.reason.contains("claims 3000000000"), "{e}");
    // A face naming a vertex the mesh does not have; a weight on one.
    let e = err(&good.replace("3;0,1,2;;", "3;0,1,7;;"));
    assert!(e.reason.contains("vertex 7"), "{e}");
    let e = err(&good.replace("\"bone\"; 1; 2;", "\"bone\"; 1; 9;"));
    assert!(e.reason.contains("vertex 9"), "{e}");
    // An animated frame that the file lacks is named (a skin joint it lacks holds its vertices still: above).
    let e = err(&good.replace("{ bone }", "{ ghost }"));
    assert!(e.reason.contains("\"ghost\""), "{e}");
    // Keys a billion ticks apart one tick from each other: refused by the frame limit before allocation.
    let e = err(&triangle_x(
        &[(0, [0.0; 3]), (1, [0.0; 3]), (1_000_000_000, [0.0; 3])],
        None,
    ));
    assert!(e.field == "frames" && e.reason.contains("maximum"), "{e}");
    // Non-finite numbers, a wrong key width, binary and compressed files, nesting deeper than the limit.
    let e = err(&good.replace("1;0;0;,", "1;nan;0;,"));
    assert!(e.reason.contains("nan"), "{e}");
    let e = err(&good.replace("AnimationKey { 2; 2; 0;3;", "AnimationKey { 2; 2; 0;4;"));
    assert!(e.reason.contains("expected 3"), "{e}");
    assert!(err("xof 0303bin 0032 junk").reason.contains("binary"));
    assert!(err("xof 0303tzip0032 junk").reason.contains("compressed"));
    assert!(err("ply\nformat ascii").reason.contains("xof"));
    // 4,096 frames × 16,385 vertices is over the default clip limit (2²⁶ rows): refused before the bake allocates.
    let many: Vec<[f32; 3]> = (0..16_385).map(|i| [i as f32, 0.0, 0.0]).collect();
    let mut keys = vec![vec![[0.0f32; 3]]; 4096];
    keys[1][0] = [0.0, 1.0, 0.0];
    let e = err(&write_test_x(&many, &[[0, 1, 2]], &vec![0; many.len()], &keys));
    assert!(e.reason.contains("baked vertices"), "{e}");
    let deep = format!("xof 0303txt 0032\n{}", "Frame a {\n".repeat(100_000));
    assert!(err(&deep).reason.contains("deeper"));
}

#[test]
fn an_animation_set_on_one_key_time_is_a_pose_listed_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let walk = triangle_x(&[(0, [0.0, 1.0, 0.0]), (320, [0.0, 2.0, 0.0])], None);
    let pose = triangle_x(&[(0, [0.0, 3.0, 0.0])], None).replace("AnimationSet lift", "AnimationSet aim");
    let text = walk.clone() + &pose[pose.find("AnimationSet aim").unwrap()..];
    let path = write(dir.path(), &text);
    let names: Vec<String> = list_takes(&path).unwrap().into_iter().map(|t| t.name).collect();
    assert_eq!(names, ["lift"]);
    assert_eq!(one_frame_takes(&path).unwrap(), ["aim"]);
    let path = write(dir.path(), &walk);
    assert!(one_frame_takes(&path).unwrap().is_empty());
}

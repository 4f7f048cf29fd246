//! The MD3 reader on files written by the tests: one file, a body part with its `animation.cfg`, and a player
//! assembled through its tags.

use std::path::Path;

use super::testing::{player_cfg, write_test_player as write_player};
use super::*;
use crate::skeletal::TakeSel;

#[test]
fn reads_frames_and_refuses_bad_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flag.md3");
    let frames: Vec<Vec<[i16; 3]>> = (0..3).map(|f| vec![[0, 0, 0], [64, 0, 0], [0, 64, 64 * f]]).collect();
    let good = write_test_md3(&frames, &[[0, 1, 2]]);
    std::fs::write(&path, &good).unwrap();
    assert_eq!(list_takes(&path).unwrap()[0].frames, 3);
    let (clip, _, _) = read(&path, &ReadOptions::default()).unwrap();
    // Frame 2, vertex 2 = (0, 1, 2) → Y-up (0, 2, −1).
    assert_eq!(clip.frame(2)[2], [0.0, 2.0, -1.0]);
    assert_eq!(clip.faces, vec![[0, 1, 2]]);
    for cut in [3, 100, 150, good.len() - 2] {
        std::fs::write(&path, &good[..cut]).unwrap();
        assert!(read(&path, &ReadOptions::default()).is_err(), "cut {cut}");
    }
    std::fs::write(&path, write_test_md3(&frames[..1], &[[0, 1, 2]])).unwrap();
    assert!(
        read(&path, &ReadOptions::default())
            .unwrap_err()
            .reason
            .contains("static mesh")
    );
}

/// An `animation.cfg` laid out as Quake III's: the six `BOTH_*` lines (three 1-frame `DEAD` poses), seven
/// 2-frame `TORSO_*` lines from frame 8, then `LEGS_WALKCR` and a backwards `LEGS_WALK` numbered after the
/// torso's frames (22, 24: frames 8 and 10 of `lower.md3`).
const CFG: &str = "// animation config file\nsex m\nfootsteps normal\n\
    0 3 0 20 // BOTH_DEATH1\n2 1 0 20\n3 3 0 20\n5 1 0 20\n6 2 0 20\n7 1 0 20\n\
    8 2 0 15\n10 2 0 15\n12 2 0 15\n14 2 0 15\n16 2 0 15\n18 2 0 15\n20 2 0 15\n\
    22 2 2 25\n24 -2 2 25 // LEGS_WALK, backwards\n";

/// An `.md3` of `n` frames whose vertex 2 sits at height = frame index (after the turn to Y-up).
fn frames_md3(n: i16) -> Vec<u8> {
    let frames: Vec<Vec<[i16; 3]>> = (0..n).map(|f| vec![[0, 0, 0], [64, 0, 0], [0, 64, 64 * f]]).collect();
    write_test_md3(&frames, &[[0, 1, 2]])
}

#[test]
fn player_takes_come_from_animation_cfg() {
    let dir = tempfile::tempdir().unwrap();
    let (lower, upper, other) = (
        dir.path().join("lower.md3"),
        dir.path().join("upper_1.md3"),
        dir.path().join("flag.md3"),
    );
    std::fs::write(&lower, frames_md3(12)).unwrap();
    std::fs::write(&upper, frames_md3(22)).unwrap();
    std::fs::write(&other, frames_md3(5)).unwrap();
    std::fs::write(dir.path().join("Animation.CFG"), CFG).unwrap();
    let names = |p: &Path| list_takes(p).unwrap().into_iter().map(|t| t.name).collect::<Vec<_>>();
    assert_eq!(
        names(&lower),
        ["BOTH_DEATH1", "BOTH_DEATH2", "BOTH_DEATH3", "LEGS_WALKCR", "LEGS_WALK"]
    );
    let upper_takes = names(&upper);
    assert_eq!(upper_takes.len(), 10);
    assert_eq!(upper_takes[3..5], ["TORSO_GESTURE", "TORSO_ATTACK"]);
    assert_eq!(names(&other), ["all"]);
    let opts = |take: &str| ReadOptions {
        take: skeletal::TakeSel::parse(take),
        ..ReadOptions::default()
    };
    let (clip, _, info) = read(&lower, &opts("LEGS_WALK")).unwrap();
    assert_eq!((info.frames, info.fps), (2, 25.0));
    // Frames 10 and 11 of lower.md3, played backwards.
    assert_eq!([clip.frame(0)[2][1], clip.frame(1)[2][1]], [11.0, 10.0]);
    let (clip, _, _) = read(&upper, &opts("TORSO_STAND2")).unwrap();
    assert_eq!([clip.frame(0)[2][1], clip.frame(1)[2][1]], [20.0, 21.0]);
    // A cfg that runs past the file, and a broken line.
    std::fs::write(&lower, frames_md3(11)).unwrap();
    let e = list_takes(&lower).unwrap_err();
    assert!(e.field == "LEGS_WALK" && e.reason.contains("has 11"), "{e}");
    std::fs::write(dir.path().join("Animation.CFG"), "0 3 x 20\n").unwrap();
    let e = list_takes(&upper).unwrap_err();
    assert!(e.field == "line 1" && e.reason.contains("\"x\""), "{e}");
}

#[test]
fn an_animation_at_0_fps_plays_at_1_and_huge_first_frames_are_refused_without_overflow() {
    let dir = tempfile::tempdir().unwrap();
    let lower = dir.path().join("lower.md3");
    std::fs::write(&lower, frames_md3(12)).unwrap();
    // A real player's unused LEGS_TURN line: `192 0 0 0`; and a 2-frame LEGS_WALKCR listed at 0 fps.
    let cfg = CFG.replace("22 2 2 25\n", "22 2 2 0\n") + "192 0 0 0 // LEGS_TURN\n";
    std::fs::write(dir.path().join("animation.cfg"), cfg).unwrap();
    let takes = list_takes(&lower).unwrap();
    let walkcr = takes.iter().find(|t| t.name == "LEGS_WALKCR").unwrap();
    assert_eq!((walkcr.frames, walkcr.fps), (2, 1.0));
    for (line, needle) in [
        (format!("{} 2 0 20\n", i64::MAX), "frames"),
        ("0 2 0 -5\n".to_string(), "-5 fps"),
        ("0 2 0 NaN\n".to_string(), "NaN fps"),
        ("0 2 0 inf\n".to_string(), "inf fps"),
    ] {
        // BOTH_DEATH1 gets the hostile line; the legs' skip is computed from rows that are all present.
        let cfg = CFG.replacen("0 3 0 20 // BOTH_DEATH1\n", &line, 1);
        std::fs::write(dir.path().join("animation.cfg"), &cfg).unwrap();
        let e = list_takes(&lower).unwrap_err();
        assert!(e.to_string().contains(needle), "{line:?}: {e}");
    }
    // A legs line whose first frame lies below the torso's skip: refused, not wrapped around.
    let cfg = CFG.replace("24 -2 2 25", "5 -2 2 25");
    std::fs::write(dir.path().join("animation.cfg"), cfg).unwrap();
    let e = list_takes(&lower).unwrap_err();
    assert!(e.field == "LEGS_WALK" && e.reason.contains("frames -9..-7"), "{e}");
}

#[test]
fn a_player_is_assembled_through_its_tags_and_each_part_plays_its_own_animation() {
    let dir = tempfile::tempdir().unwrap();
    let sarge = dir.path().join("sarge");
    std::fs::create_dir(&sarge).unwrap();
    write_player(&sarge);
    let lower = sarge.join("lower.md3");
    let names: Vec<String> = list_takes(&lower).unwrap().into_iter().map(|t| t.name).collect();
    assert_eq!(names, ["BOTH_DEATH1", "TORSO_GESTURE", "LEGS_WALK", "LEGS_IDLE"]);
    let read_take = |take: &str| {
        read(
            &lower,
            &ReadOptions {
                take: TakeSel::parse(take),
                ..ReadOptions::default()
            },
        )
        .unwrap()
    };
    let y = |clip: &Clip, k: usize, v: usize| clip.frame(k)[v];
    // LEGS_WALK: legs frames 2..=5 at 20 fps, the torso holding TORSO_STAND (frame 5); 3 + 3 + 3 vertices.
    let (clip, _, info) = read_take("LEGS_WALK");
    assert_eq!(
        (clip.id.as_str(), clip.n_vertices, info.frames, info.fps),
        ("sarge", 9, 4, 20.0)
    );
    assert_eq!(clip.faces, [[0, 1, 2], [3, 4, 5], [6, 7, 8]]);
    for k in 0..4 {
        let legs = 2.0 + k as f32;
        assert_eq!(y(&clip, k, 0), [0.0, legs, 0.0], "legs vertex 0 at step {k}");
        // Torso vertex 2 = (0, 1, 5) hung at (0, 0, 100 + legs frame).
        let turn = k == 1;
        let torso_v2 = if turn {
            [-1.0, 105.0 + legs, 0.0]
        } else {
            [0.0, 105.0 + legs, -1.0]
        };
        assert_eq!(y(&clip, k, 5), torso_v2, "torso vertex 2 at step {k}");
        // The head hangs on tag_head = (5, 0, 10) turned a quarter about x, composed as Quake III's
        // CG_PositionEntityOnTag does: origin = torso origin + Σ tag.origin[i]·torso.axis[i], axis = tag.axis ×
        // torso.axis. Still torso: origin (5, 0, 110 + legs), axis rows x, z, −y. Turned torso: origin
        // (0, 5, 110 + legs) (the tag's x offset turned onto y), axis rows y, z, x. Head vertices 1 = (1, 0, 0) and
        // 2 = (0, 1, 0), then turned Y-up. A swapped product or an unturned tag origin gives other numbers.
        let (head_v1, head_v2) = if turn {
            ([0.0, 110.0 + legs, -6.0], [0.0, 111.0 + legs, -5.0])
        } else {
            ([6.0, 110.0 + legs, 0.0], [5.0, 111.0 + legs, 0.0])
        };
        assert_eq!(y(&clip, k, 7), head_v1, "head vertex 1 at step {k}");
        assert_eq!(y(&clip, k, 8), head_v2, "head vertex 2 at step {k}");
    }
    // TORSO_GESTURE: torso frames 2..=4 at 10 fps while the legs idle on frames 4, 4, 5 (5 fps, looping).
    let (clip, _, _) = read_take("TORSO_GESTURE");
    let legs: Vec<f32> = (0..3).map(|k| y(&clip, k, 0)[1]).collect();
    assert_eq!(legs, [4.0, 4.0, 5.0]);
    let torso: Vec<f32> = (0..3).map(|k| y(&clip, k, 5)[1] - 100.0 - legs[k]).collect();
    assert_eq!(torso, [2.0, 3.0, 4.0]);
    // BOTH_DEATH1: frames 0 and 1 of both parts.
    let (clip, _, _) = read_take("BOTH_DEATH1");
    assert_eq!([y(&clip, 1, 0)[1], y(&clip, 1, 5)[1]], [1.0, 102.0]);
    // The parts still read alone when named.
    assert_eq!(list_takes(&sarge.join("upper.md3")).unwrap().len(), 2);
    assert_eq!(
        read(&sarge.join("head.md3"), &ReadOptions::default())
            .unwrap_err()
            .field,
        "animations"
    );
}

#[test]
fn only_the_lower_body_of_a_player_is_an_import_source() {
    let dir = tempfile::tempdir().unwrap();
    let sarge = dir.path().join("sarge");
    std::fs::create_dir(&sarge).unwrap();
    write_player(&sarge);
    let sources: Vec<&str> = [
        "lower.md3",
        "upper.md3",
        "head.md3",
        "lower_1.md3",
        "head_2.md3",
        "flag.md3",
    ]
    .into_iter()
    .filter(|n| is_source(&sarge.join(n)))
    .collect();
    assert_eq!(sources, ["lower.md3", "flag.md3"]);
}

#[test]
fn a_player_without_its_tags_or_with_a_hostile_cfg_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    write_player(dir.path());
    let lower = dir.path().join("lower.md3");
    let upper = std::fs::read(dir.path().join("upper.md3")).unwrap();
    // A torso without tag_head while a head is present.
    let f: Vec<Vec<[i16; 3]>> = (0..6).map(|f| vec![[0, 0, f], [64, 0, 0], [0, 64, 0]]).collect();
    std::fs::write(dir.path().join("upper.md3"), write_test_md3(&f, &[[0, 1, 2]])).unwrap();
    let e = read(&lower, &ReadOptions::default()).unwrap_err();
    assert!(e.path.ends_with("upper.md3") && e.reason.contains("tag_head"), "{e}");
    std::fs::write(dir.path().join("upper.md3"), upper).unwrap();
    // A torso animation of 2^40 frames: refused by its range before anything is allocated for its steps.
    let cfg = player_cfg().replace("2 3 0 10 // TORSO_GESTURE", "2 1099511627776 0 10");
    std::fs::write(dir.path().join("animation.cfg"), cfg).unwrap();
    let e = list_takes(&lower).unwrap_err();
    assert!(e.field == "TORSO_GESTURE" && e.reason.contains("upper body"), "{e}");
    // Tags past the end of the file.
    let mut legs = std::fs::read(&lower).unwrap();
    legs[96..100].copy_from_slice(&(1i32 << 20).to_le_bytes()); // ofs_tags
    std::fs::write(&lower, legs).unwrap();
    std::fs::write(dir.path().join("animation.cfg"), player_cfg()).unwrap();
    let e = read(&lower, &ReadOptions::default()).unwrap_err();
    assert_eq!(e.field, "tags", "{e}");
}

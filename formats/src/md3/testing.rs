//! A Quake III player written for tests (the MD3 reader's own and the store's): three parts joined by tags, an
//! `animation.cfg`, and coarser copies beside them.

use std::path::Path;

use super::{TestTag, write_test_md3, write_test_md3_tags};

/// Axis rows of a quarter turn about z: the part's x points along the parent's y.
const QUARTER_Z: [[f32; 3]; 3] = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
/// Axis rows of no turn.
const STILL: [[f32; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
/// Axis rows of a quarter turn about x: the part's y points along the parent's z.
const QUARTER_X: [[f32; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]];

/// A player's cfg: `BOTH_DEATH1` on frames 0-1 of both parts, `TORSO_GESTURE` on upper frames 2-4,
/// `TORSO_STAND` one pose (upper frame 5), `LEGS_WALKCR` at 6 (so the legs skip 4 frames), `LEGS_WALK` lower
/// frames 2-5 at 20 fps and `LEGS_IDLE` lower frames 4-5 looping at 5 fps; every other animation one frame.
pub fn player_cfg() -> String {
    let mut lines = vec!["sex m".to_owned(), "0 2 0 10 // BOTH_DEATH1".to_owned()];
    lines.extend(["1 1 0 10"; 5].map(str::to_owned));
    lines.push("2 3 0 10 // TORSO_GESTURE".into());
    lines.extend(["5 1 0 10"; 5].map(str::to_owned)); // TORSO_ATTACK .. TORSO_STAND (5)
    lines.push("5 1 0 10 // TORSO_STAND2".into());
    lines.push("6 1 0 10 // LEGS_WALKCR".into());
    lines.push("6 4 4 20 // LEGS_WALK".into());
    lines.extend(["6 1 0 10"; 7].map(str::to_owned)); // LEGS_RUN .. LEGS_LANDB
    lines.push("8 2 2 5 // LEGS_IDLE".into());
    lines.join("\n") + "\n"
}

/// Writes a player into `dir`: legs whose vertex 0 sits at height = frame and whose `tag_torso` rises from 100
/// (a quarter turn at frame 3); a torso whose vertex 2 sits at height = frame and whose `tag_head` is at (5, 0, 10)
/// turned a quarter about x; a one-frame head. Coarser copies and an unrelated flag lie beside them.
pub fn write_test_player(dir: &Path) {
    let part = |frames: usize, tags: &[TestTag]| {
        let f: Vec<Vec<[i16; 3]>> = (0..frames as i16)
            .map(|f| vec![[0, 0, 64 * f], [64, 0, 0], [0, 64, 64 * f]])
            .collect();
        write_test_md3_tags(&f, &[[0, 1, 2]], tags)
    };
    let torso: Vec<_> = (0..6)
        .map(|f| ([0.0, 0.0, 100.0 + f as f32], if f == 3 { QUARTER_Z } else { STILL }))
        .collect();
    let head = vec![([5.0, 0.0, 10.0], QUARTER_X); 6];
    let flag: Vec<Vec<[i16; 3]>> = (0..3).map(|f| vec![[0, 0, 0], [64, 0, 0], [0, 64, 64 * f]]).collect();
    for (name, bytes) in [
        ("lower.md3", part(6, &[("tag_torso", torso)])),
        (
            "upper.md3",
            part(6, &[("tag_weapon", head.clone()), ("tag_head", head)]),
        ),
        ("head.md3", part(1, &[])),
        ("lower_1.md3", part(6, &[])),
        ("head_2.md3", part(1, &[])),
        ("flag.md3", write_test_md3(&flag, &[[0, 1, 2]])),
    ] {
        std::fs::write(dir.join(name), bytes).expect("a writable test folder");
    }
    std::fs::write(dir.join("animation.cfg"), player_cfg()).expect("a writable test folder");
}

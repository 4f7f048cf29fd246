//! Tests of the rigged characters: determinism, every template × action a valid closed moving clip, rigid bones,
//! captions, and the skeleton's and skin's own checks on degenerate rigs.

use std::collections::{HashMap, HashSet};

use super::*;
use crate::synth::tests::extent;
use crate::synth::{Family, generate_one as synth_one};

fn cfg(seed: u64) -> SynthConfig {
    SynthConfig {
        clips: 8,
        seed,
        family: Family::Rigged(Default::default()),
        ..SynthConfig::default()
    }
}

/// Every undirected edge in exactly two faces, once in each direction: closed, consistently oriented surfaces.
fn closed(faces: &[[u32; 3]]) -> bool {
    let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
    for f in faces {
        for k in 0..3 {
            *directed.entry((f[k], f[(k + 1) % 3])).or_default() += 1;
        }
    }
    directed
        .iter()
        .all(|(&(a, b), &n)| n == 1 && directed.get(&(b, a)) == Some(&1))
}

#[test]
fn same_seed_same_clip_and_forced_kinds_match_the_drawn_ones() {
    let a = synth_one(&cfg(3), 5).unwrap();
    assert_eq!(a, synth_one(&cfg(3), 5).unwrap());
    assert_ne!(a.vertices, synth_one(&cfg(4), 5).unwrap().vertices);
    let (t, act) = kinds(&a.id).unwrap();
    assert_eq!(generate_with(&cfg(3), 5, t, act).unwrap(), a);
    assert_eq!(
        a.source, "synth-rigged:3:5",
        "a source of its own: a shapes run of seed 3 does not replace it"
    );
    assert!(
        a.id.starts_with(&format!("rigged-{}-{}-3-5_offset0_0-15", t.name(), act.name())),
        "{}",
        a.id
    );
}

#[test]
fn every_template_and_action_is_a_valid_closed_moving_clip() {
    let c = cfg(17);
    let mut i = 0;
    for template in Template::ALL {
        for &action in template.actions() {
            i += 1;
            let clip = generate_with(&c, i, template, action).unwrap();
            let tag = format!("{} / {}: {}", template.name(), action.name(), clip.caption);
            clip.validate().unwrap();
            assert_eq!(kinds(&clip.id), Some((template, action)), "{tag}");
            assert!(
                (c.min_vertices..=c.max_vertices).contains(&clip.n_vertices),
                "{tag}: {}",
                clip.n_vertices
            );
            assert!(closed(&clip.faces), "{tag}: open or inconsistently oriented skin");
            assert!(clip.vertices.iter().flatten().all(|x| x.is_finite()), "{tag}");
            let size = extent(clip.frame(0));
            assert!((0.2..5.0).contains(&size), "{tag}: size {size}");
            // Standing on the ground (flight starts above it).
            let low = clip.frame(0).iter().map(|p| p[1]).fold(f32::INFINITY, f32::min);
            if action != Action::Fly {
                assert!(low.abs() < 1e-4, "{tag}: lowest point {low}");
            } else {
                assert!(low > 0.0, "{tag}");
            }
            // It moves, and smoothly: no vertex jumps more than half the body between frames.
            let n = clip.n_vertices;
            let mut moved = 0.0f32;
            for f in 1..clip.frames {
                let step = clip
                    .frame(f)
                    .iter()
                    .zip(clip.frame(f - 1))
                    .map(|(a, b)| norm(sub(*a, *b)))
                    .fold(0.0, f32::max);
                assert!(step < 0.5 * size, "{tag}: frame {f} moves a vertex by {step}");
                moved = moved.max(
                    clip.frame(f)
                        .iter()
                        .zip(clip.frame(0))
                        .map(|(a, b)| norm(sub(*a, *b)))
                        .fold(0.0, f32::max),
                );
            }
            assert!(moved > 0.02 * size, "{tag}: moves at most {moved} of {size}");
            assert_eq!(clip.vertices.len(), n * clip.frames);
        }
    }
}

#[test]
fn six_templates_and_their_nouns() {
    let c = cfg(5);
    let nouns = [
        (Template::Biped, ["humanoid", "character", "figure"].as_slice()),
        (Template::MultiArm, &["four-armed", "six-armed"]),
        (Template::Quadruped, &["four-legged", "quadruped"]),
        (Template::Insect, &["six-legged", "eight-legged", "beetle"]),
        (Template::Bird, &["bird", "winged"]),
        (Template::Snake, &["snake", "serpent"]),
    ];
    assert_eq!(Template::ALL.len(), 6);
    for (k, (t, words)) in nouns.into_iter().enumerate() {
        for j in 0..4 {
            let clip = generate_with(&c, 10 * k + j, t, t.actions()[0]).unwrap();
            assert!(
                words.iter().any(|w| clip.caption.contains(w)),
                "{}: {}",
                t.name(),
                clip.caption
            );
        }
    }
}

#[test]
fn a_bone_moves_its_own_vertices_rigidly() {
    // Two vertices that follow one bone alone keep their distance in every frame (no breathing outside idle).
    let c = cfg(9);
    let mut r = rng(1, 2);
    let rig = skeletons::build(Template::Biped, &mut r);
    let skin = skin(&rig, 1500, 512, 4096).unwrap();
    let motion = actions::draw(Action::Walk, &rig, &mut r);
    let whole: Vec<usize> = (0..skin.pos.len())
        .filter(|&v| skin.influences[v].len() == 1 && skin.influences[v][0].1 == 1.0)
        .collect();
    let by_bone: HashMap<usize, Vec<usize>> = whole.iter().fold(HashMap::new(), |mut m, &v| {
        m.entry(skin.influences[v][0].0).or_insert_with(Vec::new).push(v);
        m
    });
    assert!(
        by_bone.len() >= 8,
        "most bones own vertices outright: {}",
        by_bone.len()
    );
    let mut frame = vec![[0.0f32; 3]; skin.pos.len()];
    for f in 0..c.frames {
        let pose = actions::pose(&motion, &rig, f as f32 / 15.0);
        pose_frame(&skin, &rig.bones, &pose, 37.0, &mut frame);
        for vs in by_bone.values() {
            let (a, b) = (vs[0], vs[vs.len() - 1]);
            let rest = norm(sub(skin.pos[a], skin.pos[b]));
            let now = norm(sub(frame[a], frame[b]));
            assert!((rest - now).abs() < 1e-4 * (1.0 + rest), "frame {f}: {rest} → {now}");
        }
    }
}

#[test]
fn captions_name_the_direction_the_clip_travels() {
    let c = cfg(21);
    let mut seen = HashSet::new();
    for i in 0..24 {
        let clip = generate_with(&c, i, Template::Quadruped, Action::Walk).unwrap();
        let n = clip.n_vertices;
        let mean = |f: usize| -> [f32; 3] {
            let fr = clip.frame(f);
            [0, 1, 2].map(|k| fr.iter().map(|p| p[k]).sum::<f32>() / n as f32)
        };
        let (a, b) = (mean(0), mean(clip.frames - 1));
        let (dx, dz) = (b[0] - a[0], b[2] - a[2]);
        let word = if dx.abs() >= dz.abs() {
            if dx > 0.0 { "to the right" } else { "to the left" }
        } else if dz > 0.0 {
            "toward the viewer"
        } else {
            "away from the viewer"
        };
        if dx.hypot(dz) > 0.3 {
            assert!(clip.caption.ends_with(word), "{}: travelled ({dx}, {dz})", clip.caption);
            seen.insert(word);
        }
    }
    assert!(seen.len() >= 3, "headings are drawn all round: {seen:?}");
}

#[test]
fn degenerate_skeletons_are_refused_with_the_reason() {
    let bone = |parent, head: V3, tail: V3| Bone { parent, head, tail };
    let good = vec![
        bone(None, [0.0; 3], [0.0, 1.0, 0.0]),
        bone(Some(0), [0.0, 1.0, 0.0], [0.0, 2.0, 0.0]),
    ];
    check_bones(&good).unwrap();
    let cases: Vec<(Vec<Bone>, &str)> = vec![
        (vec![], "needs 1"),
        (vec![bone(None, [0.0; 3], [0.0; 3])], "zero-length"),
        (
            vec![
                good[0].clone(),
                bone(Some(2), [0.0; 3], [1.0, 0.0, 0.0]),
                bone(Some(1), [0.0; 3], [0.0, 0.0, 1.0]),
            ],
            "cycle",
        ),
        (vec![good[0].clone(), bone(Some(1), [0.0; 3], [1.0, 0.0, 0.0])], "cycle"),
        (
            vec![good[0].clone(), bone(None, [0.0; 3], [1.0, 0.0, 0.0])],
            "second root",
        ),
        (vec![bone(Some(0), [0.0; 3], [1.0, 0.0, 0.0])], "root has a parent"),
        (vec![bone(None, [f32::NAN, 0.0, 0.0], [1.0, 0.0, 0.0])], "not finite"),
        (
            (0..=MAX_BONES)
                .map(|i| bone(i.checked_sub(1), [i as f32, 0.0, 0.0], [i as f32 + 1.0, 0.0, 0.0]))
                .collect(),
            "needs 1",
        ),
    ];
    for (bones, why) in cases {
        let e = check_bones(&bones).unwrap_err();
        assert!(e.to_string().contains(why), "{e} (wanted {why:?})");
    }
}

#[test]
fn degenerate_weights_are_refused_with_the_reason() {
    check_weights(&[[(0, 0.25), (1, 0.75)]], 2).unwrap();
    for (w, why) in [
        ([(0, 0.0), (1, 0.0)], "all-zero"),
        ([(0, 1.0), (5, 0.0)], "bone 5 of 2"),
        ([(0, f32::NAN), (1, 1.0)], "weights"),
        ([(0, -0.5), (1, 1.5)], "weights"),
        ([(0, 0.7), (1, 0.7)], "sum to"),
    ] {
        let e = check_weights(&[[(0, 1.0), (1, 0.0)], w], 2).unwrap_err();
        assert!(
            e.to_string().contains(why) && e.to_string().contains("weights[1]"),
            "{e} (wanted {why:?})"
        );
    }
}

#[test]
fn a_rigged_store_cannot_share_one_body_and_unknown_kinds_are_not_parsed() {
    let bad = SynthConfig {
        body: Some(crate::synth::ShapeFamily::Blob),
        ..cfg(1)
    };
    assert!(bad.validate().unwrap_err().to_string().contains("body"));
    assert_eq!(
        kinds("rigged-biped-fly-1-2_offset0_0-15").map(|k| k.1),
        Some(Action::Fly)
    );
    assert_eq!(kinds("rigged-dragon-walk-1-2"), None);
    assert_eq!(kinds("synth-blob-bend-1-2"), None);
    let e = generate_with(&cfg(1), 0, Template::Snake, Action::Fly).unwrap_err();
    assert!(e.to_string().contains("cannot fly"), "{e}");
}

#[test]
fn a_run_may_fix_the_template_or_the_action_under_a_source_of_its_own() {
    let fixed = |template, action| SynthConfig {
        family: Family::Rigged(crate::synth::RiggedKinds { template, action }),
        ..cfg(4)
    };
    let both = fixed(Some(Template::Bird), Some(Action::Fly));
    for i in 0..3 {
        let clip = synth_one(&both, i).unwrap();
        assert_eq!(kinds(&clip.id), Some((Template::Bird, Action::Fly)));
        assert_eq!(clip.source, format!("synth-rigged-bird-fly:4:{i}"));
    }
    let flyers = fixed(None, Some(Action::Fly));
    for i in 0..6 {
        assert_eq!(
            kinds(&synth_one(&flyers, i).unwrap().id).unwrap().0,
            Template::Bird,
            "only birds fly"
        );
    }
    let quads = fixed(Some(Template::Quadruped), None);
    let acts: HashSet<Action> = (0..24)
        .map(|i| kinds(&synth_one(&quads, i).unwrap().id).unwrap().1)
        .collect();
    assert!(
        acts.len() >= 5 && acts.iter().all(|a| Template::Quadruped.actions().contains(a)),
        "{acts:?}"
    );
    assert_eq!(quads.source(2), "synth-rigged-quadruped-any:4:2");
    let e = fixed(Some(Template::Snake), Some(Action::Jump))
        .validate()
        .unwrap_err()
        .to_string();
    assert!(e.contains("a snake cannot jump; it can slither"), "{e}");
}

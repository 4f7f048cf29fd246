//! Tests of the synthetic dataset: determinism, validity of every family pair, vertex spread, captions.

use std::collections::HashMap;

use super::*;

fn cfg(seed: u64) -> SynthConfig {
    SynthConfig {
        clips: 8,
        seed,
        ..SynthConfig::default()
    }
}

fn centroid(frame: &[[f32; 3]]) -> [f32; 3] {
    let n = frame.len() as f32;
    [0, 1, 2].map(|k| frame.iter().map(|p| p[k]).sum::<f32>() / n)
}

/// The largest axis-aligned extent of a frame (shared with the rigged characters' tests).
pub(super) fn extent(frame: &[[f32; 3]]) -> f32 {
    (0..3)
        .map(|k| {
            let (lo, hi) = frame.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), p| {
                (l.min(p[k]), h.max(p[k]))
            });
            hi - lo
        })
        .fold(0.0, f32::max)
}

#[test]
fn same_seed_same_clip_other_seed_other_clip() {
    let a = generate_one(&cfg(3), 5).unwrap();
    assert_eq!(a, generate_one(&cfg(3), 5).unwrap());
    assert_ne!(a.vertices, generate_one(&cfg(4), 5).unwrap().vertices);
    assert_ne!(a.vertices, generate_one(&cfg(3), 6).unwrap().vertices);
    let all = generate(&cfg(3)).unwrap();
    assert_eq!(all[5], a, "generate gives clip i from stream i");
    let (s, m) = families(&a.id).unwrap();
    assert_eq!(generate_with(&cfg(3), 5, s, m).unwrap(), a);
}

#[test]
fn every_family_pair_is_a_valid_visible_smooth_clip() {
    let c = cfg(11);
    for (i, shape) in ShapeFamily::ALL.into_iter().enumerate() {
        for (j, motion) in MotionFamily::ALL.into_iter().enumerate() {
            let clip = generate_with(&c, i * 7 + j, shape, motion).unwrap();
            let tag = format!("{} / {}: {}", shape.name(), motion.name(), clip.caption);
            clip.validate().unwrap();
            assert_eq!(families(&clip.id), Some((shape, motion)), "{tag}");
            assert!(
                (c.min_vertices..=c.max_vertices).contains(&clip.n_vertices),
                "{tag}: {}",
                clip.n_vertices
            );
            assert_eq!(clip.frames, 16);
            assert!(clip.caption.contains(shape.noun()), "{tag}");
            assert!(!clip.faces.is_empty(), "{tag}");
            let size = extent(clip.frame(0));
            assert!(size > 0.3 && size < 5.0, "{tag}: size {size}");
            // Visible: some vertex moves at least 10 % of the size over the clip.
            let f0 = clip.frame(0);
            let moved = (1..clip.frames)
                .flat_map(|f| clip.frame(f).iter().zip(f0).map(|(p, q)| dist(*p, *q)))
                .fold(0.0, f32::max);
            assert!(moved > 0.1 * size, "{tag}: largest displacement {moved} of size {size}");
            // Smooth: no vertex jumps more than 40 % of the size between consecutive frames.
            let step = (1..clip.frames)
                .flat_map(|f| clip.frame(f).iter().zip(clip.frame(f - 1)).map(|(p, q)| dist(*p, *q)))
                .fold(0.0, f32::max);
            assert!(step < 0.4 * size, "{tag}: frame step {step} of size {size}");
        }
    }
}

fn dist(p: [f32; 3], q: [f32; 3]) -> f32 {
    (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f32>().sqrt()
}

#[test]
fn closed_shapes_are_oriented_closed_surfaces_with_outward_faces() {
    for shape in ShapeFamily::ALL {
        let clip = generate_with(&cfg(2), 0, shape, MotionFamily::Squash).unwrap();
        let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
        for f in &clip.faces {
            for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
                *directed.entry((a, b)).or_default() += 1;
            }
        }
        if shape == ShapeFamily::Sheet {
            assert!(
                directed.keys().any(|&(a, b)| !directed.contains_key(&(b, a))),
                "the sheet has a border"
            );
            continue;
        }
        for (&(a, b), &count) in &directed {
            assert_eq!(count, 1, "{}: edge {a}->{b} used {count} times", shape.name());
            assert!(
                directed.contains_key(&(b, a)),
                "{}: edge {a}->{b} has no twin",
                shape.name()
            );
        }
        // Signed volume (divergence theorem) is positive when faces point outwards.
        let p = clip.frame(0);
        let vol: f32 = clip
            .faces
            .iter()
            .map(|f| {
                let (a, b, c) = (p[f[0] as usize], p[f[1] as usize], p[f[2] as usize]);
                a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                    + a[2] * (b[0] * c[1] - b[1] * c[0])
            })
            .sum::<f32>()
            / 6.0;
        assert!(vol > 0.0, "{}: signed volume {vol}", shape.name());
    }
}

#[test]
fn vertex_counts_spread_over_the_range() {
    let c = SynthConfig {
        clips: 120,
        seed: 9,
        ..SynthConfig::default()
    };
    let counts: Vec<usize> = generate(&c).unwrap().iter().map(|c| c.n_vertices).collect();
    assert!(counts.iter().all(|n| (512..=4096).contains(n)));
    let quarter = |q: usize| {
        counts
            .iter()
            .filter(|&&n| (n - 512) * 4 / (4096 - 512 + 1) == q)
            .count()
    };
    for q in 0..4 {
        assert!(
            quarter(q) >= 15,
            "quarter {q} of the range holds only {} of 120 clips",
            quarter(q)
        );
    }
}

#[test]
fn direction_words_match_the_motion() {
    // Sliding, walking and travelling jumps: the centroid moves the way the caption says.
    let c = cfg(5);
    let mut checked = 0;
    for index in 0..60 {
        let motion = [MotionFamily::Rigid, MotionFamily::Walk, MotionFamily::Jump][index % 3];
        let clip = generate_with(&c, index, ShapeFamily::ALL[index % 7], motion).unwrap();
        let (a, b) = (centroid(clip.frame(0)), centroid(clip.frame(clip.frames - 1)));
        let d = [b[0] - a[0], b[2] - a[2]];
        let word = if d[0].abs() > d[1].abs() {
            if d[0] > 0.0 { "to the right" } else { "to the left" }
        } else if d[1] > 0.0 {
            "toward the viewer"
        } else {
            "away from the viewer"
        };
        if clip.caption.contains("in place") {
            assert!(d[0].hypot(d[1]) < 0.05 * extent(clip.frame(0)), "{}", clip.caption);
        } else {
            assert!(clip.caption.ends_with(word), "{}: centroid moved {d:?}", clip.caption);
            checked += 1;
        }
    }
    assert!(checked > 30);
}

#[test]
fn twist_and_bend_words_match_the_motion() {
    // An upright tube: the top of a counterclockwise twist (seen from above) turns by a positive yaw; a bend
    // "to the right" moves the top to +x.
    let c = cfg(8);
    for index in 0..12 {
        let clip = generate_with(&c, index, ShapeFamily::Tube, MotionFamily::Twist).unwrap();
        let (f0, top) = (clip.frame(0), clip.frame(clip.frames / 4));
        let h = extent(f0);
        let cen = centroid(f0);
        // Mean yaw of the upper tenth: cross product of rest and moved xz offsets.
        let yaw: f32 = f0
            .iter()
            .zip(top)
            .filter(|(p, _)| p[1] > 0.9 * h)
            .map(|(p, q)| {
                let (u, v) = ([p[0] - cen[0], p[2] - cen[2]], [q[0] - cen[0], q[2] - cen[2]]);
                // Counterclockwise from above (+y) maps +x towards −z: z·x' − x·z' > 0.
                u[1] * v[0] - u[0] * v[1]
            })
            .sum();
        let ccw = clip.caption.contains("counterclockwise");
        assert_eq!(yaw > 0.0, ccw, "{}: yaw sum {yaw}", clip.caption);

        let clip = generate_with(&c, index, ShapeFamily::Tube, MotionFamily::Bend).unwrap();
        let top_v = (0..clip.n_vertices)
            .max_by(|&i, &j| f0_y(&clip, i).total_cmp(&f0_y(&clip, j)))
            .unwrap();
        let d = (1..clip.frames)
            .map(|f| {
                let (p, q) = (clip.frame(f)[top_v], clip.frame(0)[top_v]);
                [p[0] - q[0], p[2] - q[2]]
            })
            .max_by(|a, b| a[0].hypot(a[1]).total_cmp(&b[0].hypot(b[1])))
            .unwrap();
        let k = if d[0].abs() > d[1].abs() { 0 } else { 1 };
        let word = match (k, d[k] > 0.0) {
            (0, true) => "to the right",
            (0, false) => "to the left",
            (_, true) => "toward the viewer",
            (_, false) => "away from the viewer",
        };
        assert!(clip.caption.ends_with(word), "{}: top moved {d:?}", clip.caption);
    }
}

#[test]
fn spin_words_match_the_motion() {
    // Rigid spin: the yaw of offsets from the centroid, frame 0 → frame 4 (under half a turn).
    for index in 0..12 {
        let clip = generate_with(&cfg(4), index, ShapeFamily::Quadruped, MotionFamily::Rigid).unwrap();
        let (f0, f4) = (clip.frame(0), clip.frame(4));
        let (c0, c4) = (centroid(f0), centroid(f4));
        let yaw: f32 = f0
            .iter()
            .zip(f4)
            .map(|(p, q)| {
                let (u, v) = ([p[0] - c0[0], p[2] - c0[2]], [q[0] - c4[0], q[2] - c4[2]]);
                u[1] * v[0] - u[0] * v[1]
            })
            .sum();
        let ccw = clip.caption.contains("counterclockwise");
        assert_eq!(yaw > 0.0, ccw, "{}: yaw sum {yaw}", clip.caption);
    }
}

fn f0_y(clip: &Clip, v: usize) -> f32 {
    clip.frame(0)[v][1]
}

#[test]
fn bad_config_is_rejected_naming_the_field() {
    let e = generate_one(&SynthConfig { frames: 1, ..cfg(1) }, 0).unwrap_err();
    assert_eq!(e.field, "frames");
    let e = generate(&SynthConfig {
        min_vertices: 900,
        max_vertices: 1000,
        ..cfg(1)
    })
    .unwrap_err();
    assert_eq!(e.field, "max_vertices");
    assert_eq!(families("synth-blob-nope-1-2_offset0_0-15"), None);
    assert_eq!(families("other"), None);
}

/// Throughput of the generator: `cargo test -p any4d-data synth_speed -- --ignored --nocapture`.
#[test]
#[ignore]
fn synth_speed() {
    let c = SynthConfig {
        clips: 400,
        seed: 1,
        ..SynthConfig::default()
    };
    let start = std::time::Instant::now();
    let clips = generate(&c).unwrap();
    let secs = start.elapsed().as_secs_f64();
    let verts: usize = clips.iter().map(|c| c.n_vertices).sum();
    println!(
        "synth_speed: {} clips in {secs:.2} s = {:.0} clips/s ({} threads, mean {} vertices)",
        clips.len(),
        clips.len() as f64 / secs,
        rayon::current_num_threads(),
        verts / clips.len()
    );
}

#[test]
fn one_body_clips_share_one_topology_across_seeds_and_differ_in_motion() {
    let c = SynthConfig {
        clips: 6,
        seed: 9,
        min_vertices: 256,
        max_vertices: 600,
        body: Some(ShapeFamily::Humanoid),
        ..SynthConfig::default()
    };
    let clips = generate(&c).unwrap();
    // Another seed and clip count: the same rest mesh (a store may hold several synth runs).
    let other = generate(&SynthConfig {
        seed: 10,
        clips: 2,
        ..c.clone()
    })
    .unwrap();
    let first = &clips[0];
    for clip in clips.iter().chain(&other) {
        assert_eq!(families(&clip.id).unwrap().0, ShapeFamily::Humanoid, "{}", clip.id);
        assert_eq!(clip.n_vertices, first.n_vertices, "{}", clip.id);
        assert_eq!(clip.faces, first.faces, "{}", clip.id);
    }
    let motions: std::collections::HashSet<_> = clips.iter().map(|c| families(&c.id).unwrap().1).collect();
    assert!(motions.len() > 1, "six clips drew one motion family: {motions:?}");
    // Without the option the same seed gives several shapes.
    let free = generate(&SynthConfig { body: None, ..c }).unwrap();
    let shapes: std::collections::HashSet<_> = free.iter().map(|c| families(&c.id).unwrap().0).collect();
    assert!(shapes.len() > 1);
    assert_eq!(ShapeFamily::from_name("quadruped"), Some(ShapeFamily::Quadruped));
    assert_eq!(ShapeFamily::from_name("dragon"), None);
}

//! `any4d complete` and `any4d extend` with the shipped small RF on a procedural clip moved into user coordinates:
//! outputs in the user's frame and vertex order, keyframes reproduced bit for bit, samples seeded, the rollout
//! beyond one window, and clear errors for keyframe sets the method cannot use.

use std::path::{Path, PathBuf};

use any4d_data::Clip;
use any4d_data::formats::{read_clip, write_clip};
use any4d_data::synth::{SynthConfig, generate_one};

mod common;
use common::fixtures::copy_dir;
use common::{any4d, text};

fn shipped_rf() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("weights/small/rf")
        .display()
        .to_string()
}

/// Procedural clip 0 of seed 7 with `frames` frames, scaled by 40 and moved to (100, −20, 5): far from the
/// normalised frame, so an output left normalised would show.
fn user_clip(frames: usize) -> Clip {
    let cfg = SynthConfig {
        clips: 1,
        seed: 7,
        frames,
        min_vertices: 300,
        max_vertices: 700,
        body: None,
        family: Default::default(),
        scenes: false,
    };
    let mut clip = generate_one(&cfg, 0).unwrap();
    for p in &mut clip.vertices {
        *p = [p[0] * 40.0 + 100.0, p[1] * 40.0 - 20.0, p[2] * 40.0 + 5.0];
    }
    clip
}

fn run(args: &[&str]) -> (bool, String) {
    let out = any4d(args);
    let (stdout, stderr) = text(&out);
    (out.status.success(), format!("{stdout}\n{stderr}"))
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

/// An `.obj` of one axis-aligned box (the outward-wound faces of `any4d_data::scene::Scene::cuboid`).
fn cuboid_obj(lo: [f32; 3], hi: [f32; 3]) -> String {
    let box_ = any4d_data::scene::Scene::cuboid(lo, hi);
    let mut obj: String = box_
        .vertices
        .iter()
        .map(|v| format!("v {} {} {}\n", v[0], v[1], v[2]))
        .collect();
    for f in &box_.faces {
        obj += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    obj
}

fn centroid(frame: &[[f32; 3]]) -> [f32; 3] {
    let n = frame.len() as f32;
    [0, 1, 2].map(|k| frame.iter().map(|p| p[k]).sum::<f32>() / n)
}

#[test]
fn complete_a_clip_in_user_coordinates_with_exact_keyframes() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("walk.glb");
    let clip = user_clip(16);
    write_clip(&input, &clip).unwrap();
    let out = dir.path().join("done.glb");
    let (rf, inp, o) = (shipped_rf(), s(&input), s(&out));
    let base = [
        "complete",
        "--clip",
        &inp,
        "--keyframes",
        "0,15",
        "--rf",
        &rf,
        "--steps",
        "8",
        "--out",
        &o,
    ];
    let view = dir.path().join("done.html");
    let v = s(&view);
    // A slab far below the clip: every output is scored in it (no collision) and the page draws it; the scene
    // does not overlap the clip, which is said.
    let scene = dir.path().join("far.obj");
    std::fs::write(&scene, cuboid_obj([-1e3, -2e3, -1e3], [1e3, -1.5e3, 1e3])).unwrap();
    let sc = s(&scene);
    let mut with_view = base.to_vec();
    with_view.extend(["--view", &v, "--scene", &sc]);
    let (ok, log) = run(&with_view);
    assert!(ok, "{log}");
    assert!(
        log.contains("sample 0 (seed 42) in the scene: collision frames 0.000"),
        "{log}"
    );
    assert!(log.contains("does not overlap"), "{log}");
    let page = std::fs::read_to_string(&view).unwrap();
    assert!(
        page.contains("\"keyframes\":[0,15]") && page.contains("sample 0 (seed 42)"),
        "the viewer page"
    );
    assert!(page.contains("\"scene\":{"), "the page draws the scene");
    let got = read_clip(&out).unwrap();
    let source = read_clip(&input).unwrap();
    assert_eq!((got.frames, got.n_vertices), (16, source.n_vertices));
    assert_eq!(
        got.faces, source.faces,
        "the user's triangles, in the user's vertex order"
    );
    for f in [0, 15] {
        assert_eq!(got.frame(f), source.frame(f), "keyframe {f} is the input, bit for bit");
    }
    assert_ne!(got.frame(7), source.frame(0), "in-between frames are generated");
    // In the user's coordinates: each generated frame's centroid lies near the input's (size 40, offset 100).
    for f in 1..15 {
        let (a, b) = (centroid(got.frame(f)), centroid(source.frame(f)));
        let d = (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>().sqrt();
        assert!(d < 40.0, "frame {f}: centroid {a:?} vs {b:?}");
    }

    // Two samples: sample 0 is the single sample of the same seed, sample 1 differs.
    let many = dir.path().join("many.glb");
    let m = s(&many);
    let mut args = base.to_vec();
    args.pop();
    args.extend([&m, "--samples", "2"]);
    let (ok, log) = run(&args);
    assert!(ok, "{log}");
    let s0 = read_clip(&dir.path().join("many_s0.glb")).unwrap();
    let s1 = read_clip(&dir.path().join("many_s1.glb")).unwrap();
    // The two samples share network calls (a batch of 2): sample 0 is the single sample up to float rounding.
    let diff = s0
        .vertices
        .iter()
        .zip(&got.vertices)
        .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
        .fold(0.0f32, f32::max);
    assert!(
        diff < 1e-3,
        "sample 0 = the single sample of seed 42, up to rounding: {diff}"
    );
    assert_ne!(s1.vertices, s0.vertices, "sample 1 has its own noise");
}

#[test]
fn complete_from_separate_meshes_and_extend_past_one_window() {
    let dir = tempfile::tempdir().unwrap();
    let clip = user_clip(31);
    // Keyframe meshes as single OBJ files (the first file of a written two-frame OBJ folder each).
    let key = |f: usize| -> PathBuf {
        let one = Clip::new(
            format!("k{f}"),
            clip.frame(f).repeat(2),
            2,
            clip.n_vertices,
            clip.faces.clone(),
            "",
            "test",
        )
        .unwrap();
        let folder = dir.path().join(format!("k{f}"));
        write_clip(&folder, &one).unwrap();
        let file = std::fs::read_dir(&folder)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.extension().is_some_and(|e| e == "obj"))
            .unwrap();
        let named = dir.path().join(format!("key{f}.obj"));
        std::fs::copy(file, &named).unwrap();
        named
    };
    let (k0, k15, k30) = (key(0), key(15), key(30));
    let rf = shipped_rf();
    let out = dir.path().join("long.bin");
    let keys = [
        format!("0={}", s(&k0)),
        format!("15={}", s(&k15)),
        format!("30={}", s(&k30)),
    ];
    let o = s(&out);
    let (ok, log) = run(&[
        "extend",
        "--key",
        &keys[0],
        "--key",
        &keys[1],
        "--key",
        &keys[2],
        "--frames",
        "31",
        "--caption",
        "",
        "--rf",
        &rf,
        "--steps",
        "8",
        "--out",
        &o,
    ]);
    assert!(ok, "{log}");
    let got = read_clip(&out).unwrap();
    let reference = read_clip(&dir.path().join("k0")).unwrap();
    assert_eq!((got.frames, got.n_vertices), (31, clip.n_vertices));
    for (f, k) in [(0, "k0"), (15, "k15"), (30, "k30")] {
        let given = read_clip(&dir.path().join(k)).unwrap();
        assert_eq!(got.frame(f), given.frame(0), "keyframe {f} is the given mesh");
    }
    assert_ne!(got.frame(20), reference.frame(0));

    // `extend` without a length, a key set without frame 0, and a mesh of another topology are refused clearly.
    let (ok, log) = run(&["extend", "--key", &keys[0], "--key", &keys[1], "--rf", &rf, "--out", &o]);
    assert!(!ok && log.contains("--frames"), "{log}");
    let (ok, log) = run(&[
        "complete", "--key", &keys[1], "--key", &keys[2], "--rf", &rf, "--out", &o,
    ]);
    assert!(!ok && log.contains("frame 0 must be given"), "{log}");
    let other = dir.path().join("other.obj");
    std::fs::write(&other, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let bad = format!("15={}", s(&other));
    let (ok, log) = run(&["complete", "--key", &keys[0], "--key", &bad, "--rf", &rf, "--out", &o]);
    assert!(!ok && log.contains("other.obj") && log.contains("topology"), "{log}");
}

#[test]
fn bad_requests_name_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("clip.glb");
    write_clip(&input, &user_clip(16)).unwrap();
    let (rf, inp) = (shipped_rf(), s(&input));
    let o = s(&dir.path().join("o.glb"));
    for (args, needle) in [
        (vec!["--keyframes", "0,16"], "frame 16 is outside"),
        (vec!["--keyframes", "0,7,7"], "given twice"),
        (vec!["--keyframes", "0,15", "--frames", "8"], "at least"),
        (vec!["--keyframes", "0,15", "--samples", "0"], "--samples 0 is outside"),
        (
            vec!["--keyframes", "0,15", "--samples", "1000000000000"],
            "outside 1..=1000",
        ),
    ] {
        let mut all = vec!["complete", "--clip", &inp, "--rf", &rf, "--out", &o, "--steps", "4"];
        all.extend(args.iter().copied());
        let (ok, log) = run(&all);
        assert!(!ok && log.contains(needle), "{args:?}: {log}");
    }
    let (ok, log) = run(&["complete", "--key", "zero=a.obj", "--out", &o]);
    assert!(!ok && log.contains("not a frame index"), "{log}");
    let missing = s(&dir.path().join("no-such-run"));
    let (ok, log) = run(&[
        "complete",
        "--clip",
        &inp,
        "--keyframes",
        "0,15",
        "--rf",
        &missing,
        "--out",
        &o,
    ]);
    assert!(!ok && log.contains("no-such-run"), "{log}");
    // Nothing to complete, a key past the requested length, an output that exists.
    let (ok, log) = run(&["complete", "--rf", &rf, "--out", &o]);
    assert!(!ok && log.contains("give the keyframes"), "{log}");
    let (k0, k20) = (format!("0={inp}"), format!("20={inp}"));
    let (ok, log) = run(&[
        "complete", "--key", &k0, "--key", &k20, "--frames", "16", "--rf", &rf, "--out", &o,
    ]);
    assert!(!ok && log.contains("frame 20 is outside the 16 frames"), "{log}");
    let (ok, log) = run(&[
        "complete",
        "--clip",
        &inp,
        "--keyframes",
        "0,15",
        "--rf",
        &rf,
        "--out",
        &inp,
    ]);
    assert!(!ok && log.contains("exists") && log.contains("--force"), "{log}");
    // An RF whose recorded VAE checkpoint is not the VAE run's: its latents would not match.
    let copy = dir.path().join("rf-copy");
    copy_dir(Path::new(&rf), &copy);
    let vae = Path::new(&rf).join("../vae").canonicalize().unwrap();
    std::fs::write(
        copy.join("vae_run.json"),
        format!("{{\"run\": {:?}, \"step\": 999}}", vae.display().to_string()),
    )
    .unwrap();
    let c = s(&copy);
    let (ok, log) = run(&[
        "complete",
        "--clip",
        &inp,
        "--keyframes",
        "0,15",
        "--rf",
        &c,
        "--out",
        &o,
    ]);
    assert!(
        !ok && log.contains("step 999") && log.contains("latents changed"),
        "{log}"
    );
    // --vae must be the VAE the RF was trained on.
    let other_vae = s(&Path::new(&rf).join("../baseline-rf"));
    let (ok, log) = run(&[
        "complete",
        "--clip",
        &inp,
        "--keyframes",
        "0,15",
        "--rf",
        &rf,
        "--vae",
        &other_vae,
        "--out",
        &o,
    ]);
    assert!(!ok && log.contains("is not the VAE run the RF"), "{log}");
    let same_vae = s(&Path::new(&rf).join("../vae"));
    let good = s(&dir.path().join("with-vae.glb"));
    let (ok, log) = run(&[
        "complete",
        "--clip",
        &inp,
        "--keyframes",
        "0,15",
        "--rf",
        &rf,
        "--vae",
        &same_vae,
        "--out",
        &good,
        "--steps",
        "2",
    ]);
    assert!(ok, "{log}");
    // Fewer vertices than the VAE's P = 128 tokens.
    let tiny = dir.path().join("tiny.obj");
    std::fs::write(&tiny, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\n").unwrap();
    let k0 = format!("0={}", s(&tiny));
    let (ok, log) = run(&["complete", "--key", &k0, "--rf", &rf, "--out", &o]);
    assert!(!ok && log.contains("fewer than the P = 128"), "{log}");
}

#[test]
fn the_readme_example_completes_the_shipped_poses() {
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let (start, end) = (
        root.join("examples/twist/start.obj"),
        root.join("examples/twist/end.obj"),
    );
    let (out, view) = (dir.path().join("twist.glb"), dir.path().join("twist.html"));
    let (k0, k15) = (format!("0={}", s(&start)), format!("15={}", s(&end)));
    let (o, v, rf) = (s(&out), s(&view), shipped_rf());
    let caption = "a small lumpy blob twisting slowly counterclockwise";
    let (ok, log) = run(&[
        "complete",
        "--key",
        &k0,
        "--key",
        &k15,
        "--caption",
        caption,
        "--out",
        &o,
        "--view",
        &v,
        "--rf",
        &rf,
        "--steps",
        "8",
    ]);
    assert!(ok, "{log}");
    let got = read_clip(&out).unwrap();
    assert_eq!(got.frames, 16);
    assert!(view.is_file());
    let given = std::fs::read_to_string(&start).unwrap();
    let first_vertex = given.lines().find(|l| l.starts_with("v ")).unwrap();
    let xyz: Vec<f32> = first_vertex[2..]
        .split_whitespace()
        .map(|x| x.parse().unwrap())
        .collect();
    assert_eq!(got.frame(0)[0].to_vec(), xyz, "frame 0 is start.obj");
}

#[test]
fn average_writes_the_mean_of_the_samples_with_exact_keyframes() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("walk.bin");
    let clip = user_clip(16);
    write_clip(&input, &clip).unwrap();
    let (rf, inp) = (shipped_rf(), s(&input));
    let go = |out: &Path, extra: &[&str]| {
        let o = s(out);
        let mut args = vec![
            "complete",
            "--clip",
            &inp,
            "--keyframes",
            "0,6,15",
            "--rf",
            &rf,
            "--steps",
            "4",
            "--samples",
            "3",
            "--out",
            &o,
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    let (ok, log) = go(&dir.path().join("s.bin"), &[]);
    assert!(ok, "{log}");
    let mean_path = dir.path().join("mean.bin");
    let (ok, log) = go(&mean_path, &["--average"]);
    assert!(ok, "{log}");
    assert!(!dir.path().join("mean_s0.bin").exists(), "--average writes one file");
    let samples: Vec<Clip> = (0..3)
        .map(|k| read_clip(&dir.path().join(format!("s_s{k}.bin"))).unwrap())
        .collect();
    let mean = read_clip(&mean_path).unwrap();
    assert_eq!((mean.frames, mean.n_vertices), (16, clip.n_vertices));
    for f in [0, 6, 15] {
        assert_eq!(mean.frame(f), clip.frame(f), "keyframe {f} is not exact");
    }
    let mut spread = 0.0f32;
    for (i, m) in mean.vertices.iter().enumerate() {
        for c in 0..3 {
            let want = samples.iter().map(|x| x.vertices[i][c]).sum::<f32>() / 3.0;
            assert!(
                (m[c] - want).abs() <= 1e-4 * want.abs().max(1.0),
                "row {i}: {m:?} vs {want}"
            );
            spread = spread.max((samples[0].vertices[i][c] - want).abs());
        }
    }
    assert!(spread > 1e-3, "the samples should differ, or the mean proves nothing");
    let (ok, log) = run(&[
        "complete",
        "--clip",
        &inp,
        "--keyframes",
        "0,15",
        "--rf",
        &rf,
        "--average",
        "--out",
        &s(&mean_path),
        "--force",
    ]);
    assert!(!ok && log.contains("--samples 2 or more"), "{log}");
}

#[test]
fn correct_moves_the_in_between_frames_by_a_residual_linear_between_keyframes() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("walk.bin");
    let clip = user_clip(16);
    write_clip(&input, &clip).unwrap();
    let (rf, inp) = (shipped_rf(), s(&input));
    let go = |out: &Path, extra: &[&str]| {
        let o = s(out);
        let mut args = vec![
            "complete",
            "--clip",
            &inp,
            "--keyframes",
            "0,6,15",
            "--rf",
            &rf,
            "--steps",
            "4",
            "--out",
            &o,
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    let (raw_path, fixed_path) = (dir.path().join("raw.bin"), dir.path().join("fixed.bin"));
    let (ok, log) = go(&raw_path, &[]);
    assert!(ok, "{log}");
    let (ok, log) = go(&fixed_path, &["--correct"]);
    assert!(ok, "{log}");
    let (raw, fixed) = (read_clip(&raw_path).unwrap(), read_clip(&fixed_path).unwrap());
    for f in [0, 6, 15] {
        assert_eq!(fixed.frame(f), clip.frame(f), "keyframe {f} is not exact");
    }
    // docs/method.md §5.6: the correction of frame f is the keyframes' residual interpolated linearly in f, so its
    // second difference vanishes inside each keyframe segment (normalisation is affine, so this holds in user
    // coordinates too).
    let n = clip.n_vertices;
    let d = |f: usize, i: usize, c: usize| fixed.vertices[f * n + i][c] - raw.vertices[f * n + i][c];
    let (mut moved, mut bend) = (0.0f32, 0.0f32);
    for i in 0..n {
        for c in 0..3 {
            moved = moved.max(d(10, i, c).abs());
            for f in 8..14 {
                bend = bend.max((d(f + 1, i, c) - 2.0 * d(f, i, c) + d(f - 1, i, c)).abs());
            }
        }
    }
    assert!(moved > 1e-4, "--correct should move the in-between frames");
    assert!(
        bend < 1e-3 * moved.max(1e-3),
        "not linear between keyframes: {bend} vs {moved}"
    );
}

//! `any4d data …` and `any4d bench data` run as a user would: the built binary, its exit code and its output.

use std::path::Path;

use any4d_data::Clip;
use any4d_data::formats;

mod common;
use common::{any4d, text};

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// A clip of `n` vertices on a slowly moving grid, far from the origin, with a triangle strip.
fn grid_clip(id: &str, frames: usize, n: usize) -> Clip {
    let vertices = (0..frames)
        .flat_map(|f| {
            (0..n).map(move |v| {
                [
                    5.0 + (v % 25) as f32 * 0.1 + 0.01 * f as f32,
                    2.0 + (v / 25) as f32 * 0.1,
                    (v % 7) as f32 * 0.05,
                ]
            })
        })
        .collect();
    let faces = (0..n as u32 - 2).map(|i| [i, i + 1, i + 2]).collect();
    Clip::new(id, vertices, frames, n, faces, "a test grid", "test").unwrap()
}

#[test]
fn synth_inspect_and_render_a_store() {
    let tmp = tempfile::tempdir().unwrap();
    let store = tmp.path().join("store");
    let out = any4d(&[
        "data",
        "synth",
        "--out",
        p(&store),
        "--clips",
        "3",
        "--seed",
        "5",
        "--p",
        "16",
    ]);
    assert!(out.status.success(), "{:?}", text(&out));

    let out = any4d(&["data", "inspect", p(&store), "--format", "json"]);
    assert!(out.status.success(), "{:?}", text(&out));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["clips"], 3);
    assert_eq!(json["ok"], 3);
    assert_eq!(json["rejected"], 0);
    assert_eq!(json["train"].as_u64().unwrap() + json["val"].as_u64().unwrap(), 3);

    let out = any4d(&["data", "inspect", p(&store)]);
    let (stdout, _) = text(&out);
    assert!(out.status.success() && stdout.contains("3 ok"), "{stdout}");

    let sheet = tmp.path().join("sheet.png");
    let out = any4d(&["data", "render", p(&store), "--out", p(&sheet)]);
    assert!(out.status.success(), "{:?}", text(&out));
    assert_eq!(&std::fs::read(&sheet).unwrap()[..8], b"\x89PNG\r\n\x1a\n");

    let out = any4d(&[
        "data",
        "render",
        p(&store),
        "--clip",
        "no-such-clip",
        "--out",
        p(&sheet),
    ]);
    let (_, stderr) = text(&out);
    assert!(!out.status.success() && stderr.contains("no-such-clip"), "{stderr}");
}

#[test]
fn convert_changes_nothing_unless_asked() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("grid.bin");
    let clip = grid_clip("grid_offset0_0-3", 4, 50);
    formats::write_clip(&src, &clip).unwrap();

    let glb = tmp.path().join("grid.glb");
    let out = any4d(&["data", "convert", p(&src), p(&glb)]);
    assert!(out.status.success(), "{:?}", text(&out));
    let back = formats::read_clip(&glb).unwrap();
    assert_eq!((back.frames, back.n_vertices, back.faces.len()), (4, 50, 48));
    assert!(
        back.vertices
            .iter()
            .zip(&clip.vertices)
            .all(|(a, b)| (0..3).all(|k| (a[k] - b[k]).abs() < 1e-5))
    );

    let norm = tmp.path().join("norm.bin");
    let out = any4d(&["data", "convert", p(&src), p(&norm), "--normalize"]);
    assert!(out.status.success(), "{:?}", text(&out));
    let n = formats::read_clip(&norm).unwrap();
    let max = n
        .frame(0)
        .iter()
        .flat_map(|q| q.iter().map(|x| x.abs()))
        .fold(0.0f32, f32::max);
    assert!((max - 1.0).abs() < 1e-5, "normalised frame 0 has L∞ extent {max}");

    let info = any4d(&["data", "inspect", p(&src), "--format", "json"]);
    let json: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    assert_eq!(
        (json["frames"].as_u64(), json["vertices"].as_u64()),
        (Some(4), Some(50))
    );
}

#[test]
fn import_lists_rejected_files_and_fails() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    std::fs::create_dir(&src).unwrap();
    formats::write_clip(&src.join("good.bin"), &grid_clip("good_offset0_0-15", 16, 40)).unwrap();
    let store = tmp.path().join("store");
    let args = [
        "--out",
        p(&store),
        "--min-vertices",
        "16",
        "--max-vertices",
        "64",
        "--p",
        "8",
    ];

    let out = any4d(&[&["data", "import", p(&src)], &args[..]].concat());
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout} {stderr}");
    assert!(stdout.contains("1 clips added"), "{stdout}");

    std::fs::write(src.join("broken.bin"), b"not a pickle").unwrap();
    let out = any4d(&[&["data", "import", p(&src)], &args[..]].concat());
    let (stdout, _) = text(&out);
    assert_eq!(out.status.code(), Some(2), "{stdout}");
    assert!(stdout.contains("rejected") && stdout.contains("broken.bin"), "{stdout}");
    assert!(
        stdout.contains("holds 1 clips"),
        "re-import must not duplicate: {stdout}"
    );
}

#[test]
fn missing_files_fail_with_their_name() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("missing.bin");
    let sheet = tmp.path().join("s.png");
    let out_bin = tmp.path().join("o.bin");
    for args in [
        vec!["data", "inspect", p(&missing)],
        vec!["data", "convert", p(&missing), p(&out_bin)],
        vec!["data", "render", p(&missing), "--out", p(&sheet)],
    ] {
        let out = any4d(&args);
        let (_, stderr) = text(&out);
        assert!(!out.status.success(), "{args:?} should fail");
        assert!(stderr.contains("missing.bin"), "{args:?}: {stderr}");
    }
    let out = any4d(&["data", "import", p(&missing), "--out", p(&tmp.path().join("st"))]);
    let (stdout, _) = text(&out);
    assert!(!out.status.success() && stdout.contains("missing.bin"), "{stdout}");
}

#[test]
fn bench_data_reports_throughput() {
    let out = any4d(&[
        "bench",
        "data",
        "--clips",
        "2",
        "--vertices",
        "600",
        "--frames",
        "4",
        "--p",
        "16",
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout} {stderr}");
    assert!(
        stdout.contains("ours (1 thread)") && stdout.contains("clips/s"),
        "{stdout}"
    );
    // Every reader is timed on the same clips written in its format.
    for format in [
        "bin", "glb", "anime", "obj-seq", "md2", "md3", "iqm", "md5", "pmd", "b3d", "spm", "x", "fbx", "dae",
    ] {
        assert!(
            stdout
                .lines()
                .any(|l| l.trim_start().starts_with(format) && l.ends_with("clips/s")),
            "{format}: {stdout}"
        );
    }
    if stdout.contains("numpy reference") {
        assert!(
            stdout.contains("FPS indices agree") && stdout.contains(": yes"),
            "{stdout}"
        );
    }
}

/// The size limits a user with large real data may raise (`--limit-frames`, `--limit-clip-vertices`,
/// `--limit-file-bytes`, `--limit-buffer-bytes`): an input over a limit is refused with the flag that raises it, the flag
/// moves the limit (either way), and values outside `1..=ceiling` are refused before anything runs.
#[test]
fn size_limits_are_named_in_refusals_and_adjustable_within_their_ceilings() {
    let tmp = tempfile::tempdir().unwrap();
    let store = tmp.path().join("store");
    let synth = |extra: &[&str]| {
        let mut args = vec![
            "data",
            "synth",
            "--out",
            p(&store),
            "--clips",
            "1",
            "--seed",
            "1",
            "--max-vertices",
            "4096",
        ];
        args.extend_from_slice(extra);
        let out = any4d(&args);
        assert!(!out.status.success());
        text(&out).1
    };
    let err = synth(&["--frames", "20000"]);
    assert!(err.contains("20000") && err.contains("--limit-frames"), "{err}");
    // Raised past the frame limit, the same request now meets the vertex-row limit (20000 × 4096 > 2^26).
    let err = synth(&["--frames", "20000", "--limit-frames", "20000"]);
    assert!(
        err.contains("vertex rows") && err.contains("--limit-clip-vertices"),
        "{err}"
    );
    assert!(!store.exists());
    for (flag, value) in [
        ("--limit-frames", "0"),
        ("--limit-frames", "1000001"),
        ("--limit-clip-vertices", "99999999999"),
        ("--limit-file-bytes", "0"),
        ("--limit-buffer-bytes", "18446744073709551615"),
    ] {
        let out = any4d(&["data", "inspect", "no-such-file.bin", flag, value]);
        let (_, err) = text(&out);
        assert!(
            !out.status.success() && err.contains(flag) && err.contains("must be in 1..="),
            "{err}"
        );
    }
    let obj = tmp.path().join("grid.bin");
    formats::write_clip(&obj, &grid_clip("grid", 4, 40)).unwrap();
    let out = any4d(&["--limit-file-bytes", "100", "data", "inspect", p(&obj)]);
    let (stdout, err) = text(&out);
    assert!(
        format!("{stdout}{err}").contains("more than the limit of 100 bytes (raise with --limit-file-bytes)"),
        "{stdout}{err}"
    );
    let out = any4d(&["data", "inspect", p(&obj)]);
    assert!(out.status.success(), "{:?}", text(&out));
    // Every reader applies the frame limit: a pickle of 101 frames and an OBJ folder of 3 frames over limits of
    // 100 and 2.
    let long = tmp.path().join("long.bin");
    formats::write_clip(&long, &grid_clip("long", 101, 4)).unwrap();
    let folder = tmp.path().join("seq");
    formats::obj::write_obj_seq(&folder, &grid_clip("seq", 3, 4)).unwrap();
    for (path, limit, frames) in [(&long, "100", "101 frames"), (&folder, "2", "3 .obj frames")] {
        let out = any4d(&["--limit-frames", limit, "data", "inspect", p(path)]);
        let (stdout, err) = text(&out);
        let all = format!("{stdout}{err}");
        assert!(
            all.contains(frames) && all.contains("(raise with --limit-frames)"),
            "{all}"
        );
        assert!(any4d(&["data", "inspect", p(path)]).status.success());
    }
}

#[test]
fn a_one_body_store_trains_the_acap_bdlstm_from_the_command_line() {
    let tmp = tempfile::tempdir().unwrap();
    let store = tmp.path().join("one");
    let synth = |body: &str| {
        any4d(&[
            "data",
            "synth",
            "--out",
            p(&store),
            "--clips",
            "12",
            "--seed",
            "2",
            "--frames",
            "16",
            "--min-vertices",
            "256",
            "--max-vertices",
            "512",
            "--p",
            "16",
            "--body",
            body,
        ])
    };
    let out = synth("dragon");
    let (_, stderr) = text(&out);
    assert!(!out.status.success() && stderr.contains("humanoid"), "{stderr}");
    let out = synth("worm");
    assert!(out.status.success(), "{:?}", text(&out));
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/bdlstm/acap_tiny.toml");
    let runs = tmp.path().join("runs");
    let train = |extra: &[&str]| {
        let mut args = vec![
            "train",
            "bdlstm",
            "--data",
            p(&store),
            "--runs-dir",
            p(&runs),
            "--set",
            "train.duration={ steps = 2 }",
        ];
        args.extend_from_slice(extra);
        any4d(&args)
    };
    // The latent preset needs a VAE; --variant acap on the same preset trains without one.
    let latent = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/bdlstm/tiny.toml");
    let out = train(&["--config", p(&latent)]);
    assert!(
        !out.status.success() && text(&out).1.contains("--vae"),
        "{:?}",
        text(&out)
    );
    let out = train(&["--config", p(&latent), "--variant", "acap"]);
    assert!(out.status.success(), "{:?}", text(&out));
    let out = train(&["--config", p(&config)]);
    assert!(out.status.success(), "{:?}", text(&out));
    let run = runs.join("bdlstm-2");
    assert!(run.join("acap.json").is_file());
    let out = any4d(&[
        "train",
        "bdlstm",
        "--data",
        p(&store),
        "--resume",
        p(&run),
        "--variant",
        "latent",
    ]);
    assert!(
        !out.status.success() && text(&out).1.contains("--variant"),
        "{:?}",
        text(&out)
    );
    // The row on the store it was trained on.
    let eval = tmp.path().join("eval");
    let out = any4d(&[
        "eval",
        "run",
        "--protocol",
        "table1",
        "--data",
        p(&store),
        "--methods",
        "bdlstm_acap,lerp",
        "--bdlstm-acap",
        p(&run),
        "--clips",
        "1",
        "--out",
        p(&eval),
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("| bdlstm_acap | random | 0 |"), "{stdout}");
}

#[test]
fn rigged_characters_add_to_a_store_and_their_choices_are_checked() {
    let tmp = tempfile::tempdir().unwrap();
    let store = tmp.path().join("store");
    let synth = |extra: &[&str]| {
        let mut args = vec![
            "data",
            "synth",
            "--out",
            p(&store),
            "--clips",
            "4",
            "--seed",
            "5",
            "--p",
            "16",
        ];
        args.extend_from_slice(extra);
        any4d(&args)
    };
    let out = synth(&[]);
    assert!(out.status.success(), "{:?}", text(&out));
    let out = synth(&["--family", "rigged"]);
    assert!(out.status.success(), "{:?}", text(&out));
    let out = synth(&["--family", "rigged", "--template", "bird", "--action", "fly"]);
    assert!(out.status.success(), "{:?}", text(&out));
    let out = any4d(&["data", "inspect", p(&store), "--format", "json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        json["clips"], 12,
        "the same seed in three generators adds, it does not replace: {json}"
    );
    let families = json["synthetic_families"].as_object().unwrap();
    let birds = families.get("rigged-bird-fly").and_then(|n| n.as_u64()).unwrap_or(0);
    assert!(birds >= 4, "{families:?}");
    let sheet = tmp.path().join("bird.png");
    let out = any4d(&[
        "data",
        "render",
        p(&store),
        "--clip",
        "rigged-bird-fly-5-0_offset0_0-15",
        "--out",
        p(&sheet),
    ]);
    assert!(out.status.success(), "{:?}", text(&out));
    for (extra, needle) in [
        (
            vec!["--family", "rigged", "--template", "snake", "--action", "jump"],
            "a snake cannot jump",
        ),
        (vec!["--template", "biped"], "--family rigged"),
        (vec!["--family", "rigged", "--template", "dragon"], "biped, quadruped"),
        (vec!["--family", "rigged", "--action", "swim"], "slither"),
        (vec!["--family", "blobs"], "shapes, rigged"),
        (vec!["--family", "rigged", "--body", "worm"], "body"),
    ] {
        let out = synth(&extra);
        let (_, stderr) = text(&out);
        assert!(!out.status.success() && stderr.contains(needle), "{extra:?}: {stderr}");
    }
}

/// `data render` draws a store clip in the scene stored with it: the same clip with and without `--scenes` renders
/// differently (the furniture), and `--scene` is refused beside a store.
#[test]
fn render_draws_a_store_clips_scene() {
    let tmp = tempfile::tempdir().unwrap();
    let sheet = |name: &str, scenes: bool| {
        let store = tmp.path().join(name);
        let mut args = vec![
            "data",
            "synth",
            "--out",
            p(&store),
            "--clips",
            "2",
            "--seed",
            "5",
            "--p",
            "16",
        ];
        if scenes {
            args.push("--scenes");
        }
        let out = any4d(&args);
        assert!(out.status.success(), "{:?}", text(&out));
        let png = tmp.path().join(format!("{name}.png"));
        let out = any4d(&["data", "render", p(&store), "--out", p(&png)]);
        assert!(out.status.success(), "{:?}", text(&out));
        (store, image::open(&png).unwrap().to_rgb8())
    };
    let (_, bare) = sheet("bare", false);
    let (scened, in_scene) = sheet("scened", true);
    assert_eq!(
        bare.dimensions(),
        in_scene.dimensions(),
        "the clip and its framing are the same"
    );
    let differ = bare.pixels().zip(in_scene.pixels()).filter(|(a, b)| a != b).count();
    assert!(differ > 100, "the scene should show: {differ} pixels differ");
    let obj = tmp.path().join("floor.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 2 3\n").unwrap();
    let png = tmp.path().join("x.png");
    let out = any4d(&["data", "render", p(&scened), "--scene", p(&obj), "--out", p(&png)]);
    let (_, err) = text(&out);
    assert!(!out.status.success() && err.contains("scene stored with it"), "{err}");
}

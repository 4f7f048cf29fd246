//! Mutation fuzzing of the skeletal and scene readers and of their sidecars (IQM and its animation-only files,
//! MD2 and its `.anm` table, MD3 and its `animation.cfg`, a Quake III player assembled from three MD3 parts, MD5
//! mesh and animation, PMD and PSA, B3D, SuperTuxKart `.spm` and its `kart.xml`, DirectX `.x`, binary FBX, COLLADA, BVH retargeted onto an IQM rig,
//! `.anime`), on the stable toolchain: each case writes its
//! seed files (made by the readers' own test writers) into a folder, then mutates one file of it — the model or
//! one sidecar — with byte- and token-level mutations plus repeated slices (deep nesting, long counts) and reads
//! the model through `formats::read_take`, asserting a clean `Ok` or error, never a panic.
//!
//! `cargo test -p any4d-data --test fuzz_readers` runs [`QUICK_RUNS`] inputs per case; the long run is ignored:
//!
//! ```sh
//! ANY4D_FUZZ_SECS=120 nice -n 15 cargo test -p any4d-data --test fuzz_readers -- --ignored --nocapture
//! ```

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;
use std::time::{Duration, Instant};

use any4d_data::Clip;
use any4d_data::formats::skeletal::ReadOptions;
use any4d_data::formats::{self, PANIC_FIELD, anime, b3d, bvh, dae, fbx, iqm, md2, md3, pmd, spm, x};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

mod fuzz_common;
use fuzz_common::{Tally, kind, mutate_once, replace_number};

/// Inputs per case in the default test run.
const QUICK_RUNS: usize = 1500;

/// One reader under test: the file read, the file mutated (the model itself or a sidecar), the files written
/// beside them once, and the seeds of the mutated file.
struct Case {
    name: &'static str,
    read: &'static str,
    mutated: &'static str,
    fixed: Vec<(&'static str, Vec<u8>)>,
    seeds: Vec<Vec<u8>>,
    text: bool,
}

/// A strip of `n` quads in the z = 0 plane, vertex `v` on joint `v % 2`.
fn strip(n: usize) -> (Vec<[f32; 3]>, Vec<[u32; 3]>, Vec<u8>) {
    let pos: Vec<[f32; 3]> = (0..2 * n).map(|v| [(v / 2) as f32, (v % 2) as f32, 0.0]).collect();
    let faces = (0..n as u32 - 1)
        .flat_map(|q| [[2 * q, 2 * q + 2, 2 * q + 1], [2 * q + 1, 2 * q + 2, 2 * q + 3]])
        .collect();
    let skin = (0..2 * n).map(|v| (v % 2) as u8).collect();
    (pos, faces, skin)
}

/// Per frame, two joint translations: the root still, the second rising.
fn keys(frames: usize) -> Vec<Vec<[f32; 3]>> {
    (0..frames)
        .map(|f| vec![[0.0; 3], [0.0, 0.1 * f as f32, 0.0]])
        .collect()
}

const MD5_MESH: &str = "MD5Version 10\ncommandline \"\"\nnumJoints 2\nnumMeshes 1\njoints {\n\
    \"root\" -1 ( 0 0 0 ) ( 0 0 0 )\n\"tip\" 0 ( 0 0 1 ) ( 0 0 0 )\n}\nmesh {\nnumverts 3\n\
    vert 0 ( 0 0 ) 0 1\nvert 1 ( 0 0 ) 1 1\nvert 2 ( 0 0 ) 2 1\nnumtris 1\ntri 0 0 1 2\nnumweights 3\n\
    weight 0 0 1 ( 1 0 0 )\nweight 1 1 1 ( 0 1 0 )\nweight 2 1 0.5 ( 0 0 1 )\n}\n";

fn md5_anim(frames: usize) -> String {
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

const SPM_KART_XML: &str = "<kart name=\"M\" model-file=\"m.spm\">\n  <animations left=\"0\" straight=\"2\" \
    end-straight=\"3\" start-jump=\"4\"/>\n</kart>\n";

const Q3_CFG: &str = "sex m\nfootsteps normal\n0 3 0 20\n2 1 0 20\n3 3 0 20\n5 1 0 20\n6 2 0 20\n7 1 0 20\n\
    8 2 0 15\n10 2 0 15\n12 2 0 15\n14 2 0 15\n16 2 0 15\n18 2 0 15\n20 2 0 15\n22 2 2 25\n24 -2 2 25\n";

fn cases() -> Vec<Case> {
    let (pos, faces, skin) = strip(3);
    let joints = [("hips", -1, [0.0; 3]), ("head", 0, [0.0, 1.0, 0.0])];
    let iqm_anim = iqm::write_test_iqm(&pos, &faces, &skin, &joints, "walk", &keys(6), true);
    let iqm_mesh = iqm::write_test_iqm(&pos, &faces, &skin, &joints, "", &[], true);
    let iqm_only = iqm::write_test_iqm(&[], &[], &[], &joints, "walk", &keys(6), false);
    let md2_frames: Vec<(String, Vec<[u8; 3]>)> = (0..6)
        .map(|f| {
            (
                format!("run{f}"),
                (0..4u8).map(|v| [v * 10, (v % 2) * 20 + f, v]).collect(),
            )
        })
        .collect();
    let md2_frames: Vec<(&str, Vec<[u8; 3]>)> = md2_frames.iter().map(|(n, v)| (n.as_str(), v.clone())).collect();
    let md2 = md2::write_md2(&md2_frames, &[[0, 1, 2], [1, 3, 2]]);
    let md3_frames: Vec<Vec<[i16; 3]>> = (0..30).map(|f| vec![[0, 0, 0], [64, 0, 0], [0, 64, 64 * f]]).collect();
    let md3 = md3::write_test_md3(&md3_frames, &[[0, 1, 2]]);
    // A Quake III player: legs with `tag_torso`, a torso with `tag_head`, a head and the cfg.
    let still = ([0.0f32; 3], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
    let tagged = |name: &'static str| vec![(name, vec![still; 30])];
    let md3_lower = md3::write_test_md3_tags(&md3_frames, &[[0, 1, 2]], &tagged("tag_torso"));
    let md3_upper = md3::write_test_md3_tags(&md3_frames, &[[0, 1, 2]], &tagged("tag_head"));
    let md3_head = md3::write_test_md3(&md3_frames[..1], &[[0, 1, 2]]);
    let faces16: Vec<[u16; 3]> = faces.iter().map(|f| f.map(|i| i as u16)).collect();
    let pmd = pmd::write_test_pmd(&pos, &faces16, &skin, &[[0.0; 3], [0.0, 1.0, 0.0]]);
    let psa = pmd::write_test_psa(&keys(6));
    let moving: Vec<u32> = (0..pos.len() as u32).filter(|v| v % 2 == 1).collect();
    let b3d_keys: Vec<(i32, [f32; 3])> = (1..=6).map(|f| (f, [0.0, 0.1 * f as f32, 0.0])).collect();
    let spm_skin: Vec<u8> = skin.iter().map(|&j| if j == 0 { 255 } else { 0 }).collect();
    let spm_keys: Vec<(u16, Vec<[f32; 3]>)> = keys(6)
        .into_iter()
        .enumerate()
        .map(|(f, k)| (f as u16, vec![k[1], k[0]]))
        .collect();
    let spm_file = spm::write_test_spm(&pos, &faces, &spm_skin, &[("tip", 1), ("root", -1)], 1, &spm_keys);
    let still = vec![0.0; 27];
    let mut turn = still.clone();
    turn[3] = 45.0;
    let bvh_text = bvh::write_test_bvh(&[still.clone(), still, turn], 1.0 / 30.0);
    let anime_clip = Clip::new(
        "a",
        keys(4)
            .into_iter()
            .flat_map(|k| [k[0], k[1], [1.0, 0.0, 0.0]])
            .collect(),
        4,
        3,
        vec![[0, 1, 2]],
        "",
        "m",
    )
    .unwrap();
    let case = |name, read, mutated, fixed, seeds, text| Case {
        name,
        read,
        mutated,
        fixed,
        seeds,
        text,
    };
    vec![
        case("iqm", "m.iqm", "m.iqm", vec![], vec![iqm_anim], false),
        case(
            "iqm-animation",
            "m.iqm",
            "walk.iqm",
            vec![("m.iqm", iqm_mesh)],
            vec![iqm_only],
            false,
        ),
        case("md2", "m.md2", "m.md2", vec![], vec![md2.clone()], false),
        case(
            "md2-anm",
            "m.md2",
            "m.anm",
            vec![("m.md2", md2)],
            vec![b"run0 0 5 10\nstand 0 0 1\n".to_vec()],
            true,
        ),
        case("md3", "lower.md3", "lower.md3", vec![], vec![md3.clone()], false),
        case(
            "md3-cfg",
            "lower.md3",
            "animation.cfg",
            vec![("lower.md3", md3)],
            vec![Q3_CFG.into()],
            true,
        ),
        case(
            "md3-player-lower",
            "lower.md3",
            "lower.md3",
            vec![
                ("upper.md3", md3_upper.clone()),
                ("head.md3", md3_head.clone()),
                ("animation.cfg", Q3_CFG.into()),
            ],
            vec![md3_lower.clone()],
            false,
        ),
        case(
            "md3-player-upper",
            "lower.md3",
            "upper.md3",
            vec![
                ("lower.md3", md3_lower.clone()),
                ("head.md3", md3_head),
                ("animation.cfg", Q3_CFG.into()),
            ],
            vec![md3_upper.clone()],
            false,
        ),
        case(
            "md3-player-cfg",
            "lower.md3",
            "animation.cfg",
            vec![("lower.md3", md3_lower), ("upper.md3", md3_upper)],
            vec![Q3_CFG.into()],
            true,
        ),
        case(
            "md5",
            "m.md5mesh",
            "m.md5mesh",
            vec![("walk.md5anim", md5_anim(5).into())],
            vec![MD5_MESH.into()],
            true,
        ),
        case(
            "md5anim",
            "m.md5mesh",
            "walk.md5anim",
            vec![("m.md5mesh", MD5_MESH.into())],
            vec![md5_anim(5).into()],
            true,
        ),
        case(
            "pmd",
            "m.pmd",
            "m.pmd",
            vec![("walk.psa", psa.clone())],
            vec![pmd.clone()],
            false,
        ),
        case("psa", "m.pmd", "walk.psa", vec![("m.pmd", pmd)], vec![psa], false),
        case(
            "b3d",
            "m.b3d",
            "m.b3d",
            vec![],
            vec![b3d::write_test_b3d(&pos, &faces, [0.0; 3], &moving, &b3d_keys)],
            false,
        ),
        case("spm", "m.spm", "m.spm", vec![], vec![spm_file.clone()], false),
        case(
            "spm-kart-xml",
            "m.spm",
            "kart.xml",
            vec![("m.spm", spm_file)],
            vec![SPM_KART_XML.into()],
            true,
        ),
        case(
            "x",
            "m.x",
            "m.x",
            vec![],
            vec![x::write_test_x(&pos, &faces, &skin, &keys(4)).into()],
            true,
        ),
        case(
            "fbx",
            "m.fbx",
            "m.fbx",
            vec![],
            vec![fbx::write_test_fbx(&pos, &faces, &skin, &keys(4))],
            false,
        ),
        case(
            "dae",
            "m.dae",
            "m.dae",
            vec![],
            vec![dae::write_test_dae(&pos, &faces, &skin, &keys(4)).into()],
            true,
        ),
        case(
            "bvh",
            "m.iqm",
            "walk.bvh",
            vec![("m.iqm", iqm::write_test_rig(bvh::TEST_RIG))],
            vec![bvh_text.into()],
            true,
        ),
        case(
            "anime",
            "m.anime",
            "m.anime",
            vec![],
            vec![anime::write_anime(&anime_clip)],
            false,
        ),
    ]
}

/// One mutated input: 1–4 mutations of a random seed; text mostly by numbers, and now and then a slice of the
/// input repeated up to 3,000 times (nesting past every depth limit, counts past every size limit).
fn mutate(rng: &mut ChaCha8Rng, seeds: &[Vec<u8>], text: bool) -> Vec<u8> {
    let mut b = seeds[rng.random_range(0..seeds.len())].clone();
    for _ in 0..rng.random_range(1..=4) {
        match rng.random_range(0..20) {
            0 if !b.is_empty() => {
                let at = rng.random_range(0..b.len());
                let end = (at + rng.random_range(1..=24)).min(b.len());
                let slice = b[at..end].to_vec();
                let times = [2, 16, 300, 3000][rng.random_range(0..4)];
                b.splice(at..at, slice.repeat(times));
            }
            1..=10 if text => replace_number(rng, &mut b),
            _ => mutate_once(rng, &mut b, seeds),
        }
    }
    b
}

/// Read `case.read` in `dir` with `input` as `case.mutated`: `Ok(None)` when it read, `Ok(Some(error kind))`, or
/// `Err(panic message)`.
fn run(case: &Case, dir: &Path, input: &[u8]) -> Result<Option<String>, String> {
    std::fs::write(dir.join(case.mutated), input).unwrap();
    let outcome = catch_unwind(AssertUnwindSafe(|| {
        match formats::read_take(&dir.join(case.read), &ReadOptions::default()) {
            Ok(_) => Ok(None),
            Err(e) if e.field == PANIC_FIELD => Err(e.to_string()),
            Err(e) => Ok(Some(kind(&e))),
        }
    }));
    outcome.unwrap_or_else(|p| {
        Err(p
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_default())
    })
}

/// Fuzz `case` until `runs` inputs or `time` have passed; panics on the first failure, saving its input.
fn fuzz(case: &Case, seed: u64, runs: usize, time: Duration) -> Tally {
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in &case.fixed {
        std::fs::write(dir.path().join(name), bytes).unwrap();
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let start = Instant::now();
    let mut tally = Tally::new();
    while tally.runs < runs && start.elapsed() < time {
        let input = match case.seeds.get(tally.runs) {
            Some(s) => s.clone(),
            None => mutate(&mut rng, &case.seeds, case.text),
        };
        let t0 = Instant::now();
        let outcome = run(case, dir.path(), &input);
        let label = format!("{}-{seed}-{}", case.name, tally.runs);
        tally.record(&label, &input, outcome, t0.elapsed());
    }
    tally.elapsed = start.elapsed();
    tally
}

#[test]
fn every_skeletal_reader_and_sidecar_survives_mutation() {
    for (k, case) in cases().iter().enumerate() {
        // Every seed reads: the mutants start from files the reader accepts, so they reach its depths.
        let t = fuzz(case, 0xf00d + k as u64, case.seeds.len(), Duration::MAX);
        assert_eq!(
            t.ok,
            case.seeds.len(),
            "{}: a seed does not read: {}",
            case.name,
            t.top_errors(3)
        );
        let t = fuzz(case, 0xf00d + k as u64, QUICK_RUNS, Duration::MAX);
        println!(
            "{}: {} inputs, {} ok, {:.1?}; errors: {}",
            case.name,
            t.runs,
            t.ok,
            t.elapsed,
            t.top_errors(4)
        );
    }
}

/// The long run (see the module doc for the command).
#[test]
#[ignore]
fn fuzz_readers_for_a_long_time() {
    let secs: u64 = std::env::var("ANY4D_FUZZ_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(120);
    for (k, case) in cases().iter().enumerate() {
        let t = fuzz(case, 1 + k as u64, usize::MAX, Duration::from_secs(secs));
        println!(
            "{}: {} inputs in {:.0?}, {} read ok, slowest {:?}; {} error kinds, most frequent: {}",
            case.name,
            t.runs,
            t.elapsed,
            t.ok,
            t.slowest,
            t.errors.len(),
            t.top_errors(6)
        );
    }
}

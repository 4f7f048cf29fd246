//! Mutation fuzzing of every reader on the stable toolchain: seeds are the committed fixtures (real numpy
//! pickles, glTF, OBJ, the hostile reproducers) plus a GLB and a store written here; each run mutates them (bit
//! flips, interesting integers, cut / copied ranges, crossover, and for text: numbers and glTF words swapped) and
//! asserts that every reader returns `Ok` or a clean error, never a panic (glTF: never its caught-panic error).
//!
//! `cargo test -p any4d-data --test fuzz_stable` runs [`QUICK_RUNS`] inputs per reader. The long run is ignored:
//!
//! ```sh
//! ANY4D_FUZZ_SECS=600 ANY4D_FUZZ_TARGETS=pickle,gltf,glb,obj,store \
//!     nice -n 15 cargo test -p any4d-data --test fuzz_stable -- --ignored --nocapture
//! ```
//!
//! It prints the inputs run, how many read `Ok`, and the slowest input per reader. A failing input is written to
//! the temporary folder and named in the panic message. The cargo-fuzz targets of `fuzz/` cover the same readers
//! with coverage feedback on a nightly toolchain.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use any4d_data::Clip;
use any4d_data::formats::dymesh_bin::read_bin_bytes;
use any4d_data::formats::gltf::{ExternalBuffers, GltfReadOptions, read_gltf_bytes, write_gltf};
use any4d_data::formats::obj::parse_obj;
use any4d_data::formats::{PANIC_FIELD, write_clip};
use any4d_data::preprocess::VertexFilter;
use any4d_data::store::{self, ImportOptions};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

mod fuzz_common;
use fuzz_common::{Tally, kind, mutate_once, replace_number};

/// Inputs per reader in the default test run (a few seconds each).
const QUICK_RUNS: usize = 3000;

/// A reader under test.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Target {
    /// `.bin` pickles through the DyMesh reader (the unpickler and the clip checks).
    Pickle,
    /// glTF JSON with embedded buffers.
    Gltf,
    /// Binary glTF.
    Glb,
    /// One OBJ frame.
    Obj,
    /// A store's `clips.bin`: the catalog (header, table, trailer), then every clip, as `Store` reads them.
    Store,
}

impl Target {
    const ALL: [Target; 5] = [Target::Pickle, Target::Gltf, Target::Glb, Target::Obj, Target::Store];

    fn name(self) -> &'static str {
        match self {
            Target::Pickle => "pickle",
            Target::Gltf => "gltf",
            Target::Glb => "glb",
            Target::Obj => "obj",
            Target::Store => "store",
        }
    }

    fn is_text(self) -> bool {
        matches!(self, Target::Gltf | Target::Obj)
    }
}

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

/// Files under `dir` (recursively) whose name ends with one of `exts`.
fn files(dir: &Path, exts: &[&str]) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            out.extend(files(&p, exts));
        } else if exts.iter().any(|e| p.to_string_lossy().ends_with(e)) {
            out.push(std::fs::read(&p).unwrap());
        }
    }
    out
}

/// A small moving clip.
fn clip(frames: usize, n: usize) -> Clip {
    let v = (0..frames * n)
        .map(|i| {
            let (f, k) = ((i / n) as f32, (i % n) as f32);
            [k.sin() + 0.1 * f, k.cos(), 0.05 * k * f]
        })
        .collect();
    let faces = (0..n as u32 - 2).map(|i| [i, i + 1, i + 2]).collect();
    Clip::new("seed", v, frames, n, faces, "a seed", "mem").unwrap()
}

/// A glTF JSON fixture as GLB: its data-URI buffer becomes the BIN chunk.
fn as_glb(json: &[u8]) -> Vec<u8> {
    let mut doc: serde_json::Value = serde_json::from_slice(json).unwrap();
    let uri = doc["buffers"][0]["uri"].as_str().unwrap().to_string();
    let bin = base64_decode(uri.split_once(',').unwrap().1);
    doc["buffers"][0].as_object_mut().unwrap().remove("uri");
    glb_of(&serde_json::to_vec(&doc).unwrap(), &bin)
}

fn base64_decode(s: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        _ => 63,
    };
    let digits: Vec<u8> = s.bytes().filter(|&c| c != b'=').map(value).collect();
    digits
        .chunks(4)
        .flat_map(|c| {
            let w = c
                .iter()
                .enumerate()
                .fold(0u32, |w, (i, &d)| w | (d as u32) << (18 - 6 * i));
            (0..c.len() * 6 / 8).map(move |k| (w >> (16 - 8 * k)) as u8)
        })
        .collect()
}

/// The seed inputs of `target`; `scratch` holds files written for them.
fn seeds(target: Target, scratch: &Path) -> Vec<Vec<u8>> {
    let f = fixtures();
    let mut out = match target {
        Target::Pickle => [files(&f.join("bin"), &[".bin"]), files(&f.join("hostile"), &[".bin"])].concat(),
        Target::Gltf => [
            files(&f.join("gltf"), &[".gltf"]),
            files(&f.join("hostile"), &[".gltf"]),
        ]
        .concat(),
        Target::Glb => {
            let mut v: Vec<Vec<u8>> = files(&f.join("gltf"), &[".gltf"]).iter().map(|j| as_glb(j)).collect();
            v.extend(files(&f.join("hostile"), &[".glb"]));
            v
        }
        Target::Obj => files(&f.join("obj"), &[".obj"]),
        Target::Store => {
            let src = scratch.join("src");
            std::fs::create_dir_all(&src).unwrap();
            write_clip(&src.join("a.bin"), &clip(16, 12)).unwrap();
            write_clip(&src.join("b.bin"), &clip(17, 9)).unwrap();
            let opts = ImportOptions {
                filter: VertexFilter { min: 3, max: 64 },
                p: 4,
                ..ImportOptions::default()
            };
            let out = scratch.join("seed_store");
            store::import(&[src], &out, &opts).unwrap();
            vec![std::fs::read(out.join("clips.bin")).unwrap()]
        }
    };
    if target == Target::Glb {
        let path = scratch.join("seed.glb");
        write_gltf(&path, &clip(5, 6), 30.0).unwrap();
        out.push(std::fs::read(&path).unwrap());
    }
    assert!(!out.is_empty(), "no seeds for {target:?}");
    out
}

const GLTF_WORDS: [&str; 18] = [
    "\"SCALAR\"",
    "\"VEC2\"",
    "\"VEC3\"",
    "\"VEC4\"",
    "\"MAT4\"",
    "\"weights\"",
    "\"rotation\"",
    "\"scale\"",
    "\"translation\"",
    "\"STEP\"",
    "\"CUBICSPLINE\"",
    "\"LINEAR\"",
    "5120",
    "5121",
    "5122",
    "5123",
    "5125",
    "5126",
];

const GLTF_KEYS: [&str; 24] = [
    "\"count\"",
    "\"byteOffset\"",
    "\"byteLength\"",
    "\"byteStride\"",
    "\"componentType\"",
    "\"bufferView\"",
    "\"type\"",
    "\"node\"",
    "\"path\"",
    "\"sampler\"",
    "\"input\"",
    "\"output\"",
    "\"indices\"",
    "\"POSITION\"",
    "\"JOINTS_0\"",
    "\"WEIGHTS_0\"",
    "\"mesh\"",
    "\"skin\"",
    "\"children\"",
    "\"matrix\"",
    "\"weights\"",
    "\"normalized\"",
    "\"interpolation\"",
    "\"inverseBindMatrices\"",
];

/// One mutated input: 1–4 mutations of a random seed. Text is mutated mostly token-wise (numbers, glTF words)
/// so that most inputs stay JSON and reach the checks behind the parser; a GLB mostly inside its JSON or BIN
/// chunk, re-packed with correct lengths.
fn mutate(rng: &mut ChaCha8Rng, seeds: &[Vec<u8>], target: Target) -> Vec<u8> {
    let mut b = seeds[rng.random_range(0..seeds.len())].clone();
    let chunks = if target == Target::Glb { glb_chunks(&b) } else { None };
    if let (Some((mut json, mut bin)), true) = (chunks, rng.random_bool(0.7)) {
        for _ in 0..rng.random_range(1..=4) {
            if rng.random_bool(0.6) {
                mutate_text(rng, &mut json, seeds);
            } else {
                mutate_once(rng, &mut bin, seeds);
            }
        }
        return glb_of(&json, &bin);
    }
    for _ in 0..rng.random_range(1..=4) {
        if target.is_text() {
            mutate_text(rng, &mut b, seeds);
        } else {
            mutate_once(rng, &mut b, seeds);
        }
    }
    // A protocol-4/5 pickle opens with a FRAME over the rest: mostly keep it consistent, so that mutations reach
    // the opcodes instead of the frame check.
    if target == Target::Pickle && b.len() >= 11 && b[2] == 0x95 && rng.random_bool(0.8) {
        let rest = (b.len() - 11) as u64;
        b[3..11].copy_from_slice(&rest.to_le_bytes());
    }
    b
}

/// A token-level mutation most of the time, a byte-level one otherwise.
fn mutate_text(rng: &mut ChaCha8Rng, b: &mut Vec<u8>, seeds: &[Vec<u8>]) {
    match rng.random_range(0..10) {
        0..=4 => replace_number(rng, b),
        5..=7 => replace_word(rng, b),
        _ => mutate_once(rng, b, seeds),
    }
}

/// The JSON and BIN chunks of a well-formed GLB.
fn glb_chunks(b: &[u8]) -> Option<(Vec<u8>, Vec<u8>)> {
    let u32_at = |at: usize| Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?) as usize);
    let json_len = u32_at(12)?;
    let json = b.get(20..20 + json_len)?.to_vec();
    let bin = match u32_at(20 + json_len) {
        Some(len) => b.get(28 + json_len..28 + json_len + len)?.to_vec(),
        None => Vec::new(),
    };
    Some((json, bin))
}

/// A GLB of these chunks with correct lengths (JSON padded with spaces, BIN with zeros).
fn glb_of(json: &[u8], bin: &[u8]) -> Vec<u8> {
    let pad = |mut v: Vec<u8>, with: u8| {
        while !v.len().is_multiple_of(4) {
            v.push(with);
        }
        v
    };
    let (json, bin) = (pad(json.to_vec(), b' '), pad(bin.to_vec(), 0));
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = b"glTF".to_vec();
    for w in [2, total, json.len()] {
        out.extend((w as u32).to_le_bytes());
    }
    out.extend(b"JSON");
    out.extend(json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out
}

/// Replace one JSON string: a key by another glTF key, a value by a glTF word or component type.
fn replace_word(rng: &mut ChaCha8Rng, b: &mut Vec<u8>) {
    let quotes: Vec<usize> = (0..b.len()).filter(|&i| b[i] == b'"').collect();
    if quotes.len() < 2 {
        return;
    }
    // JSON strings pair up their quotes: an even index opens one.
    let k = 2 * rng.random_range(0..quotes.len() / 2);
    let (s, e) = (quotes[k], quotes[k + 1] + 1);
    if e - s > 40 {
        return;
    }
    let is_key = b[e..].iter().find(|c| !c.is_ascii_whitespace()) == Some(&b':');
    let new = if is_key {
        GLTF_KEYS[rng.random_range(0..GLTF_KEYS.len())]
    } else {
        GLTF_WORDS[rng.random_range(0..GLTF_WORDS.len())]
    };
    b.splice(s..e, new.bytes());
}

/// Run `target` on `input`: `Ok(None)` when it read, `Ok(Some(error kind))`, or `Err(panic message)`.
fn run(target: Target, input: &[u8], scratch: &Path) -> Result<Option<String>, String> {
    let outcome = catch_unwind(AssertUnwindSafe(|| match target {
        Target::Pickle => Ok(read_bin_bytes(input, "fuzz.bin").err().map(|e| kind(&e))),
        Target::Gltf | Target::Glb => {
            let path = scratch.join(if target == Target::Gltf {
                "fuzz.gltf"
            } else {
                "fuzz.glb"
            });
            match read_gltf_bytes(input, &path, &GltfReadOptions::default(), &ExternalBuffers::Refuse) {
                Ok(_) => Ok(None),
                Err(e) if e.field == PANIC_FIELD => Err(e.to_string()),
                Err(e) => Ok(Some(kind(&e))),
            }
        }
        Target::Obj => Ok(parse_obj(&String::from_utf8_lossy(input), Path::new("fuzz.obj"))
            .err()
            .map(|e| kind(&e))),
        Target::Store => {
            let path = Path::new("fuzz/clips.bin");
            Ok(match store::read_catalog_bytes(input, path) {
                Err(e) => Some(kind(&e)),
                Ok(catalog) => (0..catalog.entries.len()).find_map(|i| {
                    store::decode_clip_bytes(input, &catalog, i, path)
                        .err()
                        .map(|e| kind(&e))
                }),
            })
        }
    }));
    match outcome {
        Ok(r) => r,
        Err(p) => Err(p
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_default()),
    }
}

/// Fuzz `target` until `runs` inputs or `time` have passed (whichever first); panics on the first failure.
fn fuzz(target: Target, seed: u64, runs: usize, time: Duration) -> Tally {
    let scratch = tempfile::tempdir().unwrap();
    let corpus = seeds(target, scratch.path());
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let start = Instant::now();
    let mut tally = Tally::new();
    // The seeds themselves first, then mutations.
    let mut next = 0;
    while tally.runs < runs && start.elapsed() < time {
        let input = if next < corpus.len() {
            next += 1;
            corpus[next - 1].clone()
        } else {
            mutate(&mut rng, &corpus, target)
        };
        let t0 = Instant::now();
        let outcome = run(target, &input, scratch.path());
        let label = format!("{}-{seed}-{}.bin", target.name(), tally.runs);
        tally.record(&label, &input, outcome, t0.elapsed());
    }
    tally.elapsed = start.elapsed();
    tally
}

#[test]
fn every_reader_survives_mutated_seeds() {
    for (k, target) in Target::ALL.into_iter().enumerate() {
        let t = fuzz(target, 0x5eed + k as u64, QUICK_RUNS, Duration::MAX);
        assert_eq!(t.runs, QUICK_RUNS);
        // Some mutants must still read (the harness reaches the readers' depths, not only their first checks).
        assert!(t.ok > 0, "{target:?}: no input read ok");
        println!(
            "{}: {} inputs, {} ok, {:.1?}; errors: {}",
            target.name(),
            t.runs,
            t.ok,
            t.elapsed,
            t.top_errors(6)
        );
    }
}

/// The long run (see the module doc for the command).
#[test]
#[ignore]
fn fuzz_for_a_long_time() {
    let secs: u64 = std::env::var("ANY4D_FUZZ_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(600);
    let seed: u64 = std::env::var("ANY4D_FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let wanted = std::env::var("ANY4D_FUZZ_TARGETS").unwrap_or_default();
    for target in Target::ALL {
        if !wanted.is_empty() && !wanted.split(',').any(|w| w == target.name()) {
            continue;
        }
        let t = fuzz(target, seed, usize::MAX, Duration::from_secs(secs));
        println!(
            "{}: {} inputs in {:.0?}, {} read ok, slowest {:?}; {} error kinds, most frequent: {}",
            target.name(),
            t.runs,
            t.elapsed,
            t.ok,
            t.slowest,
            t.errors.len(),
            t.top_errors(8)
        );
    }
}

//! `any4d bench …`: each benchmark's measurement lives in the crate it measures (`any4d_data::bench`,
//! `any4d_model::bench`, `any4d_train::bench`, `any4d_eval::bench`); its arguments and report live with its
//! subcommand group here, and its Python reference runs through `crate::reference`.

use std::path::PathBuf;
use std::process::ExitCode;

use any4d_data::bench::acap::{bench_clip, time_acap};
use anyhow::{Context, bail};
use clap::{Args, Subcommand};

use crate::reference::{PythonReference, Skipped};

#[derive(Subcommand, Debug)]
pub enum BenchCmd {
    /// Import + normalise + FPS throughput against the Python reference.
    Data(super::data::BenchArgs),
    /// VAE encode+decode and RF forward+backward time per clip.
    Model(super::model::BenchArgs),
    /// Training steps/s for a preset: RF presets on random latents with model FLOP/s, VAE and BD-LSTM presets on a store.
    Train(super::train::BenchArgs),
    /// Metric throughput against the numpy/scipy reference.
    Metrics(super::eval::BenchArgs),
    /// Wall time of `any4d complete` for one 16-frame clip per vertex count (median over repetitions).
    Complete(super::complete::BenchArgs),
    /// P-Table 4 timing (encode → midpoint sampling → decode, 16 and 31 frames) of ours at a config's size with
    /// freshly initialised weights, on any backend: no trained run needed.
    Sample(super::timing::SampleBenchArgs),
    /// ACAP features + reconstruction of one clip (the faithful BD-LSTM's per-clip work) against the numpy/scipy
    /// reference.
    Acap(AcapBenchArgs),
    /// Procedural clips per second on one thread: the rigged characters against the shape families, same seed,
    /// same frames and vertex range, alternating.
    Synth(SynthBenchArgs),
    /// Scene features per clip (the occupancy grid (S1) and the keyframes' basis-point offsets (S2)) against the
    /// numpy reference, on procedural scene clips.
    Scene(SceneBenchArgs),
    /// The streaming reader: every clip of each store read and decoded in a training epoch's order (shard by shard
    /// through the shuffle buffer), alternating between the stores; the first is the reference of the ratios. An
    /// object-storage URL is fetched into an empty cache first (cold), then read from the filled cache.
    Store(StoreBenchArgs),
}

#[derive(Args, Debug)]
pub struct StoreBenchArgs {
    /// Stores: folders or object-storage URLs (`s3://…`, `http://…`); the first is the reference.
    #[arg(required = true)]
    pub stores: Vec<PathBuf>,
    /// Clips read from each store per round (default: all of it).
    #[arg(long)]
    pub clips: Option<usize>,
    /// Shuffle buffer of the data order (the presets' `train.shuffle_buffer`).
    #[arg(long, default_value_t = 8192)]
    pub buffer: usize,
    /// Seed of the data order.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Timed rounds, alternating between the stores; medians are reported.
    #[arg(long, default_value_t = 3)]
    pub rounds: usize,
    /// Also write the rows as CSV to this file.
    #[arg(long)]
    pub csv: Option<PathBuf>,
}

/// One row of `bench store`: a store as it was opened, and its timed reads.
struct StoreRow {
    name: String,
    store: any4d_data::store::Store,
    /// Seconds to fetch an object-storage store into an empty cache (`None` for a folder).
    fetch_s: Option<f64>,
    reads: Vec<any4d_train::bench::StoreRead>,
}

/// `any4d bench store`: see [`BenchCmd::Store`].
fn bench_store(args: StoreBenchArgs) -> anyhow::Result<ExitCode> {
    use any4d_data::store::{Store, is_url, remote};
    use any4d_model::bench::median;
    use any4d_train::bench::time_store_read;
    if args.rounds == 0 || args.clips == Some(0) {
        bail!("--rounds and --clips must be at least 1");
    }
    let cache = tempfile::tempdir().context("a temporary cache folder")?;
    let mut rows = Vec::new();
    for path in &args.stores {
        let name = path.display().to_string();
        match path.to_str().filter(|_| is_url(path)) {
            Some(url) => {
                let start = std::time::Instant::now();
                let local = remote::fetch(url, &remote::env_options(), cache.path())?;
                let fetch_s = start.elapsed().as_secs_f64();
                let store = Store::open(&local)?;
                // The first read after the fetch, then the same store as later runs see it (cache filled).
                let cold = time_store_read(&store, args.seed, args.buffer, args.clips)?;
                rows.push(StoreRow {
                    name: format!("{name} (fetch into an empty cache + first read)"),
                    store: store.clone(),
                    fetch_s: Some(fetch_s),
                    reads: vec![cold],
                });
                rows.push(StoreRow {
                    name: format!("{name} (cache filled)"),
                    store,
                    fetch_s: None,
                    reads: Vec::new(),
                });
            }
            None => rows.push(StoreRow {
                name,
                store: Store::open(path)?,
                fetch_s: None,
                reads: Vec::new(),
            }),
        }
    }
    for _ in 0..args.rounds {
        for row in rows.iter_mut().filter(|r| r.fetch_s.is_none()) {
            row.reads
                .push(time_store_read(&row.store, args.seed, args.buffer, args.clips)?);
        }
    }
    let rate = |r: &StoreRow| {
        let secs: Vec<f64> = r.reads.iter().map(|x| x.seconds).collect();
        let s = median(&secs) + r.fetch_s.unwrap_or(0.0);
        (r.reads[0].clips as f64 / s, r.reads[0].bytes as f64 / s / 1e6, s)
    };
    let reference = rate(&rows[0]).0;
    println!(
        "store bench: each store read and decoded in a training epoch's order (buffer {}, seed {}) on one thread; \
         medians of {} alternating rounds (a fetched store: one)",
        args.buffer, args.seed, args.rounds
    );
    let mut csv = String::from("store,shards,clips,bytes,seconds,clips_per_s,mb_per_s,ratio\n");
    println!("| store | shards | clips | s | clips/s | MB/s | × first |");
    println!("|---|---|---|---|---|---|---|");
    for row in &rows {
        let (clips_s, mb_s, s) = rate(row);
        let (clips, bytes) = (row.reads[0].clips, row.reads[0].bytes);
        let shards = row.store.shard_count();
        let ratio = clips_s / reference;
        println!(
            "| {} | {shards} | {clips} | {s:.3} | {clips_s:.0} | {mb_s:.0} | {ratio:.2} |",
            row.name
        );
        csv.push_str(&format!(
            "\"{}\",{shards},{clips},{bytes},{s:.4},{clips_s:.1},{mb_s:.1},{ratio:.4}\n",
            row.name.replace('"', "'")
        ));
    }
    if let Some(path) = &args.csv {
        any4d_data::io::write_atomic(path, csv.as_bytes())?;
    }
    Ok(ExitCode::SUCCESS)
}

#[derive(Args, Debug)]
pub struct SceneBenchArgs {
    /// Procedural scene clips (rigged characters in furnished rooms).
    #[arg(long, default_value_t = 4)]
    pub clips: usize,
    /// Keyframes per clip whose anchors get offsets (S2).
    #[arg(long, default_value_t = 5)]
    pub keyframes: usize,
    /// Anchor vertices per keyframe (the VAE's P).
    #[arg(long, default_value_t = 512)]
    pub anchors: usize,
    /// Timed passes over the clips; the fastest is reported, as the reference does.
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// The numpy reference script.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/scene_features_reference.py"))]
    pub script: PathBuf,
    /// Python interpreter for the reference.
    #[arg(long, default_value = "python3")]
    pub python: PathBuf,
}

/// What the scene reference prints.
#[derive(serde::Deserialize)]
struct SceneReference {
    clips: usize,
    seconds_per_clip: f64,
}

/// `any4d bench scene`: (S1) + (S2) of every clip on one thread and on the pool, then the reference on one core.
fn bench_scene(args: SceneBenchArgs) -> anyhow::Result<ExitCode> {
    use any4d_data::scene::features::{GridSpec, bps_offsets, frame_center, occupancy_grid};
    use any4d_data::synth::{Family, SynthConfig, generate_scened};
    if args.repeat == 0 || args.clips == 0 || args.keyframes == 0 || args.anchors == 0 {
        bail!("--clips, --keyframes, --anchors and --repeat must be at least 1");
    }
    let cfg = SynthConfig {
        clips: args.clips,
        family: Family::Rigged(Default::default()),
        scenes: true,
        ..SynthConfig::default()
    };
    cfg.validate()?;
    let spec = GridSpec::default();
    // Per clip: its scene, frame 0's centre and the anchors of `keyframes` frames spread over the clip.
    let mut inputs = Vec::with_capacity(args.clips);
    for i in 0..args.clips {
        let (clip, scene) = generate_scened(&cfg, i)?;
        let scene = scene.context("a procedural scene clip without its scene")?;
        let center = frame_center(clip.frame(0));
        let points: Vec<[f32; 3]> = (0..args.keyframes)
            .flat_map(|k| {
                let f = k * (clip.frames - 1) / (args.keyframes.max(2) - 1).max(1);
                let frame = clip.frame(f.min(clip.frames - 1));
                (0..args.anchors).map(move |p| frame[p * frame.len() / args.anchors])
            })
            .collect();
        inputs.push((scene, center, points));
    }
    let run = || -> anyhow::Result<f64> {
        let mut best = f64::INFINITY;
        for _ in 0..args.repeat {
            let t0 = std::time::Instant::now();
            for (scene, center, points) in &inputs {
                occupancy_grid(scene, *center, &spec)?;
                bps_offsets(scene, points)?;
            }
            best = best.min(t0.elapsed().as_secs_f64() / inputs.len() as f64);
        }
        Ok(best)
    };
    let threads = rayon::current_num_threads();
    let t1 = rayon::ThreadPoolBuilder::new().num_threads(1).build()?.install(run)?;
    let tn = run()?;
    let triangles = inputs.iter().map(|(s, _, _)| s.faces.len()).sum::<usize>() as f64 / inputs.len() as f64;
    println!(
        "scene bench: {} procedural scene clips ({triangles:.0} scene triangles on average), a {}×{}×{} grid and \
         {} keyframes × {} anchors per clip, fastest of {}",
        args.clips, spec.cells[0], spec.cells[1], spec.cells[2], args.keyframes, args.anchors, args.repeat
    );
    println!("| implementation | ms per clip |\n|---|---|");
    println!("| ours, 1 thread | {:.2} |", 1e3 * t1);
    println!("| ours, {threads} threads | {:.2} |", 1e3 * tn);
    let file = tempfile::NamedTempFile::new().context("creating the clips file of the reference")?;
    let clips: Vec<serde_json::Value> = inputs
        .iter()
        .map(|(scene, center, points)| {
            serde_json::json!({
                "vertices": scene.vertices, "faces": scene.faces, "cells": spec.cells, "cell": spec.cell,
                "center": center, "points": points,
            })
        })
        .collect();
    std::fs::write(file.path(), serde_json::json!({ "clips": clips }).to_string())
        .context("writing the clips file of the reference")?;
    let reference = PythonReference::bench(&args.python, &args.script, file.path(), args.repeat);
    match reference.json::<SceneReference>()? {
        Ok(r) if r.clips != inputs.len() => bail!("the reference read {} clips, not {}", r.clips, inputs.len()),
        Ok(r) => {
            println!("| numpy, 1 core | {:.2} |", 1e3 * r.seconds_per_clip);
            println!(
                "speed-up over the reference: {:.1}× (1 thread), {:.1}× ({threads} threads)",
                r.seconds_per_clip / t1,
                r.seconds_per_clip / tn
            );
        }
        Err(Skipped(why)) => println!("reference skipped: {why}"),
    }
    Ok(ExitCode::SUCCESS)
}

#[derive(Args, Debug)]
pub struct SynthBenchArgs {
    /// Clips per family and round.
    #[arg(long, default_value_t = 200)]
    pub clips: usize,
    /// Rounds, alternating the families; the fastest round of each is reported.
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// Frames per clip.
    #[arg(long, default_value_t = 16)]
    pub frames: usize,
}

/// `any4d bench synth`: clips/s of each generator on one thread (no store, no FPS: the generators alone).
fn bench_synth(args: SynthBenchArgs) -> anyhow::Result<ExitCode> {
    use any4d_data::synth::{Family, SynthConfig, generate_one};
    if args.repeat == 0 || args.clips == 0 {
        bail!("--clips and --repeat must be at least 1");
    }
    let mut best = [f64::INFINITY; 2];
    let mut vertices = [0usize; 2];
    for _ in 0..args.repeat {
        for (k, family) in Family::ALL.into_iter().enumerate() {
            let cfg = SynthConfig {
                clips: args.clips,
                frames: args.frames,
                family,
                ..SynthConfig::default()
            };
            cfg.validate()?;
            let start = std::time::Instant::now();
            let mut n = 0;
            for i in 0..args.clips {
                n += generate_one(&cfg, i)?.n_vertices;
            }
            best[k] = best[k].min(start.elapsed().as_secs_f64());
            vertices[k] = n;
        }
    }
    println!(
        "synth bench: {} clips of {} frames per generator, one thread, fastest of {} alternating rounds",
        args.clips, args.frames, args.repeat
    );
    println!("| generator | clips/s | mean vertices | s |");
    println!("|---|---|---|---|");
    for (k, family) in Family::ALL.into_iter().enumerate() {
        println!(
            "| {} | {:.1} | {:.0} | {:.3} |",
            family.name(),
            args.clips as f64 / best[k],
            vertices[k] as f64 / args.clips as f64,
            best[k]
        );
    }
    println!("rigged / shapes time per clip: {:.2}×", best[1] / best[0]);
    Ok(ExitCode::SUCCESS)
}

#[derive(Args, Debug)]
pub struct AcapBenchArgs {
    /// Vertices of the clip (a twisting tube; within ±128 of this).
    #[arg(long, default_value_t = 4096)]
    pub vertices: usize,
    /// Frames of the clip.
    #[arg(long, default_value_t = 16)]
    pub frames: usize,
    /// Timed runs; the fastest is reported, as the reference does.
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// The numpy/scipy reference script.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/acap_reference.py"))]
    pub script: PathBuf,
    /// Python interpreter for the reference.
    #[arg(long, default_value = "python3")]
    pub python: PathBuf,
}

/// What the reference prints.
#[derive(serde::Deserialize)]
struct AcapReference {
    vertices: usize,
    features_s: f64,
    reconstruction_s: f64,
    total_s: f64,
}

/// `any4d bench acap`: ours on one thread and on the whole pool, then the reference on one core, same clip.
fn bench_acap(args: AcapBenchArgs) -> anyhow::Result<ExitCode> {
    if args.repeat == 0 {
        bail!("--repeat must be at least 1");
    }
    let clip = bench_clip(args.vertices, args.frames)?;
    let threads = rayon::current_num_threads();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let t1 = one.install(|| time_acap(&clip, args.repeat))?;
    let tn = time_acap(&clip, args.repeat)?;
    println!(
        "acap bench: {} ({} frames × {} vertices), features + ring-moment reconstruction of every frame, best of {}",
        clip.id, clip.frames, clip.n_vertices, args.repeat
    );
    println!("| implementation | features s | reconstruction s | total s |");
    println!("|---|---|---|---|");
    let row = |name: &str, f: f64, r: f64, t: f64| println!("| {name} | {f:.4} | {r:.4} | {t:.4} |");
    row("ours, 1 thread", t1.features_s, t1.reconstruction_s, t1.total_s());
    row(
        &format!("ours, {threads} threads"),
        tn.features_s,
        tn.reconstruction_s,
        tn.total_s(),
    );
    let file = tempfile::NamedTempFile::new().context("creating the clip file of the reference")?;
    let frames: Vec<&[[f32; 3]]> = (0..clip.frames).map(|f| clip.frame(f)).collect();
    std::fs::write(
        file.path(),
        serde_json::json!({ "faces": clip.faces, "frames": frames }).to_string(),
    )
    .context("writing the clip file of the reference")?;
    let reference = PythonReference::bench(&args.python, &args.script, file.path(), args.repeat);
    match reference.json::<AcapReference>()? {
        Ok(r) => {
            if r.vertices != clip.n_vertices {
                bail!(
                    "the reference read {} vertices, the clip has {}",
                    r.vertices,
                    clip.n_vertices
                );
            }
            row("numpy+scipy, 1 core", r.features_s, r.reconstruction_s, r.total_s);
            println!(
                "speed-up over the reference: {:.2}× (1 thread), {:.2}× ({threads} threads)",
                r.total_s / t1.total_s(),
                r.total_s / tn.total_s()
            );
        }
        Err(Skipped(why)) => println!("reference skipped: {why}"),
    }
    Ok(ExitCode::SUCCESS)
}

pub fn exec(cmd: BenchCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        BenchCmd::Data(args) => super::data::bench(args),
        BenchCmd::Model(args) => super::model::bench(args),
        BenchCmd::Train(args) => super::train::bench(args),
        BenchCmd::Metrics(args) => super::eval::bench(args),
        BenchCmd::Complete(args) => super::complete::bench(args),
        BenchCmd::Sample(args) => super::timing::bench_sample(args),
        BenchCmd::Acap(args) => bench_acap(args),
        BenchCmd::Synth(args) => bench_synth(args),
        BenchCmd::Scene(args) => bench_scene(args),
        BenchCmd::Store(args) => bench_store(args),
    }
}

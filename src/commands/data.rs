//! `any4d data …` and `any4d bench data`: parse arguments, call `any4d_data` (docs/method.md §2: clip files, the
//! dataset store, inspection, contact sheets; the throughput benchmark of import + normalise (D1)–(D3) + FPS).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::{Args, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};

use any4d_data::Clip;
use any4d_data::bench::readers::{JOINTS, per_format};
use any4d_data::bench::{DataBench, DataTiming, bench_clip};
use any4d_data::formats;
use any4d_data::inspect;
use any4d_data::preprocess::{self, VertexFilter};
use any4d_data::render::{RenderOptions, render_contact_sheet};
use any4d_data::store::{self, DEFAULT_P, ImportOptions, ShardSpec, Store, Weld};
use any4d_data::synth::rigged::{Action, Template};
use any4d_data::synth::{Family, RiggedKinds, ShapeFamily, SynthConfig};

use crate::reference::{PythonReference, Skipped};

#[derive(Subcommand, Debug)]
pub enum DataCmd {
    /// Convert a clip between formats (chosen by extension); geometry is unchanged unless a flag asks.
    Convert(ConvertArgs),
    /// Import clip files and folders into a dataset store (normalise, FPS, split; rejected files are listed).
    Import(ImportArgs),
    /// Write procedural clips into a dataset store.
    Synth(SynthArgs),
    /// Make a sharded store of shard folders (each written by `data import --shard K/N` or `data synth --shard
    /// K/N`): writes STORE/manifest.json listing them, copying no clip. Run again after re-importing a shard.
    Merge(MergeArgs),
    /// Summarise a dataset store (checking clips.bin against its index) or one clip file.
    Inspect(InspectArgs),
    /// Check every clip of a dataset store: checksum, decoding, index row. Exit code 1 when any clip fails.
    Verify(VerifyArgs),
    /// Render a clip (file, or one clip of a store) as a contact sheet PNG.
    Render(RenderArgs),
    /// Stage the animated assets of unpacked registry packages (one folder per package, from `dpkg -x`) for
    /// `data import`: one folder per asset with its provenance (package, licence); see `scripts/real_corpus.sh`.
    StageReal(StageRealArgs),
}

#[derive(Args, Debug)]
pub struct StageRealArgs {
    /// Folder holding one unpacked package per sub-folder.
    pub extracted: PathBuf,
    /// Staging folder to write.
    #[arg(long)]
    pub out: PathBuf,
}

#[derive(Args, Debug)]
pub struct ConvertArgs {
    /// Input clip: .bin, .gltf, .glb or a folder of .obj frames.
    pub input: PathBuf,
    /// Output clip; the extension picks the format.
    pub output: PathBuf,
    /// Take (animation) to read, by name or index (formats with takes; default: the first).
    #[arg(long)]
    pub take: Option<String>,
    /// Normalise by frame 0 (docs/method.md (D1)–(D3)).
    #[arg(long)]
    pub normalize: bool,
    /// Weld vertices closer than EPS before writing.
    #[arg(long, value_name = "EPS")]
    pub weld: Option<f32>,
}

#[derive(Args, Debug)]
pub struct MergeArgs {
    /// The sharded store folder (created; must not be a one-file store).
    pub store: PathBuf,
    /// Shard folders, in the order their clips are numbered (inside STORE, or anywhere: paths outside it are
    /// recorded absolute).
    #[arg(required = true)]
    pub shards: Vec<PathBuf>,
    /// The largest shard (`clips.bin`) taken: a larger one is refused with the shard count that would fit
    /// (`1GiB`, `500M`, bytes).
    #[arg(long, default_value = "1GiB", value_parser = store::parse_bytes)]
    pub max_shard_bytes: u64,
}

#[derive(Args, Debug)]
pub struct ImportArgs {
    /// Clip files or folders (searched recursively).
    #[arg(required = true)]
    pub sources: Vec<PathBuf>,
    /// Store folder (created, or re-imported into).
    #[arg(long)]
    pub out: PathBuf,
    /// Smallest accepted vertex count (inclusive).
    #[arg(long, default_value_t = 512)]
    pub min_vertices: usize,
    /// Largest accepted vertex count (inclusive).
    #[arg(long, default_value_t = 4096)]
    pub max_vertices: usize,
    /// Window length T.
    #[arg(long, default_value_t = 16)]
    pub frames: usize,
    /// Frames between window starts.
    #[arg(long, default_value_t = 1)]
    pub stride: usize,
    /// Weld vertices closer than EPS (off by default).
    #[arg(long, value_name = "EPS")]
    pub weld: Option<f32>,
    /// FPS tokens P per clip.
    #[arg(long, default_value_t = DEFAULT_P)]
    pub p: usize,
    /// Longest take (animation) read from a file with takes, in frames; a longer one is rejected unread.
    #[arg(long, default_value_t = any4d_data::formats::skeletal::MAX_FRAMES)]
    pub max_frames: usize,
    /// Play a take shorter than the window as a cycle when its last frame leads back to its first (a walk or
    /// idle loop); without it such takes are rejected.
    #[arg(long)]
    pub loop_short: bool,
    /// Import only shard K of N (counted from 0): the sources whose path below the folder given hashes to K, so
    /// N processes or machines (a Slurm array, an indexed Job, GNU parallel) write N shard folders that `data
    /// merge` makes one store.
    #[arg(long, value_name = "K/N")]
    pub shard: Option<ShardSpec>,
}

#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Store folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Number of clips.
    #[arg(long)]
    pub clips: usize,
    /// Generator seed.
    #[arg(long)]
    pub seed: u64,
    /// Frames per clip.
    #[arg(long, default_value_t = 16)]
    pub frames: usize,
    /// Smallest vertex count (generator default if omitted).
    #[arg(long)]
    pub min_vertices: Option<usize>,
    /// Largest vertex count (generator default if omitted).
    #[arg(long)]
    pub max_vertices: Option<usize>,
    /// FPS tokens P per clip.
    #[arg(long, default_value_t = DEFAULT_P)]
    pub p: usize,
    /// Store windows of this many frames [default: --frames]; `--frames 31 --window 16 --stride 15` makes the
    /// long-horizon pairs of `eval run --protocol table2`.
    #[arg(long)]
    pub window: Option<usize>,
    /// Frames between window starts.
    #[arg(long, default_value_t = 1)]
    pub stride: usize,
    /// Every clip animates one and the same rest mesh of this shape family (blob, tube, humanoid, quadruped, sheet,
    /// worm, helix): a single-topology store, what `train bdlstm --variant acap` needs.
    #[arg(long, value_parser = parse_body)]
    pub body: Option<ShapeFamily>,
    /// The generator: `shapes` (shape families deformed by motion families) or `rigged` (skinned characters on
    /// random skeletons — biped, quadruped, insect, bird, snake, multi-armed — performing actions).
    #[arg(long, default_value = "shapes", value_parser = parse_family)]
    pub family: Family,
    /// With `--family rigged`: every clip of this skeleton (biped, quadruped, insect, bird, snake, multiarm).
    #[arg(long, value_parser = parse_template)]
    pub template: Option<Template>,
    /// With `--family rigged`: every clip performs this action (walk, run, jump, turn, attack, wave, fall, idle,
    /// fly, slither), on the skeletons that can.
    #[arg(long, value_parser = parse_action)]
    pub action: Option<Action>,
    /// Put each clip in a procedural scene around it (a floor and a pillar, walls, a low ceiling, a box or a
    /// table, never touching the clip), stored with its windows; the caption names the furniture.
    #[arg(long)]
    pub scenes: bool,
    /// Write only shard K of N (counted from 0): the clips whose source `synth:<seed>:<index>` hashes to K (see
    /// `data import --shard`).
    #[arg(long, value_name = "K/N")]
    pub shard: Option<ShardSpec>,
}

/// The one of `all` called `name`, else an error listing the names.
fn parse_named<T: Copy>(name: &str, what: &str, all: &[T], name_of: fn(T) -> &'static str) -> Result<T, String> {
    all.iter().copied().find(|&x| name_of(x) == name).ok_or_else(|| {
        let names: Vec<&str> = all.iter().map(|&x| name_of(x)).collect();
        format!("unknown {what} {name:?}; one of {}", names.join(", "))
    })
}

fn parse_template(name: &str) -> Result<Template, String> {
    parse_named(name, "skeleton template", &Template::ALL, Template::name)
}

fn parse_action(name: &str) -> Result<Action, String> {
    parse_named(name, "action", &Action::ALL, Action::name)
}

fn parse_family(name: &str) -> Result<Family, String> {
    parse_named(name, "generator", &Family::ALL, Family::name)
}

fn parse_body(name: &str) -> Result<ShapeFamily, String> {
    parse_named(name, "shape family", &ShapeFamily::ALL, ShapeFamily::name)
}

/// Output format of `inspect`.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputFormat {
    Table,
    Json,
}

#[derive(Args, Debug)]
pub struct InspectArgs {
    /// A store folder or a clip file.
    pub path: PathBuf,
    #[arg(long, value_enum, default_value_t = OutputFormat::Table)]
    pub format: OutputFormat,
}

#[derive(Args, Debug)]
pub struct VerifyArgs {
    /// A store folder.
    pub dir: PathBuf,
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// A clip file, or a store folder.
    pub path: PathBuf,
    /// Clip id inside a store (default: its first clip).
    #[arg(long)]
    pub clip: Option<String>,
    /// Output PNG.
    #[arg(long)]
    pub out: PathBuf,
    /// Take (animation) of a clip file, by name or index (default: the first).
    #[arg(long)]
    pub take: Option<String>,
    /// A static scene (`.obj`, in the clip's coordinates) drawn in grey around a clip file; a store clip is drawn in
    /// the scene stored with it.
    #[arg(long)]
    pub scene: Option<PathBuf>,
}

/// Exit code of `import` when some sources were rejected (the store is still written).
pub const EXIT_REJECTED: u8 = 2;

pub fn exec(cmd: DataCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        DataCmd::Convert(a) => convert(a),
        DataCmd::Import(a) => import(a),
        DataCmd::Synth(a) => synth(a),
        DataCmd::Merge(a) => {
            let manifest = store::merge_bounded(&a.store, &a.shards, a.max_shard_bytes)?;
            let clips: usize = manifest.shards.iter().map(|s| s.clips).sum();
            let bytes: u64 = manifest.shards.iter().map(|s| s.bytes).sum();
            emit(&format!(
                "{}: {} shards, {clips} clips, {bytes} bytes (T = {}, P = {}); {} written\n",
                a.store.display(),
                manifest.shards.len(),
                manifest.frames,
                manifest.p,
                store::MANIFEST_FILE
            ))?;
            Ok(ExitCode::SUCCESS)
        }
        DataCmd::Inspect(a) => {
            let found = inspect::inspect(&a.path)?;
            match a.format {
                OutputFormat::Table => emit(&found.to_table())?,
                OutputFormat::Json => emit(&format!("{}\n", found.to_json()))?,
            }
            Ok(ExitCode::SUCCESS)
        }
        DataCmd::Verify(a) => {
            let report = store::verify_store(&a.dir)?;
            emit(&report.to_string())?;
            Ok(if report.is_ok() {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            })
        }
        DataCmd::Render(a) => render(a),
        DataCmd::StageReal(a) => {
            let report = any4d_data::real_corpus::stage(&a.extracted, &a.out)?;
            for (package, n) in &report.assets {
                println!("{package}: {n} assets staged");
            }
            for (member, why) in &report.refused {
                println!("  refused {member}: {why}");
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// Print to stdout; a closed pipe (`any4d data inspect … | head`) ends the output quietly instead of panicking.
fn emit(text: &str) -> anyhow::Result<()> {
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}

fn weld(eps: Option<f32>) -> Weld {
    eps.map_or(Weld::Off, Weld::Eps)
}

fn convert(a: ConvertArgs) -> anyhow::Result<ExitCode> {
    let taken = read_taken(&a.input, a.take.as_deref())?;
    // The take's own rate travels into formats that keep one (glTF); 0 = the file does not say.
    let fps = taken.take.as_ref().map(|t| t.fps).filter(|&f| f > 0.0);
    let mut clip = weld(a.weld).apply(taken.clip)?;
    if a.normalize {
        clip = preprocess::normalize(&clip).0;
    }
    formats::write_clip_at(&a.output, &clip, fps)?;
    println!(
        "{} → {}: {} frames, {} vertices, {} faces",
        a.input.display(),
        a.output.display(),
        clip.frames,
        clip.n_vertices,
        clip.faces.len()
    );
    Ok(ExitCode::SUCCESS)
}

/// A clip file, at take `take` (name or index) when given.
fn read_file(path: &Path, take: Option<&str>) -> anyhow::Result<Clip> {
    Ok(read_taken(path, take)?.clip)
}

fn read_taken(path: &Path, take: Option<&str>) -> anyhow::Result<formats::Taken> {
    let opts = formats::skeletal::ReadOptions {
        take: take.map_or(formats::skeletal::TakeSel::First, formats::skeletal::TakeSel::parse),
        ..Default::default()
    };
    Ok(formats::read_take(path, &opts)?)
}

fn progress_bar(what: &str) -> ProgressBar {
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template(&format!(
            "{what} {{bar:40}} {{pos}}/{{len}} sources, {{per_sec}}, ETA {{eta}}"
        ))
        .expect("static progress template"),
    );
    bar
}

fn import(a: ImportArgs) -> anyhow::Result<ExitCode> {
    let opts = ImportOptions {
        filter: VertexFilter {
            min: a.min_vertices,
            max: a.max_vertices,
        },
        frames: a.frames,
        stride: a.stride,
        weld: weld(a.weld),
        p: a.p,
        max_frames: a.max_frames,
        loop_short: a.loop_short,
        shard: a.shard,
        ..ImportOptions::default()
    };
    opts.validate()?;
    let bar = progress_bar("import");
    let tick = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let report = store::import_with_progress(&a.sources, &a.out, &opts, Some(&tick))?;
    bar.finish_and_clear();
    emit(&report.to_string())?;
    if report.rejected.is_empty() {
        Ok(ExitCode::SUCCESS)
    } else {
        Ok(ExitCode::from(EXIT_REJECTED))
    }
}

fn synth(a: SynthArgs) -> anyhow::Result<ExitCode> {
    let default = SynthConfig::default();
    let cfg = SynthConfig {
        clips: a.clips,
        seed: a.seed,
        frames: a.frames,
        min_vertices: a.min_vertices.unwrap_or(default.min_vertices),
        max_vertices: a.max_vertices.unwrap_or(default.max_vertices),
        body: a.body,
        family: match (a.family, a.template, a.action) {
            (Family::Rigged(_), template, action) => Family::Rigged(RiggedKinds { template, action }),
            (Family::Shapes, None, None) => Family::Shapes,
            (Family::Shapes, _, _) => bail!("--template and --action choose rigged characters: add --family rigged"),
        },
        scenes: a.scenes,
    };
    cfg.validate()?;
    let bar = progress_bar("synth");
    let tick = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let windows = (a.window.unwrap_or(a.frames), a.stride);
    let report = store::write_synth_shard(&cfg, &a.out, a.p, windows, a.shard, Some(&tick))?;
    bar.finish_and_clear();
    emit(&report.to_string())?;
    if report.rejected.is_empty() {
        Ok(ExitCode::SUCCESS)
    } else {
        Ok(ExitCode::from(EXIT_REJECTED))
    }
}

fn render(a: RenderArgs) -> anyhow::Result<ExitCode> {
    let (clip, scene) = if a.path.is_dir() && store::is_store(&a.path) {
        if a.scene.is_some() {
            bail!("--scene draws around a clip file; a store clip is drawn in the scene stored with it");
        }
        let store = Store::open(&a.path)?;
        let i = match &a.clip {
            Some(id) => store
                .position(id)?
                .with_context(|| format!("{}: no clip with id {id:?}", a.path.display()))?,
            None if store.is_empty() => bail!("{}: the store holds no clip", a.path.display()),
            None => 0,
        };
        let stored = store.get(i)?;
        (stored.clip, stored.scene)
    } else {
        if a.clip.is_some() {
            bail!(
                "--clip selects a clip inside a store folder; {} is a clip file",
                a.path.display()
            );
        }
        (
            read_file(&a.path, a.take.as_deref())?,
            super::view::read_scene(a.scene.as_deref())?,
        )
    };
    render_contact_sheet(&clip, scene.as_ref(), &a.out, &RenderOptions::default())?;
    println!(
        "{} ({}) → {}: {:?}",
        clip.id,
        a.path.display(),
        a.out.display(),
        clip.caption
    );
    Ok(ExitCode::SUCCESS)
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Clips to write and read.
    #[arg(long, default_value_t = 32)]
    pub clips: usize,
    /// Vertices per clip.
    #[arg(long, default_value_t = 4096)]
    pub vertices: usize,
    /// Frames per clip.
    #[arg(long, default_value_t = 16)]
    pub frames: usize,
    /// FPS tokens P.
    #[arg(long, default_value_t = DEFAULT_P)]
    pub p: usize,
    /// The numpy reference script.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/bench_data_reference.py"))]
    pub script: PathBuf,
    /// Python interpreter for the reference.
    #[arg(long, default_value = "python3")]
    pub python: PathBuf,
}

/// What the numpy reference printed.
#[derive(serde::Deserialize)]
struct Reference {
    clips: usize,
    seconds: f64,
    fps_checksum: u64,
}

/// `any4d bench data`: [`DataBench`] in a temporary folder, beside the numpy reference on the same files.
pub fn bench(a: BenchArgs) -> anyhow::Result<ExitCode> {
    let bench = DataBench {
        clips: a.clips,
        vertices: a.vertices,
        frames: a.frames,
        p: a.p,
    };
    bench.check()?;
    let dir = tempfile::tempdir().context("creating the benchmark folder")?;
    let files = bench.write_clips(dir.path())?;
    println!(
        "bench data: {} clips × {} frames × {} vertices, P = {}",
        a.clips, a.frames, a.vertices, a.p
    );
    if cfg!(debug_assertions) {
        println!("note: debug build; run `cargo run --release -- bench data` for representative numbers");
    }
    let ours = bench.time(&files)?;
    let rate = a.clips as f64 / ours.seconds;
    println!("ours (1 thread):        {rate:>9.2} clips/s ({:.3} s)", ours.seconds);
    let reference = PythonReference {
        python: &a.python,
        script: &a.script,
        args: vec![dir.path().display().to_string(), "--p".into(), a.p.to_string()],
        threads: 1,
    };
    match reference.json()? {
        Ok(theirs) => compare(&theirs, &ours, a.clips)?,
        Err(Skipped(why)) => println!("reference skipped: {why}; reporting ours only"),
    }
    // Every reader on the same clips, written in its format.
    if a.vertices > usize::from(u16::MAX) {
        println!("per format: skipped (MD2 and PMD index vertices with 16 bits)");
        return Ok(ExitCode::SUCCESS);
    }
    let clips = (0..a.clips)
        .map(|i| bench_clip(i, a.frames, a.vertices))
        .collect::<any4d_data::Result<Vec<_>>>()?;
    println!("per format (read one take + normalise + FPS, 1 thread; skeletal formats bake {JOINTS} joints):");
    for (format, rate) in per_format(&clips, &dir.path().join("formats"), a.p)? {
        println!("  {format:<8} {rate:>9.2} clips/s");
    }
    Ok(ExitCode::SUCCESS)
}

/// Print the numpy reference's rate beside ours; an FPS checksum that differs is an error.
fn compare(theirs: &Reference, ours: &DataTiming, clips: usize) -> anyhow::Result<()> {
    let rate = clips as f64 / ours.seconds;
    let their_rate = theirs.clips as f64 / theirs.seconds;
    println!(
        "numpy reference (1 core): {their_rate:>7.2} clips/s ({:.3} s)",
        theirs.seconds
    );
    println!("ratio ours / reference: {:.2}×", rate / their_rate);
    let agree = theirs.fps_checksum == ours.fps_checksum && theirs.clips == clips;
    println!(
        "FPS indices agree (checksum {}): {}",
        ours.fps_checksum,
        if agree { "yes" } else { "NO" }
    );
    if !agree {
        bail!(
            "the reference FPS checksum {} differs from ours {}",
            theirs.fps_checksum,
            ours.fps_checksum
        );
    }
    Ok(())
}

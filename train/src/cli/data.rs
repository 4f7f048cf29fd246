//! `any4d data …` and `any4d bench data`: parse arguments, call `any4d_data` (SPEC §2: clip files, the dataset
//! store, inspection, contact sheets; the throughput benchmark of import + normalise (D1)–(D3) + FPS).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::{Args, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};

use any4d_data::Clip;
use any4d_data::formats;
use any4d_data::fps::farthest_point_sampling;
use any4d_data::inspect;
use any4d_data::preprocess::{self, VertexFilter};
use any4d_data::render::{RenderOptions, render_contact_sheet};
use any4d_data::rng::{Rng, rng};
use any4d_data::store::{self, DEFAULT_P, ImportOptions, Store, Weld};
use any4d_data::synth::SynthConfig;

use super::bench_formats::JOINTS;

#[derive(Subcommand, Debug)]
pub enum DataCmd {
    /// Convert a clip between formats (chosen by extension); geometry is unchanged unless a flag asks.
    Convert(ConvertArgs),
    /// Import clip files and folders into a dataset store (normalise, FPS, split; rejected files are listed).
    Import(ImportArgs),
    /// Write procedural clips into a dataset store.
    Synth(SynthArgs),
    /// Summarise a dataset store or one clip file.
    Inspect(InspectArgs),
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
    /// Normalise by frame 0 (SPEC (D1)–(D3)).
    #[arg(long)]
    pub normalize: bool,
    /// Weld vertices closer than EPS before writing.
    #[arg(long, value_name = "EPS")]
    pub weld: Option<f32>,
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
}

/// Exit code of `import` when some sources were rejected (the store is still written).
pub const EXIT_REJECTED: u8 = 2;

pub fn run(cmd: DataCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        DataCmd::Convert(a) => convert(a),
        DataCmd::Import(a) => import(a),
        DataCmd::Synth(a) => synth(a),
        DataCmd::Inspect(a) => {
            let found = inspect::inspect(&a.path)?;
            match a.format {
                OutputFormat::Table => emit(&found.to_table())?,
                OutputFormat::Json => emit(&format!("{}\n", found.to_json()))?,
            }
            Ok(ExitCode::SUCCESS)
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
    let mut clip = read_file(&a.input, a.take.as_deref())?;
    if let Weld::Eps(eps) = weld(a.weld) {
        clip = preprocess::weld(&clip, eps);
    }
    if a.normalize {
        clip = preprocess::normalize(&clip).0;
    }
    formats::write_clip(&a.output, &clip)?;
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
    let opts = formats::skeletal::ReadOptions {
        take: take.map_or(formats::skeletal::TakeSel::First, formats::skeletal::TakeSel::parse),
        ..Default::default()
    };
    Ok(formats::read_take(path, &opts)?.clip)
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
    };
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
    };
    let bar = progress_bar("synth");
    let tick = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let report = store::write_synth_windows(&cfg, &a.out, a.p, a.window.unwrap_or(a.frames), a.stride, Some(&tick))?;
    bar.finish_and_clear();
    emit(&report.to_string())?;
    if report.rejected.is_empty() {
        Ok(ExitCode::SUCCESS)
    } else {
        Ok(ExitCode::from(EXIT_REJECTED))
    }
}

fn render(a: RenderArgs) -> anyhow::Result<ExitCode> {
    let clip = if a.path.is_dir() && a.path.join(store::CLIPS_FILE).exists() {
        let store = Store::open(&a.path)?;
        let i = match &a.clip {
            Some(id) => store
                .position(id)?
                .with_context(|| format!("{}: no clip with id {id:?}", a.path.display()))?,
            None if store.is_empty() => bail!("{}: the store holds no clip", a.path.display()),
            None => 0,
        };
        store.get(i)?.clip
    } else {
        if a.clip.is_some() {
            bail!(
                "--clip selects a clip inside a store folder; {} is a clip file",
                a.path.display()
            );
        }
        read_file(&a.path, a.take.as_deref())?
    };
    render_contact_sheet(&clip, &a.out, &RenderOptions::default())?;
    println!("{} ({}) → {}", clip.id, a.path.display(), a.out.display());
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
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/../scripts/bench_data_reference.py"))]
    pub script: PathBuf,
    /// Python interpreter for the reference.
    #[arg(long, default_value = "python3")]
    pub python: PathBuf,
}

/// A deterministic clip for the benchmark: a noisy sphere that drifts and breathes, with a triangle strip.
fn bench_clip(index: usize, frames: usize, n: usize) -> anyhow::Result<Clip> {
    let mut r = rng(index as u64, 0xbe7c);
    let base: Vec<[f32; 3]> = (0..n)
        .map(|_| {
            let v = [0, 1, 2].map(|_| r.random_range(-1.0f32..1.0));
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-3);
            v.map(|x| 3.0 * x / len + 0.05 * r.random_range(-1.0f32..1.0))
        })
        .collect();
    let vertices = (0..frames)
        .flat_map(|f| {
            let (s, dx) = (1.0 + 0.02 * f as f32, 0.1 * f as f32);
            base.iter()
                .map(move |p| [p[0] * s + dx, p[1] * s, p[2] * s])
                .collect::<Vec<_>>()
        })
        .collect();
    let faces = (0..n.saturating_sub(2) as u32).map(|i| [i, i + 1, i + 2]).collect();
    Ok(Clip::new(
        format!("bench-{index}"),
        vertices,
        frames,
        n,
        faces,
        "a benchmark blob",
        format!("bench:{index}"),
    )?)
}

/// What the numpy reference printed.
#[derive(serde::Deserialize)]
struct Reference {
    clips: usize,
    seconds: f64,
    fps_checksum: u64,
}

/// Run the reference script; `Ok(None)` when Python or numpy is missing (then only our numbers are reported).
fn run_reference(a: &BenchArgs, dir: &Path) -> anyhow::Result<Option<Reference>> {
    let out = Command::new(&a.python)
        .arg(&a.script)
        .arg(dir)
        .arg("--p")
        .arg(a.p.to_string())
        .env("OMP_NUM_THREADS", "1")
        .env("OPENBLAS_NUM_THREADS", "1")
        .env("MKL_NUM_THREADS", "1")
        .output();
    let out = match out {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            println!("reference: {} not found; reporting ours only", a.python.display());
            return Ok(None);
        }
        other => other.with_context(|| format!("running {}", a.python.display()))?,
    };
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        if stderr.contains("No module named 'numpy'") {
            println!(
                "reference: numpy is not installed for {}; reporting ours only",
                a.python.display()
            );
            return Ok(None);
        }
        bail!(
            "{} {} failed ({}): {stderr}",
            a.python.display(),
            a.script.display(),
            out.status
        );
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout
        .lines()
        .last()
        .with_context(|| format!("{} printed nothing", a.script.display()))?;
    Ok(Some(serde_json::from_str(line).with_context(|| {
        format!("{}: unexpected output {line:?}", a.script.display())
    })?))
}

pub fn bench(a: BenchArgs) -> anyhow::Result<ExitCode> {
    if a.clips == 0 || a.vertices < 3 || a.frames < 2 {
        bail!("bench data needs --clips ≥ 1, --vertices ≥ 3 and --frames ≥ 2");
    }
    let dir = std::env::temp_dir().join(format!("any4d-bench-data-{}", std::process::id()));
    std::fs::create_dir(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let result = bench_in(&a, &dir);
    std::fs::remove_dir_all(&dir).with_context(|| format!("removing the benchmark folder {}", dir.display()))?;
    result
}

fn bench_in(a: &BenchArgs, dir: &Path) -> anyhow::Result<ExitCode> {
    let mut files = Vec::with_capacity(a.clips);
    for i in 0..a.clips {
        let path = dir.join(format!("clip_{i:05}.bin"));
        formats::write_clip(&path, &bench_clip(i, a.frames, a.vertices)?)?;
        files.push(path);
    }
    println!(
        "bench data: {} clips × {} frames × {} vertices, P = {}",
        a.clips, a.frames, a.vertices, a.p
    );
    if cfg!(debug_assertions) {
        println!(
            "note: debug build; run `cargo run --release -p any4d-train -- bench data` for representative numbers"
        );
    }
    // (a) ours: read + normalise (D1)–(D3) + FPS, one thread.
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let (seconds, checksum) = pool.install(|| -> anyhow::Result<(f64, u64)> {
        let start = Instant::now();
        let mut checksum = 0u64;
        for path in &files {
            let clip = formats::read_clip(path)?;
            let (clip, _norm) = preprocess::normalize(&clip);
            checksum += farthest_point_sampling(clip.frame(0), a.p)
                .iter()
                .map(|&i| u64::from(i))
                .sum::<u64>();
        }
        Ok((start.elapsed().as_secs_f64(), checksum))
    })?;
    let ours = a.clips as f64 / seconds;
    println!("ours (1 thread):        {ours:>9.2} clips/s ({seconds:.3} s)");
    // (b) the numpy reference on the same files.
    if let Some(reference) = run_reference(a, dir)? {
        let theirs = reference.clips as f64 / reference.seconds;
        println!(
            "numpy reference (1 core): {theirs:>7.2} clips/s ({:.3} s)",
            reference.seconds
        );
        println!("ratio ours / reference: {:.2}×", ours / theirs);
        let agree = reference.fps_checksum == checksum && reference.clips == a.clips;
        println!(
            "FPS indices agree (checksum {checksum}): {}",
            if agree { "yes" } else { "NO" }
        );
        if !agree {
            bail!(
                "the reference FPS checksum {} differs from ours {checksum}",
                reference.fps_checksum
            );
        }
    }
    // (c) every reader on the same clips, written in its format.
    if a.vertices > usize::from(u16::MAX) {
        println!("per format: skipped (MD2 and PMD index vertices with 16 bits)");
        return Ok(ExitCode::SUCCESS);
    }
    let clips = (0..a.clips)
        .map(|i| bench_clip(i, a.frames, a.vertices))
        .collect::<anyhow::Result<Vec<_>>>()?;
    println!("per format (read one take + normalise + FPS, 1 thread; skeletal formats bake {JOINTS} joints):");
    for (format, rate) in super::bench_formats::per_format(&clips, &dir.join("formats"), a.p)? {
        println!("  {format:<8} {rate:>9.2} clips/s");
    }
    Ok(ExitCode::SUCCESS)
}

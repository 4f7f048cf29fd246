//! `any4d eval …` and `any4d bench metrics`: parse arguments, call `any4d_eval`. Metrics follow docs/method.md
//! §6.1–§6.2.

use std::path::PathBuf;
use std::process::{Command, ExitCode};
use std::time::Instant;

use any4d_data::formats::read_clip;
use any4d_eval::metrics::{ClipMetrics, Coordinates, Motion, Protocol, Rows, average, evaluate_clip_with};
use anyhow::{Context, bail};
use clap::{Args, Subcommand, ValueEnum};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

#[derive(Subcommand, Debug)]
pub enum EvalCmd {
    /// Score a predicted clip against its ground truth: RMSE, Chamfer, DTW, jerk, … (docs/method.md §6.2).
    Metrics(MetricsArgs),
    /// Run one paper table's protocol: per-clip parquet, Markdown/CSV summary, strips and plots.
    Run(Box<super::eval_run::RunArgs>),
    /// Redraw the strips and the RMSE-vs-K_x plot of an earlier `eval run`.
    Render(super::eval_run::RenderArgs),
}

/// How `eval metrics` prints its result.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    /// Raw values (not × 100) as one JSON object.
    Json,
    /// A table with distances × 100, as printed in the paper.
    Table,
}

/// Coordinate frame of the metrics.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum CoordinatesArg {
    /// Normalise both clips by ground-truth frame 0, (D1)–(D3) (docs/method.md §6.1).
    Normalise,
    /// Use the files' coordinates as they are.
    AsGiven,
}

#[derive(Args, Debug)]
pub struct MetricsArgs {
    /// Predicted clip (.bin, .gltf, .glb or a folder of .obj frames).
    pub pred: PathBuf,
    /// Ground-truth clip, same vertex count and frame count.
    pub gt: PathBuf,
    /// Zero-based keyframe indices, comma-separated, e.g. 0,7,15 [default: first and last frame].
    #[arg(long, value_delimiter = ',')]
    pub keyframes: Option<Vec<usize>>,
    /// Output format.
    #[arg(long, value_enum, default_value_t = OutputFormat::Table)]
    pub format: OutputFormat,
    /// Frame rate r of acceleration and jerk (E5): 1 = per frame, 10 = the 10 FPS renders.
    #[arg(long, default_value_t = 1.0)]
    pub rate: f64,
    /// Coordinate frame of every metric.
    #[arg(long, value_enum, default_value_t = CoordinatesArg::Normalise)]
    pub coordinates: CoordinatesArg,
}

pub fn run(cmd: EvalCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        EvalCmd::Metrics(args) => metrics(args),
        EvalCmd::Run(args) => super::eval_run::run(*args),
        EvalCmd::Render(args) => super::eval_run::render(args),
    }
}

fn metrics(args: MetricsArgs) -> anyhow::Result<ExitCode> {
    let pred = read_clip(&args.pred).with_context(|| format!("reading the prediction {}", args.pred.display()))?;
    let gt = read_clip(&args.gt).with_context(|| format!("reading the ground truth {}", args.gt.display()))?;
    let keyframes = args
        .keyframes
        .clone()
        .unwrap_or_else(|| vec![0, gt.frames.saturating_sub(1)]);
    let coordinates = match args.coordinates {
        CoordinatesArg::Normalise => Coordinates::NormaliseByGtFrame0,
        CoordinatesArg::AsGiven => Coordinates::AsGiven,
    };
    let protocol = Protocol {
        coordinates,
        rate: args.rate,
    };
    let m = evaluate_clip_with(
        Motion::from_clip(&pred)?,
        Motion::from_clip(&gt)?,
        &keyframes,
        &protocol,
    )
    .with_context(|| format!("scoring {} against {}", args.pred.display(), args.gt.display()))?;
    match args.format {
        OutputFormat::Json => println!("{}", serde_json::to_string_pretty(&m)?),
        OutputFormat::Table => {
            println!(
                "{} vs {}: {} frames × {} vertices, keyframes {keyframes:?}, r = {}",
                args.pred.display(),
                args.gt.display(),
                gt.frames,
                gt.n_vertices,
                args.rate
            );
            print!("{}", table(&m));
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The paper's layout: distances × 100, then the motion diagnostics raw with their ground-truth values.
fn table(m: &ClipMetrics) -> String {
    let mut s = String::new();
    for (name, v) in [
        ("RMSE ×100", m.rmse),
        ("mae_elem ×100", m.mae_elem),
        ("Chamfer ×100", m.chamfer),
        ("DTW ×100", m.dtw),
        ("mean vertex error ×100", m.mean_vertex_error),
        ("keyframe RMSE ×100", m.keyframe_rmse),
    ] {
        s += &format!("{name:<24}{:>12.4}\n", 100.0 * v);
    }
    s += &format!("{:<24}{:>14}{:>14}{:>14}\n", "", "prediction", "GT", "ratio");
    for (name, p, g, r) in [
        ("acceleration", m.accel, m.accel_gt, m.accel_ratio),
        ("jerk", m.jerk, m.jerk_gt, m.jerk_ratio),
        ("motion energy", m.energy, m.energy_gt, m.energy_ratio),
    ] {
        s += &format!("{name:<24}{:>14}{:>14}{:>14}\n", number(p), number(g), number(r));
    }
    s
}

/// Six decimals, or scientific notation for values too small or large for them.
fn number(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-3..1e6).contains(&v.abs()) {
        format!("{v:.4e}")
    } else {
        format!("{v:.6}")
    }
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Number of synthetic clips.
    #[arg(long, default_value_t = 8)]
    pub clips: usize,
    /// Vertices per clip.
    #[arg(long, default_value_t = 4096)]
    pub vertices: usize,
    /// Frames per clip (≥ 4).
    #[arg(long, default_value_t = 16)]
    pub frames: usize,
    /// Timed repetitions; the median is reported.
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// The numpy/scipy reference script.
    #[arg(long, default_value = "scripts/metrics_reference.py")]
    pub script: PathBuf,
    /// Python interpreter for the reference.
    #[arg(long, default_value = "python3")]
    pub python: String,
}

/// Synthetic clips for the benchmark: a random cloud moving smoothly, and a noisy prediction. Rows `[T * N]` each.
fn bench_clips(args: &BenchArgs) -> Vec<(Rows, Rows)> {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    (0..args.clips)
        .map(|_| {
            let base: Vec<[f32; 3]> = (0..args.vertices)
                .map(|_| [0; 3].map(|_| rng.random_range(-1.0f32..1.0)))
                .collect();
            let vel: [f32; 3] = [0; 3].map(|_| rng.random_range(-0.05f32..0.05));
            let gt: Vec<[f32; 3]> = (0..args.frames)
                .flat_map(|f| base.iter().map(move |b| [0, 1, 2].map(|k| b[k] + vel[k] * f as f32)))
                .collect();
            let pred = gt
                .iter()
                .map(|g| [0, 1, 2].map(|k| g[k] + rng.random_range(-0.02f32..0.02)))
                .collect();
            (pred, gt)
        })
        .collect()
}

/// Median seconds of `repeat` runs of `f`, and the last result.
fn timed<T>(repeat: usize, mut f: impl FnMut() -> anyhow::Result<T>) -> anyhow::Result<(f64, T)> {
    let mut times = Vec::with_capacity(repeat);
    let mut last = None;
    for _ in 0..repeat.max(1) {
        let start = Instant::now();
        last = Some(f()?);
        times.push(start.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    let result = last.context("no timed run")?;
    Ok((times[times.len() / 2], result))
}

/// Runs the reference script on the same clips; `Err` carries why it could not run (missing python or scipy).
fn reference(args: &BenchArgs, clips: &[(Rows, Rows)], keys: &[usize]) -> anyhow::Result<(f64, ClipMetrics)> {
    if !args.script.is_file() {
        bail!(
            "reference script {} not found (run from the repository root or pass --script)",
            args.script.display()
        );
    }
    let file = std::env::temp_dir().join(format!("any4d-bench-metrics-{}.f32", std::process::id()));
    let bytes: Vec<u8> = clips
        .iter()
        .flat_map(|(p, g)| p.iter().chain(g))
        .flatten()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    std::fs::write(&file, bytes).with_context(|| format!("writing {}", file.display()))?;
    let keys_arg = keys.iter().map(|k| k.to_string()).collect::<Vec<_>>().join(",");
    let output = Command::new(&args.python)
        .arg(&args.script)
        .args(["--bench", &file.display().to_string()])
        .args(["--clips", &args.clips.to_string(), "--frames", &args.frames.to_string()])
        .args(["--vertices", &args.vertices.to_string(), "--keyframes", &keys_arg])
        .args(["--repeat", &args.repeat.to_string()])
        .env("OMP_NUM_THREADS", "1")
        .env("OPENBLAS_NUM_THREADS", "1")
        .env("MKL_NUM_THREADS", "1")
        .output();
    let removed = std::fs::remove_file(&file);
    let output = output.with_context(|| format!("starting `{}` (is Python installed?)", args.python))?;
    removed.with_context(|| format!("removing {}", file.display()))?;
    if !output.status.success() {
        let stderr = String::from_utf8_lossy(&output.stderr);
        bail!(
            "{} failed (numpy/scipy missing?): {}",
            args.script.display(),
            stderr.trim().lines().last().unwrap_or("")
        );
    }
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).context("parsing the reference's JSON")?;
    let seconds = json["seconds"].as_f64().context("reference JSON lacks `seconds`")?;
    let clips_metrics: Vec<ClipMetrics> =
        serde_json::from_value(json["metrics"].clone()).context("reference JSON `metrics`")?;
    Ok((seconds, average(&clips_metrics)?))
}

pub fn bench(args: BenchArgs) -> anyhow::Result<ExitCode> {
    if args.frames < 4 || args.vertices == 0 || args.clips == 0 {
        bail!("--frames must be ≥ 4 (jerk), --vertices and --clips ≥ 1");
    }
    let clips = bench_clips(&args);
    let keys = [0, args.frames - 1];
    let protocol = Protocol::default();
    let score = || -> anyhow::Result<ClipMetrics> {
        let per_clip = clips
            .par_iter()
            .map(|(p, g)| {
                let (p, g) = (
                    Motion::new(p, args.frames, args.vertices)?,
                    Motion::new(g, args.frames, args.vertices)?,
                );
                evaluate_clip_with(p, g, &keys, &protocol)
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(average(&per_clip)?)
    };
    let threads = rayon::current_num_threads();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let (t1, ours) = one.install(|| timed(args.repeat, score))?;
    let (tn, _) = timed(args.repeat, score)?;
    println!(
        "metrics bench: {} clips × {} frames × {} vertices, keyframes {keys:?}, median of {} runs",
        args.clips, args.frames, args.vertices, args.repeat
    );
    let rate = |secs: f64| args.clips as f64 / secs;
    println!("ours, 1 thread          {:>10.2} clips/s", rate(t1));
    println!("ours, {threads:>2} threads        {:>10.2} clips/s", rate(tn));
    match reference(&args, &clips, &keys) {
        Ok((tr, reference)) => {
            println!("numpy+scipy, 1 core     {:>10.2} clips/s", rate(tr));
            println!(
                "speed-up over the reference: {:.2}× (1 thread), {:.2}× ({threads} threads)",
                tr / t1,
                tr / tn
            );
            let (a, b) = (serde_json::to_value(ours)?, serde_json::to_value(reference)?);
            let worst = b
                .as_object()
                .context("reference metrics are not an object")?
                .iter()
                .map(|(k, v)| {
                    let (x, y) = (a[k].as_f64().unwrap_or(f64::NAN), v.as_f64().unwrap_or(f64::NAN));
                    ((x - y).abs() / y.abs().max(1e-12), k.clone())
                })
                .max_by(|p, q| p.0.total_cmp(&q.0))
                .context("no metrics to compare")?;
            println!(
                "agreement: largest relative difference of the mean metrics {:.1e} ({})",
                worst.0, worst.1
            );
        }
        Err(e) => println!("reference skipped: {e:#}"),
    }
    if cfg!(debug_assertions) {
        println!(
            "note: dev-profile binary (the workspace builds any4d-eval at opt-level 2 there); \
             `cargo run --release -p any4d-train -- bench metrics` gives release numbers"
        );
    }
    Ok(ExitCode::SUCCESS)
}

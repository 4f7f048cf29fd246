//! `any4d complete` and `any4d extend`: parse arguments, load the keyframe RF run, call
//! `any4d_train::complete` (docs/method.md §4.6, §7) and write the samples.

use std::path::PathBuf;
use std::process::ExitCode;

use any4d_data::formats;
use any4d_eval::view::{DEFAULT_FPS, Page, Panel, write_page};
use any4d_train::backend::{self, Backend, Precision};
use any4d_train::complete::{CompleteOptions, KeyMeshes, SAMPLE_SEED_STRIDE, average_samples, complete, sample_path};
use any4d_train::evaluate::{SamplingSetup, keyframe_method};
use anyhow::{Context, bail};
use clap::Args;

use super::enum_parser;

/// Most samples one call writes (each is a file; more is a loop in a script).
pub const MAX_SAMPLES: usize = 1000;

/// The shipped small keyframe RF, used when `--rf` is not given (run from the repository root).
pub const SHIPPED_RF: &str = "weights/small/rf";

#[derive(Args, Debug)]
pub struct CompleteArgs {
    /// A clip file whose frames `--keyframes` are kept (any readable format: .glb, .gltf, .bin, an OBJ folder, …).
    #[arg(long, conflicts_with = "key", requires = "keyframes")]
    pub clip: Option<PathBuf>,
    /// Frames of `--clip` to keep, comma-separated; must include 0 (the reference).
    #[arg(long, value_delimiter = ',', requires = "clip")]
    pub keyframes: Vec<usize>,
    /// A keyframe mesh at a frame: `FRAME=FILE` (a single .obj, or frame 0 of any clip file), repeatable; one of
    /// them at frame 0 (the reference), all of one topology.
    #[arg(long, value_parser = parse_key)]
    pub key: Vec<(usize, PathBuf)>,
    /// The prompt; empty = unconditional. Default: the clip's caption for `--clip`, empty for `--key`.
    #[arg(long)]
    pub caption: Option<String>,
    /// The keyframe RF run (its VAE is the run it was trained on).
    #[arg(long, default_value = SHIPPED_RF)]
    pub rf: PathBuf,
    /// The VAE run; optional, since the RF run records the VAE it was trained on, and refused when it is another
    /// one (its latents would not be the ones the RF learned).
    #[arg(long)]
    pub vae: Option<PathBuf>,
    /// Frames of the output. `complete`: default the clip's frame count (`--clip`) or the model's window (`--key`).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Sampler seed of the first sample (sample k uses seed + k · 1 000 000).
    #[arg(long, default_value_t = 42)]
    pub seed: u64,
    /// Number of samples; more than one writes `<out stem>_s<k>.<ext>`.
    #[arg(long, default_value_t = 1)]
    pub samples: usize,
    /// Write one file, `--out`: the per-vertex mean of the `--samples` (at least 2), keyframes exact. Smoother than
    /// any one sample, and nearer the ground truth on average (experiments/2026-12-02-small-w256).
    #[arg(long)]
    pub average: bool,
    /// Move every frame by the keyframes' decoding residuals, interpolated in time (docs/method.md §5.6, not the
    /// paper's): the given keyframes show how far the VAE's decoding of this mesh is off, and the in-between frames
    /// are corrected by as much (experiments/2026-12-07-keyframe-correction).
    #[arg(long)]
    pub correct: bool,
    /// Classifier-free guidance weight (1.0 in the paper: one conditional branch).
    #[arg(long, default_value_t = 1.0)]
    pub cfg: f64,
    /// Scale s of the sampler's initial noise, X₀ = s ε (1 in the paper; 0 gives one deterministic completion;
    /// below 1 it is not a temperature and moves the samples further from the truth: docs/method.md §4.6).
    #[arg(long, default_value_t = 1.0)]
    pub noise_scale: f64,
    /// Grid points of the ODE solver over [0, 1] (64 in the paper; midpoint rule).
    #[arg(long, default_value_t = SamplingSetup::default().n_grid)]
    pub steps: usize,
    /// Output: `.glb`, `.gltf`, `.bin`, `.anime` or a folder of OBJ frames (no extension), chosen by the path.
    #[arg(long)]
    pub out: PathBuf,
    /// Overwrite outputs that exist (refused otherwise).
    #[arg(long)]
    pub force: bool,
    /// Also write a viewer page (HTML, self-contained) playing every sample with the keyframes marked.
    #[arg(long)]
    pub view: Option<PathBuf>,
    /// A static scene (`.obj` of closed parts, in the keyframes' coordinates): each output is scored in it
    /// ((E8)–(E10), docs/method.md §6.5: does the completion pass through walls or sink into the floor?) and the
    /// `--view` page draws it. A scene-aware RF (`model.scene`, docs/method.md §4.12) also completes in it, for one
    /// window of the model's length only (more frames are refused); other RFs do not see it.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Compute backend.
    #[arg(long, value_parser = enum_parser(&Backend::ALL), default_value = "flex")]
    pub backend: Backend,
}

fn parse_key(s: &str) -> Result<(usize, PathBuf), String> {
    let (frame, file) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}`: expected FRAME=FILE, e.g. 0=start.obj"))?;
    let frame = frame
        .trim()
        .parse::<usize>()
        .map_err(|e| format!("`{s}`: frame `{frame}` is not a frame index ({e})"))?;
    if file.is_empty() {
        return Err(format!("`{s}`: no file after `=`"));
    }
    Ok((frame, PathBuf::from(file)))
}

/// `any4d complete` (`extend = false`) or `any4d extend` (`--frames` required).
pub fn exec(args: CompleteArgs, extend: bool) -> anyhow::Result<ExitCode> {
    let keys = match (&args.clip, args.key.is_empty()) {
        (Some(clip), true) => KeyMeshes::from_clip(clip, &args.keyframes)?,
        (None, false) => KeyMeshes::from_files(&args.key)?,
        (None, true) => bail!("give the keyframes: --clip FILE --keyframes 0,…  or  --key 0=FILE --key F=FILE …"),
        (Some(_), false) => bail!("give either --clip with --keyframes or --key, not both"),
    };
    if !(1..=MAX_SAMPLES).contains(&args.samples) {
        bail!("--samples {} is outside 1..={MAX_SAMPLES}", args.samples);
    }
    if args.average && args.samples < 2 {
        bail!("--average needs --samples 2 or more (it writes their per-vertex mean)");
    }
    let written = if args.average { 1 } else { args.samples };
    if extend && args.frames.is_none() {
        bail!("`extend` needs the length of the output: --frames N (e.g. 31 or 91)");
    }
    let outputs: Vec<PathBuf> = (0..written)
        .map(|k| sample_path(&args.out, k, written))
        .chain(args.view.clone())
        .collect();
    if !args.force
        && let Some(existing) = outputs.iter().find(|p| p.exists())
    {
        bail!("{} exists; pass --force to overwrite it", existing.display());
    }
    if !args.rf.exists() {
        bail!(
            "RF run {} not found: pass --rf RUN (the default is the shipped {SHIPPED_RF}, found from the \
             repository root)",
            args.rf.display()
        );
    }
    if let Some(vae) = &args.vae {
        let recorded = any4d_train::runs::read_vae_record(&args.rf)?.run;
        let given = vae
            .canonicalize()
            .with_context(|| format!("VAE run {}", vae.display()))?;
        let recorded = recorded.canonicalize().unwrap_or(recorded);
        if given != recorded {
            bail!(
                "--vae {} is not the VAE run the RF {} was trained on ({}): its latents and statistics differ; \
                 leave --vae out to use the recorded one",
                vae.display(),
                args.rf.display(),
                recorded.display()
            );
        }
    }
    let scene = super::view::read_scene(args.scene.as_deref())?;
    let device = backend::device(args.backend, Precision::F32)?;
    let sampling = SamplingSetup {
        n_grid: args.steps,
        guidance: args.cfg,
        noise_scale: args.noise_scale,
        ..SamplingSetup::default()
    };
    let model = keyframe_method(&args.rf, sampling, args.correct, &device)
        .with_context(|| format!("loading the keyframe RF run {}", args.rf.display()))?;
    let frames = args.frames.or(keys.clip_frames).unwrap_or(model.window);
    let caption = args
        .caption
        .clone()
        .or_else(|| keys.clip_caption.clone())
        .unwrap_or_default();
    let opts = CompleteOptions {
        frames,
        caption: caption.clone(),
        seed: args.seed,
        samples: args.samples,
        scene: scene.clone().filter(|_| model.reads_scene),
    };
    let mut clips = complete(&keys, model.method.as_ref(), model.window, model.tokens, &opts)?;
    if args.average {
        clips = vec![average_samples(&clips, &keys)?];
    }
    println!(
        "{} frames from keyframes {:?} of {} vertices, caption {caption:?}, model {}",
        frames,
        keys.frames(),
        keys.n_vertices,
        model.checkpoint
    );
    for (k, clip) in clips.iter().enumerate() {
        let path = sample_path(&args.out, k, clips.len());
        formats::write_clip(&path, clip).with_context(|| format!("writing sample {k}"))?;
        println!("wrote {}", path.display());
    }
    if args.view.is_none() && scene.is_none() {
        return Ok(ExitCode::SUCCESS);
    }
    let mut panels: Vec<Panel> = clips
        .into_iter()
        .enumerate()
        .map(|(k, clip)| Panel {
            label: if args.average {
                format!("mean of {} samples (seeds from {})", args.samples, args.seed)
            } else {
                format!(
                    "sample {k} (seed {})",
                    args.seed.wrapping_add(k as u64 * SAMPLE_SEED_STRIDE)
                )
            },
            clip,
            metrics: Vec::new(),
        })
        .collect();
    if let Some(scene) = &scene {
        super::view::score_in_scene(scene, &mut panels)?;
        for p in &panels {
            let lines: Vec<String> = p.metrics.iter().map(|(k, v)| format!("{k} {v}")).collect();
            println!("{} in the scene: {}", p.label, lines.join(", "));
        }
    }
    if let Some(view) = &args.view {
        let page = Page {
            title: format!("{} — completed by {}", keys.id, model.checkpoint),
            caption,
            keyframes: keys.frames(),
            ground_truth: false,
            panels,
            fps: DEFAULT_FPS,
            scene,
        };
        write_page(&page, view)?;
        println!("wrote {}", view.display());
    }
    Ok(ExitCode::SUCCESS)
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// The keyframe RF run (default: the shipped small model).
    #[arg(long, default_value = SHIPPED_RF)]
    pub rf: PathBuf,
    /// Vertex counts of the completed meshes.
    #[arg(long, value_delimiter = ',', default_values = ["512", "1024", "2048", "4096"])]
    pub vertices: Vec<usize>,
    /// Timed repetitions per size (after one warm-up); the median is reported.
    #[arg(long, default_value_t = 5)]
    pub reps: usize,
    /// Grid points of the ODE solver (64 in the paper).
    #[arg(long, default_value_t = SamplingSetup::default().n_grid)]
    pub steps: usize,
    /// Compute backend.
    #[arg(long, value_parser = enum_parser(&Backend::ALL), default_value = "flex")]
    pub backend: Backend,
}

/// `any4d bench complete`: wall time of `complete` for one 16-frame clip (two keyframes) per vertex count, the model
/// loaded once (its load time printed apart).
pub fn bench(args: BenchArgs) -> anyhow::Result<ExitCode> {
    if args.reps == 0 {
        bail!("--reps must be at least 1");
    }
    let device = backend::device(args.backend, Precision::F32)?;
    let sampling = SamplingSetup {
        n_grid: args.steps,
        ..SamplingSetup::default()
    };
    let t0 = std::time::Instant::now();
    let model = keyframe_method(&args.rf, sampling, false, &device)
        .with_context(|| format!("loading the keyframe RF run {}", args.rf.display()))?;
    println!(
        "model {} loaded in {:.2} s; {}-point midpoint grid, {} threads",
        model.checkpoint,
        t0.elapsed().as_secs_f64(),
        args.steps,
        rayon::current_num_threads()
    );
    println!("| vertices | median s | min s | max s |\n|---|---|---|---|");
    for &n in &args.vertices {
        let keys = any4d_train::complete::benchmark_keys(n, model.window - 1)?;
        let opts = CompleteOptions {
            frames: model.window,
            caption: String::new(),
            seed: 42,
            samples: 1,
            scene: None,
        };
        let mut times = Vec::with_capacity(args.reps);
        for rep in 0..=args.reps {
            let t = std::time::Instant::now();
            complete(&keys, model.method.as_ref(), model.window, model.tokens, &opts)?;
            if rep > 0 {
                times.push(t.elapsed().as_secs_f64());
            }
        }
        times.sort_by(f64::total_cmp);
        println!(
            "| {n} | {:.3} | {:.3} | {:.3} |",
            times[times.len() / 2],
            times[0],
            times[times.len() - 1]
        );
    }
    Ok(ExitCode::SUCCESS)
}

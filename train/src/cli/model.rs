//! `any4d model …` and `any4d bench model`: parameter counts of the network a config describes, and RF
//! forward+backward (docs/method.md §4.3) and VAE encode+decode (docs/method.md §3.2, §3.5) time per clip, optionally
//! beside AnimateAnyMesh's PyTorch networks run by `scripts/bench_torch_reference.py` on the same shapes and thread
//! count. Parses arguments and the `[model]` table, calls `any4d_model::summary`.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use any4d_model::dymesh_vae::DyMeshVaeConfig;
use any4d_model::frame_vae::FrameVaeConfig;
use any4d_model::mmdit::{KfMode, MmditConfig};
use any4d_model::summary::{
    StepTiming, TOTAL, format_report, param_report, time_dymesh_reconstruct, time_rf_step, time_vae_reconstruct,
};
use anyhow::{Context, bail};
use burn::prelude::Device;
use clap::{Args, Subcommand, ValueEnum};

#[derive(Subcommand, Debug)]
pub enum ModelCmd {
    /// Parameter counts per submodule of the network in a config's `[model]` table.
    Summary(SummaryArgs),
}

#[derive(Args, Debug)]
pub struct SummaryArgs {
    /// A run config (e.g. configs/rf/paper.toml).
    #[arg(long)]
    pub config: PathBuf,
}

/// Network size benchmarked by `any4d bench model`.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum BenchSize {
    /// configs/rf/paper.toml sizes (W 512, 12 blocks, P 512, L 77); VAE d 128 on N 2048 vertices.
    Paper,
    /// MmditConfig::tiny() with P 64, L 8; FrameVaeConfig::tiny() on N 256.
    Tiny,
}

/// CPU backend of the benchmark.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum CpuBackend {
    Flex,
    Ndarray,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Network size.
    #[arg(long, value_enum, default_value = "paper")]
    pub size: BenchSize,
    /// Clips per step.
    #[arg(long, default_value_t = 1)]
    pub batch: usize,
    /// Timed steps (after one warm-up step).
    #[arg(long, default_value_t = 3)]
    pub iters: usize,
    /// CPU backend.
    #[arg(long, value_enum, default_value = "flex")]
    pub backend: CpuBackend,
    /// CPU threads for our timings (a rayon pool of this size: burn-flex's gemm and kernels and burn-ndarray
    /// run on the current rayon pool) and for the PyTorch reference (torch.set_num_threads). Default: all cores.
    #[arg(long)]
    pub threads: Option<usize>,
    /// AnimateAnyMesh checkout (holds networks/dymeshvae.py): also time its PyTorch networks on the same shapes
    /// and print a table with ratios. Without Python, torch or the folder, says why and reports ours only.
    #[arg(long, value_name = "DIR")]
    pub torch_reference: Option<PathBuf>,
    /// The PyTorch reference script.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/../scripts/bench_torch_reference.py"))]
    pub script: PathBuf,
    /// Python interpreter for the reference.
    #[arg(long, default_value = "python3")]
    pub python: PathBuf,
}

pub fn run(cmd: ModelCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        ModelCmd::Summary(args) => summary(&args.config),
    }
}

/// The network a config's `[model]` table describes, told apart by its keys: `kf_mode` → rectified-flow MMDiT,
/// `frames` → sequence-wise DyMeshVAE, otherwise the frame-wise VAE.
pub enum ModelConfig {
    Rf(MmditConfig),
    FrameVae(FrameVaeConfig),
    DyMeshVae(DyMeshVaeConfig),
}

/// Reads the `[model]` table of a config file; errors name the file and field.
pub fn load_model_config(path: &Path) -> anyhow::Result<ModelConfig> {
    let text = std::fs::read_to_string(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let table: toml::Table = toml::from_str(&text).with_context(|| format!("{}: invalid TOML", path.display()))?;
    let Some(model) = table.get("model") else {
        bail!("{}: no [model] table", path.display());
    };
    let Some(model_table) = model.as_table() else {
        bail!("{}: `model` must be a table", path.display());
    };
    let ctx = || format!("{}: [model]", path.display());
    if model_table.contains_key("kf_mode") {
        let cfg: MmditConfig = model.clone().try_into().with_context(ctx)?;
        cfg.validate()
            .map_err(|msg| anyhow::anyhow!("{}: {msg}", path.display()))?;
        Ok(ModelConfig::Rf(cfg))
    } else if model_table.contains_key("frames") {
        Ok(ModelConfig::DyMeshVae(model.clone().try_into().with_context(ctx)?))
    } else {
        Ok(ModelConfig::FrameVae(model.clone().try_into().with_context(ctx)?))
    }
}

fn summary(path: &Path) -> anyhow::Result<ExitCode> {
    let device = Device::flex();
    let (title, rows) = match load_model_config(path)? {
        ModelConfig::Rf(cfg) => (
            format!(
                "{}: rectified-flow MMDiT, kf_mode {:?}, {} input / {} output channels per token",
                path.display(),
                cfg.kf_mode,
                cfg.in_channels(),
                cfg.out_channels()
            ),
            param_report(&cfg.init(&device)),
        ),
        ModelConfig::FrameVae(cfg) => (
            format!("{}: frame-wise mesh VAE", path.display()),
            param_report(&cfg.init(&device)),
        ),
        ModelConfig::DyMeshVae(cfg) => (
            format!("{}: sequence-wise DyMeshVAE", path.display()),
            param_report(&cfg.init(&device)),
        ),
    };
    print!("{}", format_report(&title, &rows));
    Ok(ExitCode::SUCCESS)
}

/// Our side of the benchmark: timings and parameter counts of the three networks.
struct OurTimings {
    rf: StepTiming,
    rf_params: usize,
    vae: StepTiming,
    vae_params: usize,
    dymesh: StepTiming,
    dymesh_params: usize,
}

/// Sizes of one benchmark size: RF config, tokens P, text tokens L, vertices N, both VAE configs.
struct BenchSizes {
    rf: MmditConfig,
    tokens: usize,
    text_len: usize,
    vertices: usize,
    vae: FrameVaeConfig,
    dymesh: DyMeshVaeConfig,
}

impl BenchSize {
    /// Must match `SIZES` in scripts/bench_torch_reference.py.
    fn sizes(self) -> BenchSizes {
        match self {
            BenchSize::Paper => BenchSizes {
                rf: MmditConfig::paper(KfMode::InputMask, 768),
                tokens: 512,
                text_len: 77,
                vertices: 2048,
                vae: FrameVaeConfig::new(),
                dymesh: DyMeshVaeConfig::new(),
            },
            BenchSize::Tiny => BenchSizes {
                rf: MmditConfig::tiny(),
                tokens: 64,
                text_len: 8,
                vertices: 256,
                vae: FrameVaeConfig::tiny(),
                dymesh: DyMeshVaeConfig::tiny(),
            },
        }
    }

    fn name(self) -> &'static str {
        match self {
            BenchSize::Paper => "paper",
            BenchSize::Tiny => "tiny",
        }
    }
}

fn total_params(rows: &[(String, usize)]) -> usize {
    rows.iter().find(|(n, _)| n == TOTAL).map_or(0, |(_, n)| *n)
}

fn time_ours(args: &BenchArgs, sz: &BenchSizes, device: &Device) -> anyhow::Result<OurTimings> {
    let rf = time_rf_step(&sz.rf, args.batch, sz.tokens, sz.text_len, args.iters, device);
    let vae = time_vae_reconstruct(
        &sz.vae,
        args.batch,
        sz.vertices,
        sz.tokens,
        sz.rf.frames,
        args.iters,
        device,
    )
    .map_err(|msg| anyhow::anyhow!("bench model: {msg}"))?;
    let dymesh = time_dymesh_reconstruct(&sz.dymesh, args.batch, sz.vertices, sz.tokens, args.iters, device)
        .map_err(|msg| anyhow::anyhow!("bench model: {msg}"))?;
    Ok(OurTimings {
        rf,
        rf_params: total_params(&param_report(&sz.rf.init(device))),
        vae,
        vae_params: total_params(&param_report(&sz.vae.init(device))),
        dymesh,
        dymesh_params: total_params(&param_report(&sz.dymesh.init(device))),
    })
}

pub fn bench(args: BenchArgs) -> anyhow::Result<ExitCode> {
    if args.batch == 0 || args.iters == 0 {
        bail!("--batch and --iters must be positive");
    }
    let threads = match args.threads {
        Some(0) => bail!("--threads must be positive"),
        Some(n) => n,
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    let sz = args.size.sizes();
    // burn 0.22 deprecates ndarray; the design card keeps it as the second CPU backend.
    #[allow(deprecated)]
    let device = match args.backend {
        CpuBackend::Flex => Device::flex(),
        CpuBackend::Ndarray => Device::ndarray(),
    };
    if cfg!(debug_assertions) {
        println!(
            "note: debug build of our crates (dependencies are optimised); `cargo run --release -p any4d-train -- \
             bench model` gives representative numbers"
        );
    }
    // Our part runs inside a rayon pool of `threads` threads: burn-flex has no pool of its own (gemm's
    // Parallelism::Rayon(0) and its parallel iterators use the current pool), so this bounds it.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("bench model: cannot build the rayon pool")?;
    let ours = pool.install(|| time_ours(&args, &sz, &device))?;
    let per_clip = |t: &StepTiming| t.median_ms / args.batch as f64;
    println!(
        "bench model: RF forward+backward, {:?} size (W {}, {} blocks, P {}, L {}), {:?}, batch {}, {} iters, \
         {threads} threads: median {:.1} ms/step, {:.1} ms/clip",
        args.size,
        sz.rf.width,
        sz.rf.blocks,
        sz.tokens,
        sz.text_len,
        args.backend,
        args.batch,
        args.iters,
        ours.rf.median_ms,
        per_clip(&ours.rf)
    );
    println!(
        "bench model: frame-wise VAE encode+decode (posterior mean, no gradients), d {}, N {}, P {}, T {}, {:?}, \
         batch {}, {} iters, {threads} threads: median {:.1} ms/step, {:.1} ms/clip",
        sz.vae.width,
        sz.vertices,
        sz.tokens,
        sz.rf.frames,
        args.backend,
        args.batch,
        args.iters,
        ours.vae.median_ms,
        per_clip(&ours.vae)
    );
    println!(
        "bench model: sequence-wise DyMeshVAE encode+decode (posterior mean, no gradients), d {}, N {}, P {}, \
         T {}, {:?}, batch {}, {} iters, {threads} threads: median {:.1} ms/step, {:.1} ms/clip",
        sz.dymesh.width,
        sz.vertices,
        sz.tokens,
        sz.dymesh.frames,
        args.backend,
        args.batch,
        args.iters,
        ours.dymesh.median_ms,
        per_clip(&ours.dymesh)
    );
    let Some(dir) = &args.torch_reference else {
        return Ok(ExitCode::SUCCESS);
    };
    let torch = match run_torch_reference(&args, dir, threads)? {
        Ok(torch) => Some(torch),
        Err(why) => {
            println!("PyTorch reference skipped: {why}; reporting ours only");
            None
        }
    };
    if let Some(t) = &torch {
        println!(
            "PyTorch reference: torch {}, {} threads, AnimateAnyMesh at {}",
            t.torch,
            t.threads,
            dir.display()
        );
    }
    let rows = [
        (
            "RF forward+backward",
            &ours.rf,
            ours.rf_params,
            torch.as_ref().map(|t| &t.rf),
        ),
        (
            "frame-wise VAE encode+decode",
            &ours.vae,
            ours.vae_params,
            torch.as_ref().map(|t| &t.vae_framewise),
        ),
        (
            "sequence-wise DyMeshVAE enc+dec",
            &ours.dymesh,
            ours.dymesh_params,
            torch.as_ref().map(|t| &t.vae_sequencewise),
        ),
    ];
    println!(
        "{:<32} {:>13} {:>16} {:>13} {:>12} {:>15}",
        "network", "ours ms/clip", "PyTorch ms/clip", "ours/PyTorch", "params ours", "params PyTorch"
    );
    for (name, ours_t, ours_p, theirs) in rows {
        let ours_ms = per_clip(ours_t);
        match theirs {
            Some(th) => {
                let theirs_ms = th.median_ms / args.batch as f64;
                println!(
                    "{name:<32} {ours_ms:>13.1} {theirs_ms:>16.1} {:>13.2} {ours_p:>12} {:>15}",
                    ours_ms / theirs_ms,
                    th.params
                );
            }
            None => println!(
                "{name:<32} {ours_ms:>13.1} {:>16} {:>13} {ours_p:>12} {:>15}",
                "-", "-", "-"
            ),
        }
    }
    println!("(ours/PyTorch is a time ratio: below 1 means ours is faster)");
    Ok(ExitCode::SUCCESS)
}

/// One network's result in the PyTorch reference's JSON.
#[derive(serde::Deserialize)]
struct TorchNet {
    median_ms: f64,
    params: usize,
}

/// What `scripts/bench_torch_reference.py --json` prints.
#[derive(serde::Deserialize)]
struct TorchReference {
    torch: String,
    threads: usize,
    rf: TorchNet,
    vae_framewise: TorchNet,
    vae_sequencewise: TorchNet,
}

/// Runs the PyTorch reference. The outer error is a failure to report (a crash, unreadable output); the inner
/// `Err` says why the reference cannot run here (no Python, no torch, DIR is not an AnimateAnyMesh checkout).
fn run_torch_reference(args: &BenchArgs, dir: &Path, threads: usize) -> anyhow::Result<Result<TorchReference, String>> {
    if !dir.join("networks").join("dymeshvae.py").is_file() {
        return Ok(Err(format!(
            "--torch-reference {}: networks/dymeshvae.py not found (not an AnimateAnyMesh checkout)",
            dir.display()
        )));
    }
    if !args.script.is_file() {
        return Ok(Err(format!("--script {}: not found", args.script.display())));
    }
    let out = Command::new(&args.python)
        .arg(&args.script)
        .arg("--aam")
        .arg(dir)
        .args(["--size", args.size.name()])
        .args(["--batch", &args.batch.to_string()])
        .args(["--iters", &args.iters.to_string()])
        .args(["--threads", &threads.to_string()])
        .arg("--json")
        .output();
    let out = match out {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Ok(Err(format!("{} not found", args.python.display())));
        }
        other => other.with_context(|| format!("running {}", args.python.display()))?,
    };
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        // Exit 2: bad folder; 3: torch or einops missing (the script's own, one-line messages).
        if matches!(out.status.code(), Some(2 | 3)) {
            return Ok(Err(stderr.trim().to_string()));
        }
        bail!(
            "{} {} failed ({}): {stderr}",
            args.python.display(),
            args.script.display(),
            out.status
        );
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout
        .lines()
        .last()
        .with_context(|| format!("{} printed nothing", args.script.display()))?;
    let parsed: TorchReference =
        serde_json::from_str(line).with_context(|| format!("{}: unexpected output {line:?}", args.script.display()))?;
    Ok(Ok(parsed))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Arguments that run `sh SCRIPT` as the "Python" reference.
    fn args(script: &Path) -> BenchArgs {
        BenchArgs {
            size: BenchSize::Tiny,
            batch: 2,
            iters: 1,
            backend: CpuBackend::Flex,
            threads: Some(3),
            torch_reference: None,
            script: script.to_path_buf(),
            python: PathBuf::from("sh"),
        }
    }

    /// A folder that looks like an AnimateAnyMesh checkout, and a fake reference script with `body`.
    fn setup(body: &str) -> (tempfile::TempDir, PathBuf, PathBuf) {
        let tmp = tempfile::tempdir().expect("temp dir");
        let aam = tmp.path().join("aam");
        std::fs::create_dir_all(aam.join("networks")).expect("mkdir");
        std::fs::write(aam.join("networks/dymeshvae.py"), "").expect("write");
        let script = tmp.path().join("fake.sh");
        std::fs::write(&script, body).expect("write");
        (tmp, aam, script)
    }

    #[test]
    fn reference_json_is_parsed_and_gets_our_sizes_and_threads() {
        // Arguments: --aam DIR --size S --batch B --iters K --threads N --json; echo S, B and N back.
        let (_tmp, aam, script) = setup(
            r#"echo "{\"torch\": \"$4\", \"threads\": ${10}, \"rf\": {\"median_ms\": $6.5, \"params\": 7},
\"vae_framewise\": {\"median_ms\": 1.0, \"params\": 8}, \"vae_sequencewise\": {\"median_ms\": 2.0, \"params\": 9}}" | tr -d '\n'
echo"#,
        );
        let parsed = run_torch_reference(&args(&script), &aam, 3)
            .expect("runs")
            .expect("available");
        assert_eq!(parsed.torch, "tiny");
        assert_eq!(parsed.threads, 3);
        assert_eq!(parsed.rf.median_ms, 2.5);
        assert_eq!(
            (
                parsed.rf.params,
                parsed.vae_framewise.params,
                parsed.vae_sequencewise.params
            ),
            (7, 8, 9)
        );
    }

    #[test]
    fn missing_torch_is_a_reason_not_an_error() {
        let (_tmp, aam, script) = setup("echo 'bench_torch_reference: torch is not installed' >&2\nexit 3\n");
        let why = run_torch_reference(&args(&script), &aam, 1)
            .expect("runs")
            .err()
            .expect("unavailable");
        assert!(why.contains("torch is not installed"), "{why}");
    }

    #[test]
    fn missing_checkout_and_python_are_reasons() {
        let (tmp, _aam, script) = setup("exit 0\n");
        let why = run_torch_reference(&args(&script), tmp.path(), 1)
            .expect("runs")
            .err()
            .expect("unavailable");
        assert!(why.contains("not an AnimateAnyMesh checkout"), "{why}");
        let (_tmp, aam, script) = setup("exit 0\n");
        let mut a = args(&script);
        a.python = PathBuf::from("/nonexistent/python3");
        let why = run_torch_reference(&a, &aam, 1)
            .expect("runs")
            .err()
            .expect("unavailable");
        assert!(why.contains("/nonexistent/python3 not found"), "{why}");
    }

    #[test]
    fn a_crashing_reference_is_an_error_naming_its_output() {
        let (_tmp, aam, script) = setup("echo 'Traceback: boom' >&2\nexit 1\n");
        let err = run_torch_reference(&args(&script), &aam, 1)
            .err()
            .expect("a crash is an error");
        assert!(format!("{err:#}").contains("Traceback: boom"), "{err:#}");
        let (_tmp, aam, script) = setup("echo not-json\n");
        let err = run_torch_reference(&args(&script), &aam, 1)
            .err()
            .expect("bad output is an error");
        assert!(format!("{err:#}").contains("unexpected output"), "{err:#}");
    }

    #[test]
    fn bench_sizes_agree_with_the_reference_script() {
        // The script's SIZES table must describe the same networks as ours.
        let script = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../scripts/bench_torch_reference.py"
        ))
        .expect("script");
        for size in [BenchSize::Paper, BenchSize::Tiny] {
            let sz = size.sizes();
            let start = script.find(&format!("\"{}\": {{", size.name())).expect("size entry");
            let entry = &script[start..];
            let rf = format!(
                "\"rf\": {{\"width\": {}, \"blocks\": {}, \"heads\": {}, \"frames\": {}, \"channels\": {}, \
                 \"text_dim\": {}}}",
                sz.rf.width, sz.rf.blocks, sz.rf.heads, sz.rf.frames, sz.rf.channels, sz.rf.text_dim
            );
            let tokens = format!("\"tokens\": {},", sz.tokens);
            let text = format!("\"text_len\": {},", sz.text_len);
            let verts = format!("\"vertices\": {},", sz.vertices);
            let fw = format!(
                "\"vae_framewise\": {{\"dim\": {}, \"heads\": {}, \"dim_head\": {}, \"blocks\": {}, \"latent\": {}}}",
                sz.vae.width, sz.vae.heads, sz.vae.head_dim, sz.vae.enc_blocks, sz.vae.latent_channels
            );
            let sw = format!(
                "\"vae_sequencewise\": {{\"dim\": {}, \"heads\": {}, \"dim_head\": {}, \"blocks\": {}, \"latent\": {}}}",
                sz.dymesh.width, sz.dymesh.heads, sz.dymesh.head_dim, sz.dymesh.enc_blocks, sz.dymesh.latent_channels
            );
            let entry_end = entry.find("\n    },").expect("entry end");
            for needle in [rf, tokens, text, verts, fw, sw] {
                assert!(
                    entry[..entry_end].contains(&needle),
                    "{} size: script lacks {needle}",
                    size.name()
                );
            }
            assert_eq!(
                sz.rf.frames, sz.dymesh.frames,
                "both VAEs time clips of the RF's frame count"
            );
            assert_eq!(
                sz.vae.dec_blocks, sz.vae.enc_blocks,
                "the script uses one block count per VAE"
            );
            assert_eq!(sz.dymesh.dec_blocks, sz.dymesh.enc_blocks);
        }
    }
}

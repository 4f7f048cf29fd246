//! `any4d model …` and `any4d bench model`: parameter counts of the network a run config describes, and the
//! timings of `any4d_model::bench` (RF forward+backward, VAE encode+decode), optionally beside AnimateAnyMesh's
//! PyTorch networks run by `scripts/bench_torch_reference.py` on the same shapes and thread count.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use any4d_model::any_vae::AnyMeshVaeConfig;
use any4d_model::bench::{BenchSizes, ModelTimings, StepTiming, time_networks};
use any4d_model::interop::{Names, Network};
use any4d_model::summary::{format_report, param_report};
use any4d_train::backend::Backend;
use any4d_train::bdlstm_loop::BdlstmVariant;
use any4d_train::interop::{MODEL_SAFETENSORS, export_run, import_file, probe_run};
use any4d_train::pack::{Precision, pack_run};
use any4d_train::run_config::RunConfig;
use any4d_train::vae_loop::LATENT_STATS_FILE;
use anyhow::{Context, bail};
use burn::prelude::Device;
use clap::{Args, Subcommand, ValueEnum};

use super::train::ConfigArgs;
use crate::reference::{PythonReference, Skipped};

#[derive(Subcommand, Debug)]
pub enum ModelCmd {
    /// Parameter counts per submodule of the network in a run config's `[model]` table.
    Summary(SummaryArgs),
    /// Reduce a trained run folder to what sampling needs (config, the newest checkpoint's sampling parameters,
    /// side files; no optimiser state), optionally in half precision. The result loads with `--vae`, `--rf`,
    /// `--baseline-rf`, `--aam` and `--bdlstm` like the run, but cannot resume.
    Pack(PackArgs),
    /// Write a trained run's network as safetensors, under any4d's names or AnimateAnyMesh's PyTorch ones (the MMDiT
    /// of an RF run, the VAE of a VAE run), with what any4d needs to read it back beside it.
    Export(ExportArgs),
    /// Make a packed run folder from a safetensors file (an export, or one written by PyTorch, with `--config`) or a
    /// PyTorch checkpoint (`.pt`/`.pth`/`.ckpt`, read without running any of its code).
    Import(ImportArgs),
    /// Run a trained network (an RF's MMDiT or a VAE of either kind) on seeded random inputs and write inputs and
    /// outputs as safetensors, for the PyTorch parity check (`scripts/torch_parity.py probe`).
    Probe(ProbeArgs),
}

#[derive(Args, Debug)]
pub struct ProbeArgs {
    /// The run folder (RF or VAE; packed, imported or not).
    #[arg(long)]
    pub run: PathBuf,
    /// The safetensors file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Seed of the random inputs.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// Whose parameter names a safetensors file uses.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum NamesArg {
    /// any4d's module paths and burn's layouts.
    Any4d,
    /// AnimateAnyMesh's state_dict keys and PyTorch's layouts (loads with `load_state_dict(strict=True)`).
    Animateanymesh,
}

impl NamesArg {
    fn names(self) -> Names {
        match self {
            NamesArg::Any4d => Names::Any4d,
            NamesArg::Animateanymesh => Names::AnimateAnyMesh,
        }
    }
}

#[derive(Args, Debug)]
pub struct ExportArgs {
    /// The trained run folder (RF or VAE; packed or not).
    #[arg(long)]
    pub run: PathBuf,
    /// The new folder to write (must not exist).
    #[arg(long)]
    pub out: PathBuf,
    /// Whose names the file uses.
    #[arg(long, value_enum, default_value = "any4d")]
    pub names: NamesArg,
    /// File format (only safetensors).
    #[arg(long, default_value = "safetensors", value_parser = ["safetensors"])]
    pub format: String,
}

#[derive(Args, Debug)]
pub struct ImportArgs {
    /// The weight file: `model.safetensors` of an export folder, one saved from PyTorch, or a PyTorch checkpoint.
    #[arg(long)]
    pub from: PathBuf,
    /// The run config it was trained with (needed when the file does not carry any4d's header).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Whose names the file uses (default: what its header says).
    #[arg(long, value_enum)]
    pub names: Option<NamesArg>,
    /// The new run folder to write (must not exist).
    #[arg(long)]
    pub out: PathBuf,
}

#[derive(Args, Debug)]
pub struct PackArgs {
    /// The trained run folder (VAE, RF or BD-LSTM; a BD-LSTM run needs its recorded VAE run in place, which sizes
    /// its codec).
    #[arg(long)]
    pub run: PathBuf,
    /// The new folder to write (must not exist).
    #[arg(long)]
    pub out: PathBuf,
    /// Store the parameters in half precision (half the size; loading casts back to f32).
    #[arg(long)]
    pub half: bool,
    /// RF and BD-LSTM runs: the VAE folder to record in `vae_run.json` instead of the run's (relative paths are resolved
    /// against the packed folder, e.g. `../vae` for a VAE packed beside it).
    #[arg(long)]
    pub vae_at: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct SummaryArgs {
    /// A run config (e.g. configs/rf/paper.toml).
    #[arg(long)]
    pub config: PathBuf,
    #[command(flatten)]
    pub overrides: ConfigArgs,
}

/// Network size benchmarked by `any4d bench model`.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum BenchSize {
    /// configs/rf/paper.toml sizes (W 512, 12 blocks, P 512, L 77); VAE d 128 on N 2048 vertices.
    Paper,
    /// MmditConfig::tiny() with P 64, L 8; FrameVaeConfig::tiny() on N 256.
    Tiny,
}

impl BenchSize {
    fn sizes(self) -> BenchSizes {
        match self {
            BenchSize::Paper => BenchSizes::paper(),
            BenchSize::Tiny => BenchSizes::tiny(),
        }
    }

    /// The name `scripts/bench_torch_reference.py --size` takes.
    fn name(self) -> &'static str {
        match self {
            BenchSize::Paper => "paper",
            BenchSize::Tiny => "tiny",
        }
    }
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
    /// Backend (a GPU one needs a binary built with its cargo feature; `--threads` applies to CPU backends).
    #[arg(long, value_parser = super::enum_parser(&Backend::ALL), default_value = "flex")]
    pub backend: Backend,
    /// Float precision of our networks (f16, bf16: GPU backends only; the reference runs f32).
    #[arg(long, value_parser = super::enum_parser(&any4d_train::backend::Precision::ALL), default_value = "f32")]
    pub precision: any4d_train::backend::Precision,
    /// CPU threads for our timings (a rayon pool of this size: burn-flex's gemm and kernels and burn-ndarray
    /// run on the current rayon pool) and for the PyTorch reference (torch.set_num_threads). Default: all cores.
    #[arg(long)]
    pub threads: Option<usize>,
    /// AnimateAnyMesh checkout (holds networks/dymeshvae.py): also time its PyTorch networks on the same shapes
    /// and print a table with ratios. Without Python, torch or the folder, says why and reports ours only.
    #[arg(long, value_name = "DIR")]
    pub torch_reference: Option<PathBuf>,
    /// The PyTorch reference script.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/bench_torch_reference.py"))]
    pub script: PathBuf,
    /// Python interpreter for the reference.
    #[arg(long, default_value = "python3")]
    pub python: PathBuf,
}

pub fn exec(cmd: ModelCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        ModelCmd::Summary(args) => summary(&args.config, &args.overrides),
        ModelCmd::Pack(args) => pack(&args),
        ModelCmd::Export(args) => export(&args),
        ModelCmd::Import(args) => import(&args),
        ModelCmd::Probe(args) => {
            let network = probe_run(&args.run, &args.out, args.seed, &Device::flex())?;
            println!(
                "probed the {} of {} into {}",
                network.name(),
                args.run.display(),
                args.out.display()
            );
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// The VAE latent size a BD-LSTM summary assumes: the paper's frame-wise VAE (P = 512, C = 12).
const BDLSTM_SUMMARY_P: usize = 512;
const BDLSTM_SUMMARY_C: usize = 12;
/// The vertex count an ACAP BD-LSTM summary assumes.
const BDLSTM_SUMMARY_N: usize = 1024;

fn summary(path: &Path, overrides: &ConfigArgs) -> anyhow::Result<ExitCode> {
    let device = Device::flex();
    let (title, rows) = match RunConfig::load(path, &overrides.set)? {
        RunConfig::Rf(cfg) => (
            format!(
                "{}: rectified-flow MMDiT, conditioning {:?}, {} input / {} output channels per token",
                path.display(),
                cfg.model.conditioning,
                cfg.model.in_channels(),
                cfg.model.out_channels()
            ),
            param_report(&cfg.model.init(&device)),
        ),
        RunConfig::Bdlstm(cfg) if cfg.model.variant == BdlstmVariant::Acap => (
            format!(
                "{}: BD-LSTM (ACAP features, mesh convolutions), codec sized for N = {BDLSTM_SUMMARY_N} vertices \
                 (a run takes N from its store's topology)",
                path.display()
            ),
            param_report(&cfg.init_acap(BDLSTM_SUMMARY_N, &device)),
        ),
        RunConfig::Bdlstm(cfg) => (
            format!(
                "{}: BD-LSTM (latent adaptation), codec sized for P = {BDLSTM_SUMMARY_P} tokens of C = \
                 {BDLSTM_SUMMARY_C} channels (a run takes both from its VAE)",
                path.display()
            ),
            param_report(&cfg.init(BDLSTM_SUMMARY_P, BDLSTM_SUMMARY_C, &device)),
        ),
        RunConfig::Vae(cfg) => match &cfg.model {
            AnyMeshVaeConfig::Framewise(m) => (
                format!("{}: frame-wise mesh VAE", path.display()),
                param_report(&m.init(&device)),
            ),
            AnyMeshVaeConfig::Sequencewise(m) => (
                format!("{}: sequence-wise DyMeshVAE", path.display()),
                param_report(&m.init(&device)),
            ),
        },
    };
    print!("{}", format_report(&title, &rows));
    Ok(ExitCode::SUCCESS)
}

fn pack(args: &PackArgs) -> anyhow::Result<ExitCode> {
    let precision = if args.half { Precision::Half } else { Precision::Full };
    let packed = pack_run(&args.run, &args.out, precision, args.vae_at.as_deref(), &Device::flex())?;
    println!(
        "packed {} run {} step {} ({} parameters, {}) into {} ({:.1} MB)",
        packed.kind,
        args.run.display(),
        packed.step,
        if packed.averaged { "averaged" } else { "trained" },
        if args.half { "f16" } else { "f32" },
        args.out.display(),
        packed.model_bytes as f64 / 1e6
    );
    Ok(ExitCode::SUCCESS)
}

fn export(args: &ExportArgs) -> anyhow::Result<ExitCode> {
    let names = args.names.names();
    let e = export_run(&args.run, &args.out, names, &Device::flex())?;
    println!(
        "exported the {} of {} step {} ({}, {} tensors under {} names) to {}",
        e.network.name(),
        args.run.display(),
        e.step,
        if e.averaged {
            "its averaged parameters"
        } else {
            "the parameters it samples with"
        },
        e.tensors,
        names.name(),
        args.out.join(MODEL_SAFETENSORS).display()
    );
    Ok(ExitCode::SUCCESS)
}

fn import(args: &ImportArgs) -> anyhow::Result<ExitCode> {
    let names = args.names.map(NamesArg::names);
    let i = import_file(&args.from, &args.out, args.config.as_deref(), names, &Device::flex())?;
    let ignored = match i.ignored {
        0 => String::new(),
        n => format!("; {n} AnimateAnyMesh keys with no any4d counterpart ignored"),
    };
    println!(
        "imported a {} ({} names, step {}) into the packed run {}{ignored}; side files: {}",
        i.network.name(),
        i.names.name(),
        i.step,
        args.out.display(),
        if i.side_files.is_empty() {
            "none".to_owned()
        } else {
            i.side_files.join(", ")
        }
    );
    if i.network != Network::Mmdit && !i.side_files.contains(&LATENT_STATS_FILE) {
        println!(
            "note: no latent statistics (`{LATENT_STATS_FILE}`, written by a finished any4d VAE run): the run samples \
             and evaluates reconstructions, but an RF cannot be trained on its latents until they exist"
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// `any4d bench model`: [`time_networks`] in a pool of `--threads`, then the PyTorch reference when asked.
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
    let device = any4d_train::backend::device(args.backend, args.precision)?;
    if cfg!(debug_assertions) {
        println!(
            "note: debug build of our crates (dependencies are optimised); `cargo run --release -- bench model` \
             gives representative numbers"
        );
    }
    // Our part runs inside a rayon pool of `threads` threads: burn-flex has no pool of its own (gemm's
    // Parallelism::Rayon(0) and its parallel iterators use the current pool), so this bounds it.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("bench model: cannot build the rayon pool")?;
    let ours = pool
        .install(|| time_networks(&sz, args.batch, args.iters, &device))
        .map_err(|msg| anyhow::anyhow!("bench model: {msg}"))?;
    print_ours(&args, &sz, &ours, threads);
    let Some(dir) = &args.torch_reference else {
        return Ok(ExitCode::SUCCESS);
    };
    let torch = match run_torch_reference(&args, dir, threads)? {
        Ok(torch) => Some(torch),
        Err(Skipped(why)) => {
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
    let per_clip = |t: &StepTiming| t.median_ms / args.batch as f64;
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

/// One line per network of our timings.
fn print_ours(args: &BenchArgs, sz: &BenchSizes, ours: &ModelTimings, threads: usize) {
    let per_clip = |t: &StepTiming| t.median_ms / args.batch as f64;
    let common = format!(
        "{:?} {}, batch {}, {} iters, {threads} threads",
        args.backend, args.precision, args.batch, args.iters
    );
    println!(
        "bench model: RF forward+backward, {:?} size (W {}, {} blocks, P {}, L {}), {common}: median {:.1} ms/step, \
         {:.1} ms/clip",
        args.size,
        sz.rf.width,
        sz.rf.blocks,
        sz.tokens,
        sz.text_len,
        ours.rf.median_ms,
        per_clip(&ours.rf)
    );
    println!(
        "bench model: frame-wise VAE encode+decode (posterior mean, no gradients), d {}, N {}, P {}, T {}, {common}: \
         median {:.1} ms/step, {:.1} ms/clip",
        sz.vae.body.width,
        sz.vertices,
        sz.tokens,
        sz.rf.frames,
        ours.vae.median_ms,
        per_clip(&ours.vae)
    );
    println!(
        "bench model: sequence-wise DyMeshVAE encode+decode (posterior mean, no gradients), d {}, N {}, P {}, T {}, \
         {common}: median {:.1} ms/step, {:.1} ms/clip",
        sz.dymesh.body.width,
        sz.vertices,
        sz.tokens,
        sz.dymesh.frames,
        ours.dymesh.median_ms,
        per_clip(&ours.dymesh)
    );
}

/// One network's result in the PyTorch reference's JSON.
#[derive(Debug, serde::Deserialize)]
struct TorchNet {
    median_ms: f64,
    params: usize,
}

/// What `scripts/bench_torch_reference.py --json` prints.
#[derive(Debug, serde::Deserialize)]
struct TorchReference {
    torch: String,
    threads: usize,
    rf: TorchNet,
    vae_framewise: TorchNet,
    vae_sequencewise: TorchNet,
}

/// Runs the PyTorch reference on `dir`, an AnimateAnyMesh checkout (`Err(Skipped)` when it is not one, or when
/// Python or torch is missing).
fn run_torch_reference(
    args: &BenchArgs,
    dir: &Path,
    threads: usize,
) -> anyhow::Result<Result<TorchReference, Skipped>> {
    if !dir.join("networks").join("dymeshvae.py").is_file() {
        return Ok(Err(Skipped(format!(
            "--torch-reference {}: networks/dymeshvae.py not found (not an AnimateAnyMesh checkout)",
            dir.display()
        ))));
    }
    PythonReference {
        python: &args.python,
        script: &args.script,
        args: vec![
            "--aam".into(),
            dir.display().to_string(),
            "--size".into(),
            args.size.name().into(),
            "--batch".into(),
            args.batch.to_string(),
            "--iters".into(),
            args.iters.to_string(),
            "--threads".into(),
            threads.to_string(),
            "--json".into(),
        ],
        threads,
    }
    .json()
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
            backend: Backend::Flex,
            precision: any4d_train::backend::Precision::F32,
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
    fn a_folder_that_is_not_a_checkout_is_a_reason() {
        let (tmp, _aam, script) = setup("exit 0\n");
        let why = run_torch_reference(&args(&script), tmp.path(), 1)
            .expect("runs")
            .expect_err("unavailable");
        assert!(why.0.contains("not an AnimateAnyMesh checkout"), "{why:?}");
    }
}

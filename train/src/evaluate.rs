//! Learned methods of the evaluation protocol built from trained run folders: the one place that turns
//! `runs/…` (train) into `eval::methods::Method`s and `eval::tables::reconstruction::Reconstructor`s (eval cannot read run folders).
//! Used by `any4d eval run` and `any4d quickstart`.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use any4d_data::batch::PadTo;
use any4d_eval::acap_bdlstm::{AcapBdlstmSampler, AcapSpace};
use any4d_eval::learned::{
    BdlstmSampler, KeyPosterior, LatentLerpSampler, LearnedModels, MeshCodec, RfSampler, VaeOracleSampler,
    VaeReconstructor,
};
use any4d_eval::methods::vertex_methods;
use any4d_eval::methods::{AAM_GUIDANCE, CorrectedBase, KeyframeCorrected, Method, MethodKind, RfMethod, SampleMean};
use any4d_eval::tables::reconstruction::Reconstructor;
use any4d_model::any_vae::VaeKind;
use any4d_model::rectified_flow::{ReplaceNoise, SampleOptions, Solver};
use any4d_model::text::scratch::ScratchTextEncoder;
use burn::prelude::{Device, Module};

use crate::bdlstm_acap::load_acap_bdlstm_run;
use crate::bdlstm_loop::load_bdlstm_run;
use crate::error::{Result, TrainError};
use crate::runs::{LoadedVae, load_rf_run, load_vae_run};

/// Trained runs that the learned methods come from.
#[derive(Debug, Clone, Default)]
pub struct LearnedRuns {
    /// Keyframe-conditioned RF run (`ours`; also serves impute-until-τ* as the inference-only variant).
    pub rf: Option<PathBuf>,
    /// Non-keyframe RF run (`conditioning = "none"`), sampled with replacement (the paper's Baseline).
    pub baseline_rf: Option<PathBuf>,
    /// VAE run for latent lerp and table 5 (defaults to the RF run's VAE).
    pub vae: Option<PathBuf>,
    /// Second VAE run for table 5 (e.g. the sequence-wise ablation).
    pub vae_b: Option<PathBuf>,
    /// BD-LSTM run (`any4d train bdlstm`), completed on its own VAE.
    pub bdlstm: Option<PathBuf>,
    /// BD-LSTM run of the ACAP variant (`any4d train bdlstm --variant acap`), on its store's one topology.
    pub bdlstm_acap: Option<PathBuf>,
    /// AnimateAnyMesh reference: an RF run on a sequence-wise VAE (`configs/rf/aam_*.toml`), sampled with CFG
    /// [`AAM_GUIDANCE`] whatever [`SamplingSetup::guidance`] says.
    pub aam: Option<PathBuf>,
}

/// How the RF methods sample.
#[derive(Debug, Clone, Copy)]
pub struct SamplingSetup {
    /// Grid points over [0, 1] (64 in the paper).
    pub n_grid: usize,
    /// Solver (midpoint in the paper).
    pub solver: Solver,
    /// Classifier-free guidance weight (1.0 in the paper).
    pub guidance: f64,
    /// Noise that re-noises the Baseline's keyframes (docs/method.md §8 X9; fixed in the paper).
    pub replace_noise: ReplaceNoise,
    /// Keyframe latents: the posterior mean (the paper) or a seeded posterior sample.
    pub posterior: KeyPosterior,
    /// Scale of the sampler's initial noise (docs/method.md §8 X14; 1 in the paper).
    pub noise_scale: f64,
}

impl Default for SamplingSetup {
    fn default() -> Self {
        Self {
            n_grid: 64,
            solver: Solver::Midpoint,
            guidance: 1.0,
            replace_noise: ReplaceNoise::Fixed,
            posterior: KeyPosterior::Mean,
            noise_scale: 1.0,
        }
    }
}

/// Methods in the order of `kinds`, each with a label → checkpoint line for the table header.
pub struct BuiltMethods {
    pub methods: Vec<Box<dyn Method>>,
    pub checkpoints: Vec<(String, String)>,
}

fn need<'a>(path: &'a Option<PathBuf>, flag: &str, kind: MethodKind) -> Result<&'a Path> {
    path.as_deref().ok_or_else(|| {
        TrainError::Setup(format!(
            "method `{}` needs a trained run: pass {flag} RUN",
            kind.label()
        ))
    })
}

fn codec_of(vae: &LoadedVae, posterior: KeyPosterior, device: &Device) -> Result<Arc<MeshCodec>> {
    let model = vae.model.clone().valid();
    Ok(Arc::new(
        MeshCodec::new(model, vae.tokens(), PadTo::BatchMax, device.clone())?.with_posterior(posterior),
    ))
}

/// `run (step N)`, the run relative to the working directory when it lies inside it: a summary committed from the
/// repository root then names `weights/small/rf`, not a path only this machine has.
fn checkpoint_label(run: &Path, step: u64) -> String {
    let here = std::env::current_dir().ok().and_then(|d| d.canonicalize().ok());
    let shown = here.as_deref().and_then(|d| run.strip_prefix(d).ok()).unwrap_or(run);
    format!("{} (step {step})", shown.display())
}

/// A learned method built from one RF run, with what a caller needs to feed it.
pub struct RunMethod {
    /// The method.
    pub method: Box<dyn Method>,
    /// `run (step N)`, for table headers and provenance.
    pub checkpoint: String,
    /// Frames T of one generated window.
    pub window: usize,
    /// FPS tokens P its VAE encodes.
    pub tokens: usize,
    /// Whether its network reads the scene a window moves in (docs/method.md §4.12).
    pub reads_scene: bool,
}

/// The keyframe RF of `run_dir` as a method (`any4d complete` / `extend`), with the keyframe correction (L2) when
/// `correct` (docs/method.md §5.6).
pub fn keyframe_method(run_dir: &Path, sampling: SamplingSetup, correct: bool, device: &Device) -> Result<RunMethod> {
    let m = rf_method(MethodKind::KeyframeRf, run_dir, sampling, device)?;
    if !correct {
        return Ok(m);
    }
    let kind = MethodKind::Corrected {
        base: CorrectedBase::KeyframeRf,
    };
    Ok(RunMethod {
        method: Box::new(KeyframeCorrected::new(kind, m.method)?),
        ..m
    })
}

/// The RF sampler of one RF run (its own VAE and statistics, its scratch text encoder) for `kind`.
fn rf_method(kind: MethodKind, run_dir: &Path, sampling: SamplingSetup, device: &Device) -> Result<RunMethod> {
    let rf = load_rf_run(run_dir, device)?;
    let vae = rf.load_vae(device)?;
    let codec = codec_of(&vae, sampling.posterior, device)?;
    let label = checkpoint_label(&rf.run, rf.step);
    let rf_config = rf.config.model.clone();
    let reads_scene = rf_config.scene.any();
    // A generated window: the RF's frames, or the clip length of the sequence-wise VAE (one trajectory slot).
    let window = codec.vae().clip_frames().unwrap_or(rf_config.frames);
    let tokens = codec.tokens();
    let text = ScratchTextEncoder {
        tokenizer: rf.tokenizer,
        model: rf.model.text.valid(),
    };
    let models = LearnedModels::new(codec, rf.model.mmdit.valid(), rf_config, vae.stats, Box::new(text))?;
    let mut base = SampleOptions::paper(rf.config.model.conditioning);
    base.n_grid = sampling.n_grid;
    base.solver = sampling.solver;
    base.replace_noise = sampling.replace_noise;
    base.noise_scale = sampling.noise_scale;
    let guidance = if kind == MethodKind::Aam {
        AAM_GUIDANCE
    } else {
        sampling.guidance
    };
    let sampler = RfSampler::for_method(kind, Arc::new(models), base, guidance)?;
    let method = RfMethod::new(kind, sampler)?;
    Ok(RunMethod {
        method: Box::new(method),
        checkpoint: label,
        window,
        tokens,
        reads_scene,
    })
}

/// The VAE run for latent lerp / table 5: `--vae`, else the VAE of the keyframe RF run.
fn vae_run_for(runs: &LearnedRuns, device: &Device) -> Result<LoadedVae> {
    if let Some(v) = &runs.vae {
        return load_vae_run(v, device);
    }
    if let Some(rf) = &runs.rf {
        return load_rf_run(rf, device)?.load_vae(device);
    }
    Err(TrainError::Setup(
        "methods `lerp_latent` and `vae_oracle` need a VAE: pass --vae RUN (or --rf RUN to use its VAE)".into(),
    ))
}

/// Builds `kinds` in order; learned methods encode with their VAE run's P (`vae.tokens`).
pub fn build_methods(
    kinds: &[MethodKind],
    runs: &LearnedRuns,
    sampling: SamplingSetup,
    device: &Device,
) -> Result<BuiltMethods> {
    let mut methods = Vec::new();
    let mut checkpoints = Vec::new();
    for &kind in kinds {
        let (method, ckpt) = match kind {
            MethodKind::Lerp | MethodKind::StaticNearest => {
                let mut m = vertex_methods(&[kind])?;
                (m.remove(0), "none".to_string())
            }
            MethodKind::KeyframeRf | MethodKind::ImputeUntil { .. } => {
                let m = rf_method(kind, need(&runs.rf, "--rf", kind)?, sampling, device)?;
                (m.method, m.checkpoint)
            }
            MethodKind::KeyframeRfMean { .. } => {
                let m = rf_method(MethodKind::KeyframeRf, need(&runs.rf, "--rf", kind)?, sampling, device)?;
                (
                    Box::new(SampleMean::new(kind, m.method)?) as Box<dyn Method>,
                    m.checkpoint,
                )
            }
            MethodKind::ReplacementRf => {
                let m = rf_method(kind, need(&runs.baseline_rf, "--baseline-rf", kind)?, sampling, device)?;
                (m.method, m.checkpoint)
            }
            MethodKind::Aam => {
                let m = rf_method(kind, need(&runs.aam, "--aam", kind)?, sampling, device)?;
                (m.method, m.checkpoint)
            }
            MethodKind::Bdlstm => {
                let run = load_bdlstm_run(need(&runs.bdlstm, "--bdlstm", kind)?, device)?;
                let codec = codec_of(&run.vae, sampling.posterior, device)?;
                let merge = run.config.merge_config();
                let sampler = BdlstmSampler::new(codec, run.model.valid(), run.vae.stats, merge)?;
                (
                    Box::new(RfMethod::new(kind, sampler)?) as Box<dyn Method>,
                    checkpoint_label(&run.run, run.step),
                )
            }
            MethodKind::BdlstmAcap => {
                let run = load_acap_bdlstm_run(need(&runs.bdlstm_acap, "--bdlstm-acap", kind)?, device)?;
                let space = AcapSpace {
                    topology: run.record.topology_of_run(&run.run)?,
                    reference: run.record.reference_clip.clone(),
                    faces: run.record.faces.clone(),
                    scaling: run.record.scaling.clone(),
                };
                let merge = run.config.merge_config();
                let sampler = AcapBdlstmSampler::new(run.model.valid(), space, merge, device)?;
                (
                    Box::new(RfMethod::new(kind, sampler)?) as Box<dyn Method>,
                    checkpoint_label(&run.run, run.step),
                )
            }
            MethodKind::LerpLatent => {
                let vae = vae_run_for(runs, device)?;
                let sampler = LatentLerpSampler::new(codec_of(&vae, sampling.posterior, device)?)?;
                let method = RfMethod::new(kind, sampler)?;
                (
                    Box::new(method) as Box<dyn Method>,
                    checkpoint_label(&vae.run, vae.step),
                )
            }
            MethodKind::Corrected { base } => {
                let mut inner = build_methods(&[base.kind()], runs, sampling, device)?;
                let method = KeyframeCorrected::new(kind, inner.methods.remove(0))?;
                (Box::new(method) as Box<dyn Method>, inner.checkpoints.remove(0).1)
            }
            MethodKind::VaeOracle => {
                let vae = vae_run_for(runs, device)?;
                let sampler = VaeOracleSampler::new(codec_of(&vae, KeyPosterior::Mean, device)?);
                let method = RfMethod::new(kind, sampler)?;
                (
                    Box::new(method) as Box<dyn Method>,
                    checkpoint_label(&vae.run, vae.step),
                )
            }
        };
        methods.push(method);
        checkpoints.push((kind.label(), ckpt));
    }
    Ok(BuiltMethods { methods, checkpoints })
}

/// Reconstructors in order, with label → checkpoint lines for the table header.
pub type BuiltReconstructors = (Vec<Box<dyn Reconstructor>>, Vec<(String, String)>);

/// Table 5 rows: `--vae` (and `--vae-b`) as reconstructors labelled by their VAE kind (`--vae-b`'s with `_b`
/// added when both are of one kind, so that their rows stay apart), decoding the `posterior` latent.
pub fn build_reconstructors(
    runs: &LearnedRuns,
    posterior: KeyPosterior,
    device: &Device,
) -> Result<BuiltReconstructors> {
    let mut out: Vec<Box<dyn Reconstructor>> = Vec::new();
    let mut ckpts = Vec::new();
    for run in [&runs.vae, &runs.vae_b].into_iter().flatten() {
        let vae = load_vae_run(run, device)?;
        let kind = match vae.model.kind() {
            VaeKind::Framewise => "framewise",
            VaeKind::Sequencewise => "sequencewise",
        };
        let label = if ckpts.iter().any(|(l, _): &(String, String)| l == kind) {
            format!("{kind}_b")
        } else {
            kind.to_string()
        };
        ckpts.push((label.clone(), checkpoint_label(&vae.run, vae.step)));
        out.push(Box::new(VaeReconstructor::new(
            label,
            codec_of(&vae, posterior, device)?,
        )));
    }
    if out.is_empty() {
        return Err(TrainError::Setup(
            "table5 needs --vae RUN (and optionally --vae-b RUN)".into(),
        ));
    }
    Ok((out, ckpts))
}

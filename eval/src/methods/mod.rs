//! Completion methods on one protocol (docs/method.md §5, §6.1): every method fills the non-keyframes of a normalised
//! clip through the same [`Method::complete`] call, so all are scored identically on the same manifest.
//!
//! Methods: keyframe-conditioned RF (ours, (R3)–(R6)), non-keyframe RF with sampling-time replacement (the
//! paper's Baseline, (R7)–(R8)), SceneMI-style impute-until-τ* with clean or noisy keyframes ((R9), §5.4), linear
//! interpolation in vertex and latent space ((L1), §5.2), the static nearest keyframe, the BD-LSTM baseline (§5.3,
//! latent adaptation) and the AnimateAnyMesh reference (§5.5: an RF on the sequence-wise VAE, no keyframes).

use any4d_data::Clip;
use any4d_data::rng::{GOLDEN_GAMMA, Rng, rng, splitmix64};
use any4d_data::scene::Scene;

use crate::baselines::VertexBaseline;
use crate::metrics::{ClipMetrics, Motion, evaluate_clip, replace_keyframes};

use crate::error::{EvalError, Result};

mod corrected;
mod kind;

pub use corrected::KeyframeCorrected;
pub use kind::{AAM_GUIDANCE, CorrectedBase, KeyframeNoise, MethodKind};

/// Standard deviation of the SceneMI keyframe noise at level l = 1, normalised units (docs/method.md §5.4: std l ·
/// 0.02).
pub const KEYFRAME_NOISE_STD: f32 = 0.02;
/// RNG stream of the keyframe noise, distinct from the sampler's streams.
const KEYFRAME_NOISE_STREAM: u64 = 0x6e6f_6973;

/// A way to fill the non-keyframes of a window.
pub trait Method {
    /// What the method is.
    fn kind(&self) -> MethodKind;

    /// Predict every frame of `clip` from its keyframes. `clip` is in the normalised frame of its frame 0
    /// (docs/method.md §1.5); only the frames listed in `keyframes` may be read (callers pass [`hide_non_keyframes`]
    /// output; the `vae_oracle` floor row alone is given the whole window).
    /// `seed` fixes the sampler noise.
    ///
    /// # Shapes
    /// `clip.vertices`: `[T, N]` rows of xyz; returns `[T, N]` rows.
    fn complete(&self, clip: &Clip, keyframes: &[usize], caption: &str, seed: u64) -> Result<Vec<[f32; 3]>>;

    /// Several completions of one window that share a caption, in request order (e.g. every keyframe set and seed
    /// of one clip of a protocol). The default runs [`Method::complete`] once per request; learned methods batch
    /// them into one network call per ODE evaluation, with the same results.
    fn complete_batch(&self, requests: &[Request<'_>], caption: &str) -> Result<Vec<Vec<[f32; 3]>>> {
        requests
            .iter()
            .map(|r| self.complete(r.clip, r.keyframes, caption, r.seed))
            .collect()
    }
}

/// One completion asked of a [`Method`] or [`WindowSampler`]: the visible window (see [`hide_non_keyframes`]), its
/// keyframes and the sampler seed.
#[derive(Debug, Clone, Copy)]
pub struct Request<'a> {
    /// The normalised window; only frame 0 and the keyframes may be read.
    pub clip: &'a Clip,
    /// Keyframe indices.
    pub keyframes: &'a [usize],
    /// Sampler seed.
    pub seed: u64,
    /// The static scene the window moves in, normalised with it; read by scene-aware networks only
    /// (docs/method.md §4.12).
    pub scene: Option<&'a Scene>,
}

impl<'a> Request<'a> {
    /// One window without a scene (what [`Method::complete`] asks).
    pub fn new(clip: &'a Clip, keyframes: &'a [usize], seed: u64) -> Self {
        Self {
            clip,
            keyframes,
            seed,
            scene: None,
        }
    }
}

/// The training-free vertex-space methods: (L1) and the static nearest keyframe.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VertexMethod(pub VertexBaseline);

impl Method for VertexMethod {
    fn kind(&self) -> MethodKind {
        match self.0 {
            VertexBaseline::Linear => MethodKind::Lerp,
            VertexBaseline::NearestKeyframe => MethodKind::StaticNearest,
        }
    }

    fn complete(&self, clip: &Clip, keyframes: &[usize], _caption: &str, _seed: u64) -> Result<Vec<[f32; 3]>> {
        let gt = Motion::from_clip(clip).map_err(|e| EvalError::invalid(&clip.id, "vertices", e.to_string()))?;
        self.0
            .complete(gt, keyframes)
            .map_err(|e| EvalError::invalid(&clip.id, self.kind().label(), e.to_string()))
    }
}

/// The training-free methods by kind; RF kinds are an error here (the caller builds them from checkpoints).
pub fn vertex_methods(kinds: &[MethodKind]) -> Result<Vec<Box<dyn Method>>> {
    kinds
        .iter()
        .map(|k| match k {
            MethodKind::Lerp => Ok(Box::new(VertexMethod(VertexBaseline::Linear)) as Box<dyn Method>),
            MethodKind::StaticNearest => Ok(Box::new(VertexMethod(VertexBaseline::NearestKeyframe)) as Box<dyn Method>),
            other => Err(EvalError::invalid(
                "methods",
                other.label(),
                "needs trained checkpoints (--rf / --baseline-rf / --vae)",
            )),
        })
        .collect()
}

/// A trained generator of whole windows: encode the keyframes, sample, decode (docs/method.md §4.6, §5.1, §5.4). The
/// model crate's samplers are wrapped in this by the caller that loads the checkpoints.
pub trait WindowSampler {
    /// Predict every frame of a normalised window from its keyframes.
    ///
    /// # Shapes
    /// `clip.vertices`: `[T, N]` rows; returns `[T, N]` rows.
    fn sample(&self, clip: &Clip, keyframes: &[usize], caption: &str, seed: u64) -> Result<Vec<[f32; 3]>>;

    /// Several windows sharing a caption, in request order; the default samples them one by one.
    fn sample_batch(&self, requests: &[Request<'_>], caption: &str) -> Result<Vec<Vec<[f32; 3]>>> {
        requests
            .iter()
            .map(|r| self.sample(r.clip, r.keyframes, caption, r.seed))
            .collect()
    }
}

/// An RF method (ours, the replacement baseline or impute-until-τ*) around its sampler: it adds SceneMI keyframe
/// noise first when its kind asks for it and returns the decoded sample as it is, keyframe frames included. The
/// evaluation assembly of docs/method.md §4.6 ("keyframe frames are replaced by ground-truth meshes") is the scorer's job
/// ([`evaluate_clip`]), after it has measured the keyframe error (E7) on the raw output.
pub struct RfMethod<S> {
    kind: MethodKind,
    sampler: S,
}

impl<S: WindowSampler> RfMethod<S> {
    /// Errors for kinds that are not RF methods.
    pub fn new(kind: MethodKind, sampler: S) -> Result<Self> {
        match kind {
            MethodKind::KeyframeRf
            | MethodKind::ReplacementRf
            | MethodKind::ImputeUntil { .. }
            | MethodKind::LerpLatent
            | MethodKind::VaeOracle
            | MethodKind::Bdlstm
            | MethodKind::BdlstmAcap
            | MethodKind::Aam => Ok(Self { kind, sampler }),
            other => Err(EvalError::invalid(
                "method",
                other.label(),
                "is not a model-based method",
            )),
        }
    }
}

impl<S: WindowSampler> Method for RfMethod<S> {
    fn kind(&self) -> MethodKind {
        self.kind
    }

    fn complete(&self, clip: &Clip, keyframes: &[usize], caption: &str, seed: u64) -> Result<Vec<[f32; 3]>> {
        let mut out = self.complete_batch(&[Request::new(clip, keyframes, seed)], caption)?;
        Ok(out.remove(0))
    }

    fn complete_batch(&self, requests: &[Request<'_>], caption: &str) -> Result<Vec<Vec<[f32; 3]>>> {
        let given: Vec<Clip> = requests
            .iter()
            .map(|r| match self.kind {
                MethodKind::ImputeUntil {
                    keyframes: KeyframeNoise::Noisy { level },
                    ..
                } => noisy_keyframes(r.clip, r.keyframes, level, r.seed),
                _ => r.clip.clone(),
            })
            .collect();
        let asked: Vec<Request<'_>> = requests
            .iter()
            .zip(&given)
            .map(|(r, clip)| Request { clip, ..*r })
            .collect();
        let outs = self.sampler.sample_batch(&asked, caption)?;
        if outs.len() != requests.len() {
            return Err(EvalError::invalid(
                self.kind.label(),
                "samples",
                format!(
                    "sampler returned {} windows for {} requests",
                    outs.len(),
                    requests.len()
                ),
            ));
        }
        outs.into_iter()
            .zip(&asked)
            .map(|(out, r)| {
                let (clip, n) = (r.clip, r.clip.n_vertices);
                if out.len() != clip.frames * n {
                    return Err(EvalError::invalid(
                        &clip.id,
                        self.kind.label(),
                        format!(
                            "sampler returned {} rows, expected {} frames × {n}",
                            out.len(),
                            clip.frames
                        ),
                    ));
                }
                Ok(out)
            })
            .collect()
    }
}

/// Most samples a `keyframe_rf_mean<N>` row averages (each one is a full completion).
pub const MAX_MEAN_SAMPLES: u16 = 64;

/// Seed of sample `k` of a [`SampleMean`] for a request of seed `seed`: sample 0 is `seed` itself.
pub fn mean_sample_seed(seed: u64, k: usize) -> u64 {
    if k == 0 {
        seed
    } else {
        splitmix64(seed ^ (k as u64).wrapping_mul(GOLDEN_GAMMA))
    }
}

/// The per-vertex mean of several completions of a stochastic method ([`MethodKind::KeyframeRfMean`]): every
/// request is expanded into `samples` requests with [`mean_sample_seed`] seeds, completed in one batch, and averaged.
pub struct SampleMean {
    kind: MethodKind,
    inner: Box<dyn Method>,
    samples: usize,
}

impl SampleMean {
    /// `kind` must be a mean kind; `inner` completes single samples.
    pub fn new(kind: MethodKind, inner: Box<dyn Method>) -> Result<Self> {
        match kind {
            MethodKind::KeyframeRfMean { samples } => Ok(Self {
                kind,
                inner,
                samples: usize::from(samples),
            }),
            other => Err(EvalError::invalid("methods", other.label(), "not a mean of samples")),
        }
    }
}

impl Method for SampleMean {
    fn kind(&self) -> MethodKind {
        self.kind
    }

    fn complete(&self, clip: &Clip, keyframes: &[usize], caption: &str, seed: u64) -> Result<Vec<[f32; 3]>> {
        let mut out = self.complete_batch(&[Request::new(clip, keyframes, seed)], caption)?;
        Ok(out.remove(0))
    }

    fn complete_batch(&self, requests: &[Request<'_>], caption: &str) -> Result<Vec<Vec<[f32; 3]>>> {
        let k = self.samples;
        let expanded: Vec<Request<'_>> = requests
            .iter()
            .flat_map(|r| {
                (0..k).map(move |i| Request {
                    seed: mean_sample_seed(r.seed, i),
                    ..*r
                })
            })
            .collect();
        let outs = self.inner.complete_batch(&expanded, caption)?;
        Ok(outs
            .chunks(k)
            .map(|group| {
                let mut mean = vec![[0.0f32; 3]; group[0].len()];
                for sample in group {
                    for (m, v) in mean.iter_mut().zip(sample) {
                        for c in 0..3 {
                            m[c] += v[c] / k as f32;
                        }
                    }
                }
                mean
            })
            .collect())
    }
}

/// A copy of `clip` in which every non-keyframe is replaced by frame 0 (the reference mesh), so a method cannot
/// read ground truth it is not given. Frame 0 is always known: it is the reference mesh (docs/method.md §1.2).
pub fn hide_non_keyframes(clip: &Clip, keyframes: &[usize]) -> Clip {
    let mut out = clip.clone();
    let reference = clip.frame(0).to_vec();
    for f in (1..clip.frames).filter(|f| !keyframes.contains(f)) {
        out.frame_mut(f).copy_from_slice(&reference);
    }
    out
}

/// What a method is shown of the window: [`hide_non_keyframes`], except for the `vae_oracle` row, whose point is to
/// read every ground-truth frame (it is the floor of the latent methods, not a completion method).
fn visible_window(kind: MethodKind, gt: &Clip, keyframes: &[usize]) -> Clip {
    match kind {
        MethodKind::VaeOracle => gt.clone(),
        _ => hide_non_keyframes(gt, keyframes),
    }
}

/// SceneMI keyframe noise (docs/method.md §5.4): each interior keyframe's vertices + i.i.d. N(0, (level · 0.02)²),
/// drawn from
/// `rng(seed, KEYFRAME_NOISE_STREAM)`; frames 0 and T − 1 stay clean. Box–Muller from uniform draws.
pub fn noisy_keyframes(clip: &Clip, keyframes: &[usize], level: f32, seed: u64) -> Clip {
    let mut out = clip.clone();
    let std = level * KEYFRAME_NOISE_STD;
    let mut r = rng(seed, KEYFRAME_NOISE_STREAM);
    let last = clip.frames - 1;
    for &f in keyframes.iter().filter(|&&f| f != 0 && f != last && f < clip.frames) {
        for p in out.frame_mut(f) {
            for c in p.iter_mut() {
                let (u1, u2): (f64, f64) = (r.random::<f64>().max(f64::MIN_POSITIVE), r.random::<f64>());
                let g = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
                *c += std * g as f32;
            }
        }
    }
    out
}

/// One scored generation: the method's prediction and its metrics (docs/method.md §6.1 assembly and (E1)–(E7)).
#[derive(Debug, Clone, PartialEq)]
pub struct Scored {
    /// The completed window `[T, N]` rows: the method's output with the keyframe frames replaced by the ground truth
    /// (docs/method.md §4.6 assembly; (E7) was measured on the output before that).
    pub prediction: Vec<[f32; 3]>,
    pub metrics: ClipMetrics,
}

/// Run `method` on `gt` (normalised) with `keyframes` and score it against `gt`: the method sees only the
/// keyframes (the `vae_oracle` row the whole window), its output is checked for shape and finiteness, then scored by [`evaluate_clip`].
///
/// # Shapes
/// `gt.vertices`: `[T, N]` rows; `Scored::prediction` the same.
pub fn complete_and_score(
    method: &dyn Method,
    gt: &Clip,
    keyframes: &[usize],
    caption: &str,
    seed: u64,
) -> Result<Scored> {
    let visible = visible_window(method.kind(), gt, keyframes);
    let prediction = method.complete(&visible, keyframes, caption, seed)?;
    score(method.kind(), gt, keyframes, prediction)
}

/// [`complete_and_score`] for several (keyframes, seed) pairs of one clip in one [`Method::complete_batch`] call,
/// in the order of `asks`, telling the method the clip's scene when it has one.
pub fn complete_and_score_batch(
    method: &dyn Method,
    gt: &Clip,
    asks: &[(&[usize], u64)],
    caption: &str,
    scene: Option<&Scene>,
) -> Result<Vec<Scored>> {
    let visible: Vec<Clip> = asks.iter().map(|(k, _)| visible_window(method.kind(), gt, k)).collect();
    let requests: Vec<Request<'_>> = asks
        .iter()
        .zip(&visible)
        .map(|(&(keyframes, seed), clip)| Request {
            clip,
            keyframes,
            seed,
            scene,
        })
        .collect();
    let predictions = method.complete_batch(&requests, caption)?;
    if predictions.len() != asks.len() {
        return Err(EvalError::invalid(
            &gt.id,
            method.kind().label(),
            format!("{} predictions for {} requests", predictions.len(), asks.len()),
        ));
    }
    predictions
        .into_iter()
        .zip(asks)
        .map(|(p, (k, _))| score(method.kind(), gt, k, p))
        .collect()
}

/// Checks a prediction's shape and finiteness and scores it against `gt` by [`evaluate_clip`].
fn score(kind: MethodKind, gt: &Clip, keyframes: &[usize], prediction: Vec<[f32; 3]>) -> Result<Scored> {
    let label = kind.label();
    let pred = Motion::new(&prediction, gt.frames, gt.n_vertices)
        .map_err(|e| EvalError::invalid(&gt.id, &label, format!("prediction: {e}")))?;
    let truth = Motion::from_clip(gt).map_err(|e| EvalError::invalid(&gt.id, "vertices", e.to_string()))?;
    let err = |e: crate::metrics::EvalError| EvalError::invalid(&gt.id, &label, e.to_string());
    let metrics = evaluate_clip(pred, truth, keyframes).map_err(err)?;
    let prediction = replace_keyframes(pred, truth, keyframes).map_err(err)?;
    Ok(Scored { prediction, metrics })
}

/// The metrics of one clip as (name, value) pairs, the values of a table's clip record.
pub fn metrics_map(m: &ClipMetrics) -> std::collections::BTreeMap<String, f64> {
    let fields = [
        ("rmse", m.rmse),
        ("mae_elem", m.mae_elem),
        ("chamfer", m.chamfer),
        ("dtw", m.dtw),
        ("jerk", m.jerk),
        ("jerk_gt", m.jerk_gt),
        ("jerk_ratio", m.jerk_ratio),
        ("accel", m.accel),
        ("accel_gt", m.accel_gt),
        ("accel_ratio", m.accel_ratio),
        ("energy", m.energy),
        ("energy_gt", m.energy_gt),
        ("energy_ratio", m.energy_ratio),
        ("keyframe_rmse", m.keyframe_rmse),
        ("mean_vertex_error", m.mean_vertex_error),
    ];
    fields.into_iter().map(|(k, v)| (k.to_string(), v)).collect()
}

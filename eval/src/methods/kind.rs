//! The methods of the evaluation protocol by name: what a config, a manifest or the CLI selects, and the labels of
//! table rows and file names.

use std::fmt;

use serde::{Deserialize, Serialize};

use super::MAX_MEAN_SAMPLES;

use crate::error::{EvalError, Result};

/// Which keyframes a method is given (docs/method.md §5.4: evaluate with clean keyframes and noisy ones at l = 1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum KeyframeNoise {
    /// The ground-truth keyframe meshes.
    Clean,
    /// Keyframe vertices + i.i.d. N(0, (level · 0.02)²); the first and last frames stay clean.
    Noisy { level: f32 },
}

/// The methods of the evaluation protocol, by name (what a config or the CLI selects).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum MethodKind {
    /// Keyframe-conditioned RF, 221 input channels, (R3)–(R6) (ours).
    KeyframeRf,
    /// Non-keyframe RF with sampling-time replacement (R7)–(R8) (the paper's "Baseline").
    ReplacementRf,
    /// SceneMI-style imputation until τ* (R9) with clean or noisy keyframes.
    ImputeUntil { tau_star: f32, keyframes: KeyframeNoise },
    /// (L1) in normalised vertex space.
    Lerp,
    /// (L1) between keyframe latents, then decoded (`lerp_space = "latent"`).
    LerpLatent,
    /// Not a completion method: every ground-truth frame encoded (posterior mean) and decoded by the VAE. It sees
    /// the frames the others must generate, so its row is the floor of every latent method on that VAE under the
    /// same scoring: how much of their error and jerk the VAE alone accounts for.
    VaeOracle,
    /// Hold the nearest keyframe (ties to the earlier one).
    StaticNearest,
    /// The BD-LSTM baseline, latent adaptation (docs/method.md §5.3): both chains per keyframe segment and the
    /// merge rule.
    Bdlstm,
    /// The BD-LSTM baseline as published (docs/method.md §5.3, ACAP variant): chains on per-vertex ACAP features of
    /// one fixed topology, positions by sparse least squares.
    BdlstmAcap,
    /// The per-vertex mean of `samples` completions by ours (`keyframe_rf`), sample 0 being the single
    /// completion of the same seed: an estimate of the model's conditional mean, which separates the error of
    /// the learned distribution's centre from the spread of its samples (not a method of the paper).
    KeyframeRfMean { samples: u16 },
    /// The AnimateAnyMesh reference (docs/method.md §5.5): an RF on the sequence-wise VAE's latents, conditioned on
    /// the reference mesh (frame 0) and the caption only, sampled with CFG [`AAM_GUIDANCE`]; keyframes enter only
    /// through the ground-truth replacement every row shares.
    Aam,
    /// A latent method whose decoded output is corrected by the keyframes' decoding residuals (docs/method.md §5.6,
    /// (L2)): what the VAE gets wrong on the known frames of this mesh is subtracted from every frame. Not a method
    /// of the paper.
    Corrected { base: CorrectedBase },
}

/// The latent methods that [`MethodKind::Corrected`] can wrap: those whose keyframe frames are decoded from
/// latents, so the decoding residual there is known. (L2) is affine in the completion, so the corrected mean of
/// samples is the mean of the corrected samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CorrectedBase {
    KeyframeRf,
    KeyframeRfMean { samples: u16 },
    ReplacementRf,
    LerpLatent,
    Bdlstm,
}

impl CorrectedBase {
    /// The method whose output is corrected.
    pub fn kind(self) -> MethodKind {
        match self {
            Self::KeyframeRf => MethodKind::KeyframeRf,
            Self::KeyframeRfMean { samples } => MethodKind::KeyframeRfMean { samples },
            Self::ReplacementRf => MethodKind::ReplacementRf,
            Self::LerpLatent => MethodKind::LerpLatent,
            Self::Bdlstm => MethodKind::Bdlstm,
        }
    }

    /// The base of a method that can be corrected, `None` for the others.
    pub fn of(kind: MethodKind) -> Option<Self> {
        Some(match kind {
            MethodKind::KeyframeRf => Self::KeyframeRf,
            MethodKind::KeyframeRfMean { samples } => Self::KeyframeRfMean { samples },
            MethodKind::ReplacementRf => Self::ReplacementRf,
            MethodKind::LerpLatent => Self::LerpLatent,
            MethodKind::Bdlstm => Self::Bdlstm,
            _ => return None,
        })
    }
}

/// Label suffix of [`MethodKind::Corrected`]: `keyframe_rf_corrected`, `lerp_latent_corrected`, …
const CORRECTED_SUFFIX: &str = "_corrected";

/// Classifier-free guidance weight of the AnimateAnyMesh reference's sampler (its code's default, docs/method.md
/// §5.5); ours and the Baseline sample with the paper's 1.0.
pub const AAM_GUIDANCE: f64 = 3.0;

impl MethodKind {
    /// Label used in tables, file names and manifests: `keyframe_rf`, `replacement_rf`, `impute_until_0.98_noisy1`, …
    pub fn label(&self) -> String {
        match self {
            MethodKind::KeyframeRf => "keyframe_rf".into(),
            MethodKind::ReplacementRf => "replacement_rf".into(),
            MethodKind::ImputeUntil {
                tau_star,
                keyframes: KeyframeNoise::Clean,
            } => format!("impute_until_{tau_star}"),
            MethodKind::ImputeUntil {
                tau_star,
                keyframes: KeyframeNoise::Noisy { level },
            } => {
                format!("impute_until_{tau_star}_noisy{level}")
            }
            MethodKind::Lerp => "lerp".into(),
            MethodKind::LerpLatent => "lerp_latent".into(),
            MethodKind::VaeOracle => "vae_oracle".into(),
            MethodKind::StaticNearest => "static_nearest".into(),
            MethodKind::Bdlstm => "bdlstm".into(),
            MethodKind::BdlstmAcap => "bdlstm_acap".into(),
            MethodKind::KeyframeRfMean { samples } => format!("keyframe_rf_mean{samples}"),
            MethodKind::Aam => "aam".into(),
            MethodKind::Corrected { base } => format!("{}{CORRECTED_SUFFIX}", base.kind().label()),
        }
    }

    /// Parse a label written by [`MethodKind::label`] (plus `impute_until` = τ* 0.98, clean).
    pub fn parse(s: &str) -> Result<Self> {
        let bad = |reason: String| EvalError::invalid("method", s, reason);
        Ok(match s {
            "keyframe_rf" | "ours" => MethodKind::KeyframeRf,
            "replacement_rf" | "baseline" => MethodKind::ReplacementRf,
            "lerp" => MethodKind::Lerp,
            "lerp_latent" => MethodKind::LerpLatent,
            "vae_oracle" => MethodKind::VaeOracle,
            "static_nearest" => MethodKind::StaticNearest,
            "bdlstm" => MethodKind::Bdlstm,
            "bdlstm_acap" => MethodKind::BdlstmAcap,
            "aam" => MethodKind::Aam,
            other if other.ends_with(CORRECTED_SUFFIX) => {
                let inner = &other[..other.len() - CORRECTED_SUFFIX.len()];
                let kind = Self::parse(inner)?;
                let base = CorrectedBase::of(kind).ok_or_else(|| {
                    bad(format!(
                        "`{inner}` cannot be corrected by its keyframes: {CORRECTED_SUFFIX} follows keyframe_rf, \
                         keyframe_rf_mean<N>, replacement_rf, lerp_latent or bdlstm"
                    ))
                })?;
                MethodKind::Corrected { base }
            }
            "impute_until" => MethodKind::ImputeUntil {
                tau_star: 0.98,
                keyframes: KeyframeNoise::Clean,
            },
            other if other.starts_with("keyframe_rf_mean") => {
                let n = &other["keyframe_rf_mean".len()..];
                let samples: u16 = n
                    .parse()
                    .map_err(|e| bad(format!("samples {n:?} of keyframe_rf_mean<N>: {e}")))?;
                if !(2..=MAX_MEAN_SAMPLES).contains(&samples) {
                    return Err(bad(format!(
                        "keyframe_rf_mean<N> averages 2..={MAX_MEAN_SAMPLES} samples, got {samples}"
                    )));
                }
                MethodKind::KeyframeRfMean { samples }
            }
            other => {
                let rest = other.strip_prefix("impute_until_").ok_or_else(|| {
                    bad(
                        "unknown method; expected keyframe_rf, keyframe_rf_mean<N>, replacement_rf, lerp, lerp_latent, \
                         vae_oracle, static_nearest, bdlstm, bdlstm_acap, aam or impute_until[_<tau*>[_noisy<level>]], \
                         or a latent method followed by _corrected"
                            .into(),
                    )
                })?;
                let (tau, noise) = match rest.split_once("_noisy") {
                    Some((t, l)) => (t, Some(l)),
                    None => (rest, None),
                };
                let tau_star: f32 = tau.parse().map_err(|e| bad(format!("τ* {tau:?}: {e}")))?;
                if !(0.0..=1.0).contains(&tau_star) {
                    return Err(bad(format!("τ* = {tau_star} is outside [0, 1]")));
                }
                let keyframes = match noise {
                    None => KeyframeNoise::Clean,
                    Some(l) => KeyframeNoise::Noisy {
                        level: l.parse().map_err(|e| bad(format!("noise level {l:?}: {e}")))?,
                    },
                };
                MethodKind::ImputeUntil { tau_star, keyframes }
            }
        })
    }

    /// Whether the method needs a trained network (RF and/or VAE) rather than keyframes alone.
    pub fn needs_model(&self) -> bool {
        !matches!(self, MethodKind::Lerp | MethodKind::StaticNearest)
    }
}

impl fmt::Display for MethodKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.label())
    }
}

//! A latent method with its decoding corrected by the keyframes (docs/method.md §5.6, (L2)): the method completes
//! the window, then every frame moves by the interpolated residual between the given keyframes and their decoding.

use any4d_data::Clip;

use super::{Method, MethodKind, Request};
use crate::baselines::correct_by_keyframes;
use crate::metrics::Motion;

use crate::error::{EvalError, Result};

/// [`MethodKind::Corrected`]: `inner` completes, (L2) corrects. The keyframes read are those of the window the
/// method is shown, so noisy or hidden frames never enter.
pub struct KeyframeCorrected {
    kind: MethodKind,
    inner: Box<dyn Method>,
}

impl KeyframeCorrected {
    /// `inner` must be the method `kind` corrects.
    pub fn new(kind: MethodKind, inner: Box<dyn Method>) -> Result<Self> {
        match kind {
            MethodKind::Corrected { base } if base.kind() == inner.kind() => Ok(Self { kind, inner }),
            MethodKind::Corrected { base } => Err(EvalError::invalid(
                "methods",
                kind.label(),
                format!("corrects {}, was given {}", base.kind().label(), inner.kind().label()),
            )),
            other => Err(EvalError::invalid(
                "methods",
                other.label(),
                "is not a corrected method",
            )),
        }
    }
}

impl Method for KeyframeCorrected {
    fn kind(&self) -> MethodKind {
        self.kind
    }

    fn complete(&self, clip: &Clip, keyframes: &[usize], caption: &str, seed: u64) -> Result<Vec<[f32; 3]>> {
        let mut out = self.complete_batch(&[Request::new(clip, keyframes, seed)], caption)?;
        Ok(out.remove(0))
    }

    fn complete_batch(&self, requests: &[Request<'_>], caption: &str) -> Result<Vec<Vec<[f32; 3]>>> {
        let outs = self.inner.complete_batch(requests, caption)?;
        if outs.len() != requests.len() {
            return Err(EvalError::invalid(
                self.kind.label(),
                "samples",
                format!("{} completions for {} requests", outs.len(), requests.len()),
            ));
        }
        outs.into_iter()
            .zip(requests)
            .map(|(mut out, r)| {
                let given =
                    Motion::from_clip(r.clip).map_err(|e| EvalError::invalid(&r.clip.id, "vertices", e.to_string()))?;
                correct_by_keyframes(&mut out, given, r.keyframes)
                    .map_err(|e| EvalError::invalid(&r.clip.id, self.kind.label(), e.to_string()))?;
                Ok(out)
            })
            .collect()
    }
}

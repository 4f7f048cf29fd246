//! The BD-LSTM baseline in its latent adaptation (docs/method.md §5.3).

use std::sync::Arc;

use any4d_data::Clip;
use any4d_data::rng::{GOLDEN_GAMMA, splitmix64};
use any4d_model::bdlstm::{
    BdLstm, LatentCodec, MergeConfig, SegmentError, SegmentTry, bbox_diagonal, frame_distance, merge_segment,
};
use any4d_model::latent_stats::LatentStats;
use any4d_model::mesh_vae::Posterior;
use burn::prelude::*;

use crate::methods::WindowSampler;

use crate::error::{EvalError, Result};

use super::*;

/// The BD-LSTM baseline, latent adaptation (docs/method.md §5.3): between each pair of consecutive keyframes a < b
/// the forward chain runs from z_a and the backward chain from z_b (standardised latents, posterior means), both
/// are decoded, and the merge rule switches from the forward to the backward chain at the aligned pair that agrees
/// best, retrying with perturbed initial states (device RNG seeded from the sampler seed and a) until that pair is
/// within the threshold. Frames 0 and T − 1 must be keyframes.
pub struct BdlstmSampler {
    codec: Arc<MeshCodec>,
    model: BdLstm<LatentCodec>,
    stats: LatentStats,
    merge: MergeConfig,
}

/// An error inside one segment's merge of a BD-LSTM row: the rule's own or the decoder's / reconstruction's.
pub(crate) enum SegmentFailure {
    Rule(SegmentError),
    Data(EvalError),
}

impl From<SegmentError> for SegmentFailure {
    fn from(e: SegmentError) -> Self {
        Self::Rule(e)
    }
}

impl BdlstmSampler {
    /// Needs the frame-wise VAE the BD-LSTM was trained on (its statistics standardise the latents). Give the network
    /// without autodiff, on the codec's device.
    pub fn new(
        codec: Arc<MeshCodec>,
        model: BdLstm<LatentCodec>,
        stats: LatentStats,
        merge: MergeConfig,
    ) -> Result<Self> {
        codec.require_frame_wise("BD-LSTM")?;
        Ok(Self {
            codec,
            model,
            stats,
            merge,
        })
    }

    /// Fills one segment a..=b (n = b − a + 1 ≥ 3 frames) from its standardised end latents `[1, P, C]`; returns
    /// the n latents in time order.
    fn segment(
        &self,
        enc: &WindowEncoding,
        clip: &Clip,
        (a, b): (usize, usize),
        (za, zb): (Tensor<3>, Tensor<3>),
        seed: u64,
    ) -> Result<Vec<Tensor<3>>> {
        let n = b - a + 1;
        let device = self.codec.device();
        device.seed(splitmix64(seed ^ (a as u64).wrapping_mul(GOLDEN_GAMMA)));
        let nv = clip.n_vertices;
        let diag = bbox_diagonal(&clip.vertices[a * nv..(a + 1) * nv]);
        let id = clip.id.as_str();
        let frames_of = |chain: Tensor<4>| -> Vec<Tensor<3>> {
            let [_, len, p, c] = chain.dims();
            (0..len)
                .map(|i| chain.clone().narrow(1, i, 1).reshape([1, p, c]))
                .collect()
        };
        let merged = merge_segment(&self.merge, |attempt| -> std::result::Result<_, SegmentFailure> {
            let init = self.model.retry_states(attempt, 1, device);
            let forward = self
                .model
                .chain(za.clone(), n - 1, init.forward, &(), Posterior::Mean)
                .frames;
            let backward = self
                .model
                .chain(zb.clone(), n - 1, init.backward, &(), Posterior::Mean)
                .frames
                .flip([1]);
            let decode = |z: Tensor<4>| {
                self.codec
                    .decode(enc, self.stats.destandardize_motion(z))
                    .map_err(SegmentFailure::Data)
            };
            let (vf, vb) = (decode(forward.clone())?, decode(backward.clone())?);
            let distances = (0..n)
                .map(|i| frame_distance(&vf[i * nv..(i + 1) * nv], &vb[i * nv..(i + 1) * nv], diag))
                .collect::<std::result::Result<Vec<f64>, SegmentError>>()?;
            Ok(SegmentTry::new(frames_of(forward), frames_of(backward), distances)?)
        })
        .map_err(|e| match e {
            SegmentFailure::Rule(e) => EvalError::invalid(id, "bdlstm", e.to_string()),
            SegmentFailure::Data(e) => e,
        })?;
        Ok(merged.frames)
    }
}

impl WindowSampler for BdlstmSampler {
    fn sample(&self, clip: &Clip, keyframes: &[usize], _caption: &str, seed: u64) -> Result<Vec<[f32; 3]>> {
        let keys = end_keyframes(clip, keyframes)?;
        let t = clip.frames;
        let enc = self.codec.encode(clip, &encoded_frames(&keys))?;
        let (z, _) = scatter_keyframes(&enc, &keys, self.codec.device())?;
        let z = self.stats.standardize_motion(z);
        let [_, _, p, c] = z.dims();
        let frame = |f: usize| z.clone().narrow(1, f, 1).reshape([1, p, c]);
        let mut out: Vec<Option<Tensor<3>>> = vec![None; t];
        for pair in keys.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let filled = if b - a + 1 >= 3 {
                self.segment(&enc, clip, (a, b), (frame(a), frame(b)), seed)?
            } else {
                vec![frame(a), frame(b)]
            };
            for (i, zf) in filled.into_iter().enumerate() {
                out[a + i] = Some(zf);
            }
        }
        let frames: Vec<Tensor<3>> = out
            .into_iter()
            .map(|f| f.expect("consecutive keyframe segments cover 0..T"))
            .collect();
        let z = self
            .stats
            .destandardize_motion(Tensor::stack::<4>(frames, 1).reshape([1, t, p, c]));
        self.codec.decode(&enc, z)
    }
}

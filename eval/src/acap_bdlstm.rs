//! The faithful BD-LSTM row (docs/method.md §5.3, "ACAP variant"): chains run on scaled per-vertex ACAP features of
//! one fixed topology, and every generated frame is turned back into vertex positions by the sparse least-squares
//! reconstruction. Only the keyframes are read.

use any4d_data::Clip;
use any4d_data::acap::{ACAP_CHANNELS, AcapFrame, AcapScaling, AcapTopology, Reconstruction, check_topology};
use any4d_data::rng::{GOLDEN_GAMMA, splitmix64};
use any4d_model::bdlstm::{
    BdLstm, MergeConfig, MeshConvCodec, MeshGraph, SegmentError, SegmentTry, bbox_diagonal, frame_distance,
    merge_segment,
};
use any4d_model::mesh_vae::Posterior;
use burn::prelude::*;
use burn::tensor::TensorData;

use crate::error::{EvalError, Result};
use crate::learned::{SegmentFailure, end_keyframes};
use crate::methods::WindowSampler;

type Frame = Vec<[f32; 3]>;

/// What the ACAP row needs besides the network: the reference mesh's topology (features and reconstruction), the
/// name of the reference clip and its triangles (to refuse other topologies), and the feature scaling.
pub struct AcapSpace {
    /// Built from the run's reference mesh.
    pub topology: AcapTopology,
    /// The reference clip's id (named in errors).
    pub reference: String,
    /// The fixed topology's triangles.
    pub faces: Vec<[u32; 3]>,
    /// The run's fitted scaling.
    pub scaling: AcapScaling,
}

/// BD-LSTM on ACAP features: between each pair of consecutive keyframes a < b the forward chain runs from the
/// features of frame a and the backward chain from those of frame b; each chain frame is unscaled, reconstructed
/// (centred), and moved so that its centroid lies on the line between the two keyframes' centroids (features do
/// not see translations, docs/method.md §5.3); the merge rule then switches from the forward to the backward
/// chain as in the latent variant. Frames 0 and T − 1 must be keyframes; keyframes are returned as given.
pub struct AcapBdlstmSampler {
    model: BdLstm<MeshConvCodec>,
    graph: MeshGraph,
    space: AcapSpace,
    merge: MergeConfig,
    device: Device,
}

impl AcapBdlstmSampler {
    /// Give the network without autodiff, on `device`.
    ///
    /// # Errors
    /// The topology's graph does not fit the network's vertex count.
    pub fn new(model: BdLstm<MeshConvCodec>, space: AcapSpace, merge: MergeConfig, device: &Device) -> Result<Self> {
        let n = space.topology.vertices();
        let graph = MeshGraph::new(&space.topology.edges(), n, device)
            .map_err(|e| EvalError::invalid(&space.reference, "faces", format!("mesh graph: {e}")))?;
        Ok(Self {
            model,
            graph,
            space,
            merge,
            device: device.clone(),
        })
    }

    /// Vertex positions of every frame of a chain `[1, len, N, 9]` (scaled features), the i-th centred on
    /// `centroid(i)`.
    fn positions(&self, chain: Tensor<4>, centroid: impl Fn(usize) -> [f32; 3]) -> Result<Vec<Frame>> {
        let [_, len, n, c] = chain.dims();
        let flat = chain
            .try_to_vec_as::<f32>()
            .map_err(|e| EvalError::invalid(&self.space.reference, "acap", format!("cannot read the tensor: {e:?}")))?;
        (0..len)
            .map(|i| {
                let scaled: AcapFrame = flat[i * n * c..(i + 1) * n * c]
                    .chunks_exact(ACAP_CHANNELS)
                    .map(|v| std::array::from_fn(|k| v[k]))
                    .collect();
                let features = self.space.scaling.unscale(&scaled)?;
                let mut p = self
                    .space
                    .topology
                    .reconstruct(&features, Reconstruction::RingMoments)?;
                let (have, want) = (mean(&p), centroid(i));
                for v in &mut p {
                    for k in 0..3 {
                        v[k] += want[k] - have[k];
                    }
                }
                Ok(p)
            })
            .collect()
    }

    /// Fills one segment a..=b (≥ 3 frames) between the scaled features `xa`, `xb` (`[1, N, 9]`) of its ends and
    /// returns its frames in time order.
    fn segment(
        &self,
        clip: &Clip,
        (a, b): (usize, usize),
        (xa, xb): (Tensor<3>, Tensor<3>),
        seed: u64,
    ) -> Result<Vec<Frame>> {
        let len = b - a + 1;
        let nv = clip.n_vertices;
        let frame = |f: usize| &clip.vertices[f * nv..(f + 1) * nv];
        let (ca, cb) = (mean(frame(a)), mean(frame(b)));
        let centroid = |i: usize| {
            let w = i as f32 / (len - 1) as f32;
            std::array::from_fn(|k| ca[k] + w * (cb[k] - ca[k]))
        };
        let diag = bbox_diagonal(frame(a));
        self.device
            .seed(splitmix64(seed ^ (a as u64).wrapping_mul(GOLDEN_GAMMA)));
        let merged = merge_segment(&self.merge, |attempt| -> std::result::Result<_, SegmentFailure> {
            let init = self.model.retry_states(attempt, 1, &self.device);
            let forward = self
                .model
                .chain(xa.clone(), len - 1, init.forward, &self.graph, Posterior::Mean)
                .frames;
            let backward = self
                .model
                .chain(xb.clone(), len - 1, init.backward, &self.graph, Posterior::Mean)
                .frames
                .flip([1]);
            let vf = self.positions(forward, centroid).map_err(SegmentFailure::Data)?;
            let vb = self.positions(backward, centroid).map_err(SegmentFailure::Data)?;
            let distances = vf
                .iter()
                .zip(&vb)
                .map(|(f, b)| frame_distance(f, b, diag))
                .collect::<std::result::Result<Vec<f64>, SegmentError>>()?;
            Ok(SegmentTry::new(vf, vb, distances)?)
        })
        .map_err(|e| match e {
            SegmentFailure::Rule(e) => EvalError::invalid(&clip.id, "bdlstm_acap", e.to_string()),
            SegmentFailure::Data(e) => e,
        })?;
        Ok(merged.frames)
    }
}

fn mean(frame: &[[f32; 3]]) -> [f32; 3] {
    let n = frame.len().max(1) as f64;
    std::array::from_fn(|k| (frame.iter().map(|p| f64::from(p[k])).sum::<f64>() / n) as f32)
}

impl WindowSampler for AcapBdlstmSampler {
    fn sample(&self, clip: &Clip, keyframes: &[usize], _caption: &str, seed: u64) -> Result<Vec<[f32; 3]>> {
        let keys = end_keyframes(clip, keyframes)?;
        let s = &self.space;
        check_topology(&s.reference, s.topology.vertices(), &s.faces, clip)?;
        let nv = clip.n_vertices;
        let frame = |f: usize| &clip.vertices[f * nv..(f + 1) * nv];
        let key_frames: Vec<&[[f32; 3]]> = keys.iter().map(|&k| frame(k)).collect();
        let features = s.topology.features(&key_frames)?;
        let scaled = features
            .iter()
            .map(|f| {
                let x = s.scaling.scale(f)?;
                let flat: Vec<f32> = x.into_iter().flatten().collect();
                Ok(Tensor::<3>::from_data(
                    TensorData::new(flat, [1, nv, ACAP_CHANNELS]),
                    &self.device,
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        let mut out = vec![[0.0f32; 3]; clip.frames * nv];
        for &k in &keys {
            out[k * nv..(k + 1) * nv].copy_from_slice(frame(k));
        }
        for (i, pair) in keys.windows(2).enumerate() {
            let (a, b) = (pair[0], pair[1]);
            if b - a + 1 < 3 {
                continue;
            }
            let filled = self.segment(clip, (a, b), (scaled[i].clone(), scaled[i + 1].clone()), seed)?;
            // Interior frames only: the keyframes stay exactly as given.
            for (f, p) in filled.into_iter().enumerate().take(b - a).skip(1) {
                out[(a + f) * nv..(a + f + 1) * nv].copy_from_slice(&p);
            }
        }
        Ok(out)
    }
}

//! Frozen-VAE latents of the clips (docs/method.md §3.4, §4.1): encoded once into host memory or per micro-batch.

use any4d_data::store::Store;
use any4d_model::frame_vae::FrameVae;
use burn::prelude::{Device, Tensor};

use any4d_model::mesh_vae::MeshVae;

use crate::error::{Result, TrainError};
use crate::vae_loop::{load_clips, vae_batch};

/// Frozen-VAE encoding of one clip, kept in host memory in the VAE's layout.
#[derive(Clone, Debug)]
pub struct ClipLatents {
    /// Index of the clip in the store.
    pub store_index: usize,
    /// Its caption.
    pub caption: String,
    /// Shape latent z₀, `[P, C]` row-major.
    pub z0: Vec<f32>,
    /// Posterior mean μ_f of every frame, `[T, P, C]` row-major.
    pub mu: Vec<f32>,
    /// Posterior log σ²_f, `[T, P, C]` row-major.
    pub logvar: Vec<f32>,
}

/// The latents of one split and their sizes.
#[derive(Clone, Debug)]
pub struct LatentSet {
    /// One entry per clip, in store order.
    pub clips: Vec<ClipLatents>,
    /// T.
    pub frames: usize,
    /// P.
    pub tokens: usize,
    /// C.
    pub channels: usize,
}

impl LatentSet {
    /// Host bytes held.
    pub fn bytes(&self) -> usize {
        self.clips.len() * self.tokens * self.channels * (1 + 2 * self.frames) * std::mem::size_of::<f32>()
    }
}

fn host_f32<const D: usize>(t: Tensor<D>, what: &str) -> Result<Vec<f32>> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| TrainError::Loop(format!("{what}: cannot read tensor data: {e:?}")))
}

/// Encodes clips `store_indices` of `store` with the frozen frame-wise VAE on `tokens` FPS tokens (the VAE run's
/// `vae.tokens`), `micro_batch` clips at a time.
pub fn encode_latents(
    vae: &FrameVae,
    store: &Store,
    store_indices: &[usize],
    micro_batch: usize,
    tokens: usize,
    device: &Device,
) -> Result<LatentSet> {
    let frames = store.frames();
    let mut clips = Vec::with_capacity(store_indices.len());
    let mut channels = 0;
    for chunk in store_indices.chunks(micro_batch.max(1)) {
        let (batch, _) = load_clips(store, chunk, device)?;
        let enc = vae.encode_vae_batch(&vae_batch(&batch, tokens, device)?);
        let [b, t, p, c] = enc.mu.dims();
        if (t, p) != (frames, tokens) {
            return Err(TrainError::Setup(format!(
                "VAE latents are [{b}, {t}, {p}, {c}], expected T = {frames} (the store {}) and P = {tokens}",
                store.dir().display()
            )));
        }
        channels = c;
        let z0 = host_f32(enc.z0, "z0")?;
        let mu = host_f32(enc.mu, "mu")?;
        let logvar = host_f32(enc.logvar, "logvar")?;
        let (shape_len, motion_len) = (p * c, t * p * c);
        for (i, (&store_index, caption)) in chunk.iter().zip(batch.captions).enumerate() {
            clips.push(ClipLatents {
                store_index,
                caption,
                z0: z0[i * shape_len..(i + 1) * shape_len].to_vec(),
                mu: mu[i * motion_len..(i + 1) * motion_len].to_vec(),
                logvar: logvar[i * motion_len..(i + 1) * motion_len].to_vec(),
            });
        }
    }
    Ok(LatentSet {
        clips,
        frames,
        tokens,
        channels,
    })
}

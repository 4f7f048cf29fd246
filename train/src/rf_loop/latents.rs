//! Frozen-VAE latents of the clips (docs/method.md §3.4, §4.1): encoded once into host memory or per micro-batch.

use any4d_data::augment::Augment;
use any4d_data::scene::features::{ClipSceneFeatures, GridSpec, clip_scene_features};
use any4d_data::store::Store;
use any4d_model::any_vae::AnyMeshVae;
use burn::prelude::{Device, Tensor};
use rand_chacha::ChaCha8Rng;

use any4d_model::mesh_vae::MeshVae;

use crate::backend;
use crate::error::{Result, TrainError};
use crate::vae_loop::{load_augmented, vae_batch};

/// Frozen-VAE encoding of one clip, kept in host memory in the VAE's layout.
#[derive(Clone, Debug)]
pub struct ClipLatents {
    /// Index of the clip in the store.
    pub store_index: usize,
    /// Its caption.
    pub caption: String,
    /// Shape latent z₀, `[P, C]` row-major.
    pub z0: Vec<f32>,
    /// Posterior mean μ of every latent slot, `[S, P, C]` row-major: S = T frames (frame-wise VAE) or the one
    /// trajectory slot of the sequence-wise VAE.
    pub mu: Vec<f32>,
    /// Posterior log σ², `[S, P, C]` row-major.
    pub logvar: Vec<f32>,
    /// (S1)–(S2) of the clip in its scene on the P anchor vertices (docs/method.md §4.11), when asked for and the
    /// clip has a scene.
    pub scene: Option<ClipSceneFeatures>,
}

/// The latents of one split and their sizes.
#[derive(Clone, Debug)]
pub struct LatentSet {
    /// One entry per clip, in store order.
    pub clips: Vec<ClipLatents>,
    /// Latent slots S per clip: T frames, or 1 for the sequence-wise VAE.
    pub frames: usize,
    /// P.
    pub tokens: usize,
    /// C.
    pub channels: usize,
}

impl LatentSet {
    /// Host bytes held.
    pub fn bytes(&self) -> usize {
        let scenes: usize = self
            .clips
            .iter()
            .filter_map(|c| c.scene.as_ref())
            .map(|s| s.grid.len() + s.offsets.len())
            .sum();
        (self.clips.len() * self.tokens * self.channels * (1 + 2 * self.frames) + scenes) * std::mem::size_of::<f32>()
    }
}

fn host_f32<const D: usize>(t: Tensor<D>, what: &str) -> Result<Vec<f32>> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| TrainError::Loop(format!("{what}: cannot read tensor data: {e:?}")))
}

/// Encodes clips `store_indices` of `store` with the frozen VAE on `tokens` FPS tokens (the VAE run's `vae.tokens`),
/// `micro_batch` clips at a time: one latent slot per frame (frame-wise VAE) or per clip (sequence-wise).
pub fn encode_latents(
    vae: &AnyMeshVae,
    store: &Store,
    store_indices: &[usize],
    micro_batch: usize,
    tokens: usize,
    device: &Device,
) -> Result<LatentSet> {
    encode_augmented(vae, store, store_indices, micro_batch, tokens, None, None, device)
}

/// [`encode_latents`] on `workers` CPU threads, each with its share of the cores ([`backend::worker_pools`]) and a
/// contiguous run of the micro-batches: every clip is encoded in the same micro-batch as by one worker, so the
/// latents are the same, and the parts are joined in store order. With `scene`, each clip with a scene also keeps
/// its (S1)–(S2) features on that grid.
#[allow(clippy::too_many_arguments)]
pub fn encode_latents_on_workers(
    vae: &AnyMeshVae,
    store: &Store,
    store_indices: &[usize],
    micro_batch: usize,
    tokens: usize,
    device: &Device,
    workers: usize,
    scene: Option<&GridSpec>,
) -> Result<LatentSet> {
    let micro_batch = micro_batch.max(1);
    let batches = store_indices.len().div_ceil(micro_batch);
    let workers = workers.clamp(1, batches.max(1));
    if workers == 1 {
        return encode_augmented(vae, store, store_indices, micro_batch, tokens, None, scene, device);
    }
    let pools = backend::worker_pools(workers).map_err(|e| {
        TrainError::Setup(format!(
            "cannot start the thread pools of {workers} encoding workers: {e}"
        ))
    })?;
    let per_worker = batches.div_ceil(workers) * micro_batch;
    let parts: Vec<Result<LatentSet>> = std::thread::scope(|s| {
        let handles: Vec<_> = store_indices
            .chunks(per_worker)
            .zip(&pools)
            .map(|(part, pool)| {
                s.spawn(move || {
                    pool.install(|| encode_augmented(vae, store, part, micro_batch, tokens, None, scene, device))
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err(TrainError::Loop("a latent-encoding worker panicked".into())))
            })
            .collect()
    });
    // At least two parts: `workers` ≥ 2 is clamped to the number of micro-batches.
    let mut all: Option<LatentSet> = None;
    for part in parts {
        let part = part?;
        match &mut all {
            Some(set) => set.clips.extend(part.clips),
            None => all = Some(part),
        }
    }
    all.ok_or_else(|| TrainError::Loop("no latent-encoding worker ran".into()))
}

/// [`encode_latents`] of the clips augmented in order with draws from the generator, when one is given
/// (docs/method.md §2.9), keeping the scene features of [`encode_latents_on_workers`] when `scene` is given.
#[allow(clippy::too_many_arguments)]
pub fn encode_augmented(
    vae: &AnyMeshVae,
    store: &Store,
    store_indices: &[usize],
    micro_batch: usize,
    tokens: usize,
    mut augment: Option<(&Augment, &mut ChaCha8Rng)>,
    scene: Option<&GridSpec>,
    device: &Device,
) -> Result<LatentSet> {
    let frames = if vae.clip_frames().is_some() { 1 } else { store.frames() };
    let mut clips = Vec::with_capacity(store_indices.len());
    let mut channels = 0;
    for chunk in store_indices.chunks(micro_batch.max(1)) {
        let aug = augment.as_mut().map(|(a, rng)| (*a, &mut **rng));
        let (batch, items) = load_augmented(store, chunk, aug, device)?;
        let enc = vae.encode_vae_batch(&vae_batch(&batch, tokens, device)?);
        let [b, t, p, c] = enc.mu.dims();
        if (t, p) != (frames, tokens) {
            return Err(TrainError::Setup(format!(
                "VAE latents are [{b}, {t}, {p}, {c}], expected {frames} latent slots (the store {} and the VAE kind) and P = {tokens}",
                store.dir().display()
            )));
        }
        channels = c;
        let z0 = host_f32(enc.z0, "z0")?;
        let mu = host_f32(enc.mu, "mu")?;
        let logvar = host_f32(enc.logvar, "logvar")?;
        let (shape_len, motion_len) = (p * c, t * p * c);
        for (i, ((&store_index, caption), item)) in chunk.iter().zip(batch.captions).zip(&items).enumerate() {
            let scene = match (scene, &item.scene) {
                (Some(spec), Some(s)) => Some(clip_scene_features(&item.clip, s, &item.fps[..tokens], spec)?),
                _ => None,
            };
            clips.push(ClipLatents {
                store_index,
                caption,
                z0: z0[i * shape_len..(i + 1) * shape_len].to_vec(),
                mu: mu[i * motion_len..(i + 1) * motion_len].to_vec(),
                logvar: logvar[i * motion_len..(i + 1) * motion_len].to_vec(),
                scene,
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

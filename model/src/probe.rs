//! Probes for the PyTorch parity check (docs/method.md §12): a network run on seeded random inputs, the inputs and its
//! outputs as the tensors of one safetensors file, which `scripts/torch_parity.py probe` feeds to AnimateAnyMesh's
//! module loaded with the same weights.

use burn::prelude::*;
use burn::tensor::Distribution;

use crate::bench::synthetic_vae_batch;
use crate::dymesh_vae::DyMeshVae;
use crate::frame_vae::FrameVae;
use crate::interop::FileTensor;
use crate::mesh_vae::Posterior;
use crate::mmdit::Mmdit;

/// Tokens, caption length and batch of an MMDiT probe.
pub const MMDIT_PROBE: (usize, usize, usize) = (64, 8, 2);
/// Vertices, tokens, frames and batch of a frame-wise VAE probe (a chain mesh, the first tokens as FPS tokens).
pub const VAE_PROBE: (usize, usize, usize, usize) = (256, 64, 4, 1);

fn file_tensor<const D: usize>(name: &str, t: Tensor<D>) -> FileTensor {
    let data = t.into_data().convert::<f32>();
    FileTensor {
        name: name.to_owned(),
        shape: data.shape().to_vec(),
        bytes: data.as_bytes().to_vec(),
    }
}

/// The MMDiT on random inputs drawn from `seed`: `input` `[B, P, in]` and `text` `[B, L, D_txt]` ~ N(0, 1), `keep`
/// `[B]` = (1, 0) (the second example's caption dropped), `tau` `[B]` ~ U(0, 1); `output` = [`Mmdit::forward`].
pub fn probe_mmdit(model: &Mmdit, seed: u64, device: &Device) -> Vec<FileTensor> {
    let (tokens, text_len, batch) = MMDIT_PROBE;
    device.seed(seed);
    let normal = Distribution::Normal(0.0, 1.0);
    let input = Tensor::<3>::random([batch, tokens, model.in_channels()], normal, device);
    let text_dim = model.text_dim();
    let text = Tensor::<3>::random([batch, text_len, text_dim], normal, device);
    let keep = Tensor::<1>::from_floats([1.0, 0.0], device);
    let tau = Tensor::<1>::random([batch], Distribution::Uniform(0.0, 1.0), device);
    let output = model.forward(input.clone(), text.clone(), keep.clone(), tau.clone());
    vec![
        file_tensor("input", input),
        file_tensor("text", text),
        file_tensor("keep", keep),
        file_tensor("tau", tau),
        file_tensor("output", output),
    ]
}

/// The frame-wise VAE's encode + decode (posterior mean) of a synthetic clip drawn from `seed` (the benchmark's: a
/// chain mesh, uniform reference, N(0, 0.05) motion, the first P vertices as tokens): `reference` `[B, N, 3]`,
/// `frames` `[B, T, N, 3]` and the reconstruction `output` `[B, T, N, 3]`.
pub fn probe_frame_vae(model: &FrameVae, seed: u64, device: &Device) -> Result<Vec<FileTensor>, String> {
    let (vertices, tokens, frames, batch) = VAE_PROBE;
    device.seed(seed);
    let b = synthetic_vae_batch(batch, vertices, tokens, frames, device)?;
    let (output, _) = model.reconstruct(&b, Posterior::Mean);
    Ok(vec![
        file_tensor("reference", b.reference.clone()),
        file_tensor("frames", b.frames.clone()),
        file_tensor("output", output),
    ])
}

/// The sequence-wise DyMeshVAE's encode + decode (posterior mean) of a synthetic clip of its own length drawn from
/// `seed`, as [`probe_frame_vae`] but with the clip's frame 0 as the reference.
pub fn probe_dymesh_vae(model: &DyMeshVae, seed: u64, device: &Device) -> Result<Vec<FileTensor>, String> {
    let (vertices, tokens, _, batch) = VAE_PROBE;
    device.seed(seed);
    let mut b = synthetic_vae_batch(batch, vertices, tokens, model.frames(), device)?;
    // The sequence-wise VAE's reference is the clip's frame 0 (AnimateAnyMesh reads it from the frames).
    b.reference = b.frames.clone().narrow(1, 0, 1).squeeze_dim(1);
    let (output, _) = model.reconstruct(&b, Posterior::Mean);
    Ok(vec![
        file_tensor("reference", b.reference.clone()),
        file_tensor("frames", b.frames.clone()),
        file_tensor("output", output),
    ])
}

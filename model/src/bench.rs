//! What `any4d bench model` measures: RF forward+backward (docs/method.md §4.3) and VAE encode+decode (§3.2, §3.5)
//! time per step on random inputs, at the sizes of [`BenchSizes`] (which `scripts/bench_torch_reference.py` mirrors
//! for AnimateAnyMesh's PyTorch networks), and the one [`median`] of the workspace's timings.

use burn::prelude::*;

use crate::dymesh_vae::DyMeshVaeConfig;
use crate::frame_vae::FrameVaeConfig;
use crate::mmdit::{KeyframeConditioning, MmditConfig};
use crate::summary::{TOTAL, param_report};

/// The networks and shapes of one benchmark size.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchSizes {
    /// The RF.
    pub rf: MmditConfig,
    /// FPS tokens P.
    pub tokens: usize,
    /// Text tokens L.
    pub text_len: usize,
    /// Vertices N of the VAE clips.
    pub vertices: usize,
    /// The frame-wise VAE.
    pub vae: FrameVaeConfig,
    /// The sequence-wise VAE.
    pub dymesh: DyMeshVaeConfig,
}

impl BenchSizes {
    /// `configs/rf/paper.toml` sizes (W 512, 12 blocks, P 512, L 77); VAEs at paper size on N 2048 vertices.
    pub fn paper() -> Self {
        Self {
            rf: MmditConfig::paper(KeyframeConditioning::InputMask, 768),
            tokens: 512,
            text_len: 77,
            vertices: 2048,
            vae: FrameVaeConfig::paper(),
            dymesh: DyMeshVaeConfig::paper(),
        }
    }

    /// `MmditConfig::tiny()` with P 64, L 8; the tiny VAEs on N 256.
    pub fn tiny() -> Self {
        Self {
            rf: MmditConfig::tiny(),
            tokens: 64,
            text_len: 8,
            vertices: 256,
            vae: FrameVaeConfig::tiny(),
            dymesh: DyMeshVaeConfig::tiny(),
        }
    }
}

/// Timings and parameter counts of the three networks at one size.
#[derive(Clone, Debug)]
pub struct ModelTimings {
    /// RF forward + backward.
    pub rf: StepTiming,
    /// RF parameters.
    pub rf_params: usize,
    /// Frame-wise VAE encode + decode.
    pub vae: StepTiming,
    /// Frame-wise VAE parameters.
    pub vae_params: usize,
    /// Sequence-wise VAE encode + decode.
    pub dymesh: StepTiming,
    /// Sequence-wise VAE parameters.
    pub dymesh_params: usize,
}

/// Times the three networks of `sizes` on batches of `batch` clips: one warm-up, then `iters` timed runs each,
/// on the current rayon pool (burn-flex's kernels use it).
///
/// # Errors
/// If the synthetic clips cannot be built (names the reason).
pub fn time_networks(sizes: &BenchSizes, batch: usize, iters: usize, device: &Device) -> Result<ModelTimings, String> {
    let frames = sizes.rf.frames;
    let total = |rows: Vec<(String, usize)>| rows.iter().find(|(n, _)| n == TOTAL).map_or(0, |(_, n)| *n);
    Ok(ModelTimings {
        rf: time_rf_step(&sizes.rf, batch, sizes.tokens, sizes.text_len, iters, device),
        rf_params: total(param_report(&sizes.rf.init(device))),
        vae: time_vae_reconstruct(&sizes.vae, batch, sizes.vertices, sizes.tokens, frames, iters, device)?,
        vae_params: total(param_report(&sizes.vae.init(device))),
        dymesh: time_dymesh_reconstruct(&sizes.dymesh, batch, sizes.vertices, sizes.tokens, iters, device)?,
        dymesh_params: total(param_report(&sizes.dymesh.init(device))),
    })
}

/// Wall-clock time of RF training steps.
#[derive(Clone, Debug)]
pub struct StepTiming {
    /// Median over the timed steps, milliseconds per step.
    pub median_ms: f64,
    /// Every timed step, milliseconds.
    pub steps_ms: Vec<f64>,
}

/// Times (R4)–(R5) forward + backward of a freshly initialised RF on random inputs: one warm-up step, then
/// `iters` timed steps (each ends with a device sync).
///
/// # Shapes
/// - the batch is `[batch, tokens, in_channels]` with text `[batch, text_len, text_dim]`
pub fn time_rf_step(
    cfg: &MmditConfig,
    batch: usize,
    tokens: usize,
    text_len: usize,
    iters: usize,
    device: &Device,
) -> StepTiming {
    use burn::tensor::Distribution;
    let ad = device.clone().autodiff();
    let model = cfg.init(&ad);
    let normal = Distribution::Normal(0.0, 1.0);
    let step = || {
        let input = Tensor::<3>::random([batch, tokens, cfg.in_channels()], normal, &ad);
        let text = Tensor::<3>::random([batch, text_len, cfg.text_dim], normal, &ad);
        let target = Tensor::<3>::random([batch, tokens, cfg.out_channels()], normal, &ad);
        let tau = Tensor::<1>::random([batch], Distribution::Uniform(0.0, 1.0), &ad);
        let keep = Tensor::<1>::ones([batch], &ad);
        // The inputs exist before the clock starts (GPU backends build them lazily).
        if let Err(e) = ad.sync() {
            panic!("device sync failed: {e:?}");
        }
        let start = std::time::Instant::now();
        let loss = (model.forward(input, text, keep, tau) - target).square().mean();
        let grads = loss.backward();
        drop(grads);
        if let Err(e) = ad.sync() {
            panic!("device sync failed: {e:?}");
        }
        start.elapsed().as_secs_f64() * 1e3
    };
    step();
    let steps_ms: Vec<f64> = (0..iters).map(|_| step()).collect();
    StepTiming {
        median_ms: median(&steps_ms),
        steps_ms,
    }
}

/// Times frame-wise VAE encode + decode (posterior mean, no gradients) of synthetic clips: a chain mesh of
/// `vertices` vertices, `frames` frames, the first `tokens` vertices as FPS tokens; one warm-up, `iters` timed runs.
///
/// # Errors
/// If the synthetic edge list is rejected (names the reason).
pub fn time_vae_reconstruct(
    cfg: &FrameVaeConfig,
    batch: usize,
    vertices: usize,
    tokens: usize,
    frames: usize,
    iters: usize,
    device: &Device,
) -> Result<StepTiming, String> {
    time_reconstruct(&cfg.init(device), batch, vertices, tokens, frames, iters, device)
}

/// Times sequence-wise DyMeshVAE (docs/method.md §3.5) encode + decode on the same synthetic clips as
/// [`time_vae_reconstruct`]; `cfg.frames` gives the clip length.
///
/// # Errors
/// If the synthetic edge list is rejected (names the reason).
pub fn time_dymesh_reconstruct(
    cfg: &DyMeshVaeConfig,
    batch: usize,
    vertices: usize,
    tokens: usize,
    iters: usize,
    device: &Device,
) -> Result<StepTiming, String> {
    time_reconstruct(&cfg.init(device), batch, vertices, tokens, cfg.frames, iters, device)
}

/// Encode + decode (posterior mean) of `model` on the synthetic clips of [`synthetic_vae_batch`].
fn time_reconstruct<V: crate::mesh_vae::MeshVae>(
    model: &V,
    batch: usize,
    vertices: usize,
    tokens: usize,
    frames: usize,
    iters: usize,
    device: &Device,
) -> Result<StepTiming, String> {
    let vae_batch = synthetic_vae_batch(batch, vertices, tokens, frames, device)?;
    Ok(time_runs(iters, || {
        let (recon, _) = model.reconstruct(&vae_batch, crate::mesh_vae::Posterior::Mean);
        let _ = recon.into_data();
    }))
}

/// Synthetic VAE batch: a chain mesh (vertex i joined to i + 1), uniform reference in [−1, 1]³, N(0, 0.05)
/// motion, all vertices real, the first `tokens` vertices as FPS tokens.
///
/// # Shapes
/// - `frames` `[batch, frames, vertices, 3]`, `reference` `[batch, vertices, 3]`, `fps` `[batch, tokens]`
pub fn synthetic_vae_batch(
    batch: usize,
    vertices: usize,
    tokens: usize,
    frames: usize,
    device: &Device,
) -> Result<crate::mesh_vae::VaeBatch, String> {
    use crate::mesh_vae::{EdgeList, VaeBatch};
    use burn::tensor::{Distribution, TensorData};
    if vertices < 2 || tokens > vertices {
        return Err(format!(
            "synthetic clips need at least 2 vertices and no more tokens than vertices, got {vertices} vertices \
             and {tokens} tokens"
        ));
    }
    let chain: Vec<[u32; 2]> = (0..vertices as u32 - 1).map(|i| [i, i + 1]).collect();
    let edges = EdgeList::new(&vec![chain; batch], vertices, device).map_err(|e| format!("synthetic {e}"))?;
    let reference = Tensor::<3>::random([batch, vertices, 3], Distribution::Uniform(-1.0, 1.0), device);
    let motion = Tensor::<4>::random([batch, frames, vertices, 3], Distribution::Normal(0.0, 0.05), device);
    let fps_ids: Vec<i64> = (0..batch).flat_map(|_| 0..tokens as i64).collect();
    Ok(VaeBatch {
        frames: reference.clone().unsqueeze_dim::<4>(1) + motion,
        reference,
        vmask: Tensor::<2, Bool>::from_data(TensorData::new(vec![true; batch * vertices], [batch, vertices]), device),
        fps: Tensor::from_data(TensorData::new(fps_ids, [batch, tokens]), device),
        edges,
        noise_seed: None,
    })
}

/// One warm-up call of `run`, then `iters` timed calls.
fn time_runs(iters: usize, mut run: impl FnMut()) -> StepTiming {
    let mut timed = || {
        let start = std::time::Instant::now();
        run();
        start.elapsed().as_secs_f64() * 1e3
    };
    timed();
    let steps_ms: Vec<f64> = (0..iters).map(|_| timed()).collect();
    StepTiming {
        median_ms: median(&steps_ms),
        steps_ms,
    }
}

/// The median of `values` (the mean of the two middle ones for an even count); NaN for an empty list. The one
/// median of the workspace's timings and benchmarks.
pub fn median(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    match n {
        0 => f64::NAN,
        _ if n % 2 == 1 => sorted[n / 2],
        _ => 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vae_timings_report_every_timed_run() {
        let dev = Device::flex();
        let seq = time_dymesh_reconstruct(&DyMeshVaeConfig::tiny(), 1, 16, 4, 3, &dev).expect("times");
        assert_eq!(seq.steps_ms.len(), 3);
        assert!(seq.steps_ms.iter().all(|&ms| ms > 0.0));
        assert_eq!(seq.median_ms, median(&seq.steps_ms));
        let frame = time_vae_reconstruct(&FrameVaeConfig::tiny(), 1, 16, 4, 2, 2, &dev).expect("times");
        assert_eq!(frame.steps_ms.len(), 2);
    }

    #[test]
    fn impossible_synthetic_clips_are_errors() {
        let dev = Device::flex();
        let err = time_dymesh_reconstruct(&DyMeshVaeConfig::tiny(), 1, 4, 8, 1, &dev).expect_err("P > N");
        assert!(err.contains("4 vertices and 8 tokens"), "{err}");
        let err = time_vae_reconstruct(&FrameVaeConfig::tiny(), 1, 1, 1, 2, 1, &dev).expect_err("N < 2");
        assert!(err.contains("at least 2 vertices"), "{err}");
    }

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&[]).is_nan());
    }

    #[test]
    fn bench_sizes_agree_with_the_reference_script() {
        // The script's SIZES table must describe the same networks as ours.
        let script = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../scripts/bench_torch_reference.py"
        ))
        .expect("script");
        for (name, sz) in [("paper", BenchSizes::paper()), ("tiny", BenchSizes::tiny())] {
            let start = script.find(&format!("\"{name}\": {{")).expect("size entry");
            let entry = &script[start..];
            let rf = format!(
                "\"rf\": {{\"width\": {}, \"blocks\": {}, \"heads\": {}, \"frames\": {}, \"channels\": {}, \
                 \"text_dim\": {}}}",
                sz.rf.width, sz.rf.blocks, sz.rf.heads, sz.rf.frames, sz.rf.channels, sz.rf.text_dim
            );
            let tokens = format!("\"tokens\": {},", sz.tokens);
            let text = format!("\"text_len\": {},", sz.text_len);
            let verts = format!("\"vertices\": {},", sz.vertices);
            let vae = |key: &str, b: &crate::mesh_vae::MeshVaeBodyConfig| {
                format!(
                    "\"{key}\": {{\"dim\": {}, \"heads\": {}, \"dim_head\": {}, \"blocks\": {}, \"latent\": {}}}",
                    b.width, b.heads, b.head_dim, b.enc_blocks, b.latent_channels
                )
            };
            let fw = vae("vae_framewise", &sz.vae.body);
            let sw = vae("vae_sequencewise", &sz.dymesh.body);
            let entry_end = entry.find("\n    },").expect("entry end");
            for needle in [rf, tokens, text, verts, fw, sw] {
                assert!(
                    entry[..entry_end].contains(&needle),
                    "{name} size: script lacks {needle}"
                );
            }
            assert_eq!(
                sz.rf.frames, sz.dymesh.frames,
                "both VAEs time clips of the RF's frame count"
            );
            assert_eq!(
                sz.vae.body.dec_blocks, sz.vae.body.enc_blocks,
                "the script uses one block count per VAE"
            );
            assert_eq!(sz.dymesh.body.dec_blocks, sz.dymesh.body.enc_blocks);
        }
    }
}

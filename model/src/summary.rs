//! Parameter counts of a network per top-level submodule (checks docs/method.md §4.3 "≈ 78M trainable"; used by
//! `any4d model summary`) and timings of the RF step and VAE encode+decode (used by `any4d bench model`).

use burn::module::{Module, ModuleVisitor, Param};
use burn::prelude::*;

/// Name of the last row of [`param_report`].
pub const TOTAL: &str = "total";

/// One float parameter: the names of the modules and fields leading to it (`["blocks", "0", "qkv", "weight"]`)
/// and its shape.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NamedParam {
    /// Module and field names from the root down to the parameter.
    pub path: Vec<String>,
    /// Its shape.
    pub shape: Vec<usize>,
}

impl NamedParam {
    /// Number of elements.
    pub fn numel(&self) -> usize {
        self.shape.iter().product()
    }
}

/// Every float parameter of `module`, in visiting (declaration) order.
pub fn named_params<M: Module>(module: &M) -> Vec<NamedParam> {
    #[derive(Default)]
    struct Collect {
        path: Vec<String>,
        params: Vec<NamedParam>,
    }
    impl ModuleVisitor for Collect {
        fn enter_module(&mut self, name: &str, _container_type: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _name: &str, _container_type: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.params.push(NamedParam {
                path: self.path.clone(),
                shape: param.lazy_shape().dims::<D>().to_vec(),
            });
        }
    }
    let mut c = Collect::default();
    module.visit(&mut c);
    c.params
}

/// Float parameter counts per top-level submodule, in declaration order, followed by `("total", sum)`.
/// Vectors of blocks count as one submodule (e.g. `blocks`).
pub fn param_report<M: Module>(module: &M) -> Vec<(String, usize)> {
    let mut rows: Vec<(String, usize)> = Vec::new();
    for p in named_params(module) {
        let name = p.path.first().cloned().unwrap_or_else(|| "(root)".to_string());
        match rows.iter_mut().find(|(n, _)| *n == name) {
            Some((_, total)) => *total += p.numel(),
            None => rows.push((name, p.numel())),
        }
    }
    let total = rows.iter().map(|(_, n)| n).sum();
    rows.push((TOTAL.to_string(), total));
    rows
}

/// Renders a report as aligned text lines (name, count, share of the total).
pub fn format_report(title: &str, rows: &[(String, usize)]) -> String {
    let total = rows.iter().find(|(n, _)| n == TOTAL).map_or(0, |(_, n)| *n).max(1);
    let width = rows.iter().map(|(n, _)| n.len()).max().unwrap_or(0).max(8);
    let mut out = format!("{title}\n");
    for (name, count) in rows {
        let share = 100.0 * *count as f64 / total as f64;
        out.push_str(&format!("  {name:<width$}  {count:>12}  {share:6.2}%\n"));
    }
    out
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
    cfg: &crate::mmdit::MmditConfig,
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
    cfg: &crate::frame_vae::FrameVaeConfig,
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
    cfg: &crate::dymesh_vae::DyMeshVaeConfig,
    batch: usize,
    vertices: usize,
    tokens: usize,
    iters: usize,
    device: &Device,
) -> Result<StepTiming, String> {
    time_reconstruct(&cfg.init(device), batch, vertices, tokens, cfg.frames, iters, device)
}

/// Encode + decode (posterior mean) of `model` on the synthetic clips of [`synthetic_vae_batch`].
fn time_reconstruct<V: crate::frame_vae::MeshVaeModel>(
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
        let (recon, _) = model.reconstruct(&vae_batch, crate::frame_vae::Posterior::Mean);
        let _ = recon.into_data();
    }))
}

/// Synthetic VAE batch: a chain mesh (vertex i joined to i + 1), uniform reference in [−1, 1]³, N(0, 0.05)
/// motion, all vertices real, the first `tokens` vertices as FPS tokens.
///
/// # Shapes
/// - `frames` `[batch, frames, vertices, 3]`, `reference` `[batch, vertices, 3]`, `fps` `[batch, tokens]`
fn synthetic_vae_batch(
    batch: usize,
    vertices: usize,
    tokens: usize,
    frames: usize,
    device: &Device,
) -> Result<crate::frame_vae::VaeBatch, String> {
    use crate::frame_vae::{EdgeList, VaeBatch};
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

/// Median of a non-empty list (mean of the two middle values for an even count).
pub fn median(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    if n % 2 == 1 {
        sorted[n / 2]
    } else {
        0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dymesh_vae::DyMeshVaeConfig;
    use crate::frame_vae::FrameVaeConfig;

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
    }
}

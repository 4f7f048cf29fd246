//! Data-parallel training on several devices of one machine (issue 5 item 6): the shared loop of
//! [`crate::loop_common`] with each step's micro-batches spread over the devices, using burn-train 0.22.1's own
//! multi-device mechanism (`MultiDeviceOptim::OptimMainDevice`): every worker forks the model onto its device
//! (`Module::fork`), runs forward/backward there, the gradients move to the main device
//! (`GradientsParams::to_device`) and burn's `GradientsAccumulator` sums them; the optimiser steps once on
//! the main device. Same global batch, same micro-batches, same checkpoints and exact resume as one device.

use std::path::{Path, PathBuf};

use any4d_data::store::{Split, Store};
use burn::module::Module;
use burn::optim::{GradientsAccumulator, GradientsParams};
use burn::prelude::Device;
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::backend::{self, Backend, Precision};
use crate::checkpoint::{self, TrainState};
use crate::config::TrainConfig;
use crate::error::{Result, TrainError};
use crate::loop_common::{LoopSetup, Objective, Outcome, StepGradients, StepLosses, run_steps, scalar};
use crate::run_folder::{CHECKPOINTS_DIR, RunFolder, write_atomic};
use crate::vae_loop::{
    LATENT_STATS_FILE, MeshVae, StoredLatentStats, VaeModelConfig, VaeObjective, VaeRunConfig, VaeRunOptions,
    latent_stats,
};

/// One entry of `--devices`: a backend and a device index (`flex`, `ndarray`, `cuda:1`, `vulkan:0`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DeviceSpec {
    /// Backend of the device.
    pub backend: Backend,
    /// Hardware index (always 0 on the CPU backends, which have one device each).
    pub index: usize,
}

impl DeviceSpec {
    /// Parses `BACKEND` or `BACKEND:INDEX`.
    pub fn parse(text: &str) -> Result<Self> {
        let bad = |reason: String| TrainError::Other(format!("--devices entry `{text}`: {reason}"));
        let (name, index) = match text.split_once(':') {
            Some((n, i)) => (
                n,
                i.parse::<usize>()
                    .map_err(|e| bad(format!("index `{i}` is not a number ({e})")))?,
            ),
            None => (text, 0),
        };
        let backend = <Backend as clap::ValueEnum>::from_str(name.trim(), true)
            .map_err(|_| bad(format!("unknown backend `{name}` (flex, ndarray, vulkan, cuda)")))?;
        if backend.is_cpu() && index != 0 {
            return Err(bad(format!("the {backend} backend has one device, index 0")));
        }
        Ok(DeviceSpec { backend, index })
    }

    /// Parses a comma-separated list (`flex,flex` or `cuda:0,cuda:1`); at least one entry.
    pub fn parse_list(text: &str) -> Result<Vec<Self>> {
        let specs = text
            .split(',')
            .filter(|s| !s.trim().is_empty())
            .map(|s| Self::parse(s.trim()))
            .collect::<Result<Vec<_>>>()?;
        if specs.is_empty() {
            return Err(TrainError::Other("--devices: no device given".into()));
        }
        Ok(specs)
    }

    /// The plain (non-autodiff) burn device at `precision`.
    pub fn device(self, precision: Precision) -> Result<Device> {
        if self.index == 0 {
            return Ok(backend::device(self.backend, precision)?);
        }
        if precision != Precision::F32 {
            return Err(TrainError::Other(format!(
                "--devices {}:{}: only f32 is supported on a device other than index 0",
                self.backend, self.index
            )));
        }
        indexed_gpu(self.backend, self.index)
    }
}

#[allow(unused_variables)]
fn indexed_gpu(backend: Backend, index: usize) -> Result<Device> {
    match backend {
        #[cfg(feature = "cuda")]
        Backend::Cuda => Ok(Device::cuda(index)),
        #[cfg(feature = "vulkan")]
        Backend::Vulkan => Ok(Device::vulkan(burn::tensor::DeviceKind::DiscreteGpu(index))),
        other => Err(TrainError::Other(format!(
            "--devices {other}:{index}: this build has no {other} backend (build with --features {other})"
        ))),
    }
}

/// [`loop_common::train`](crate::loop_common::train) data-parallel over `devices` (autodiff devices; the
/// first is the main device, where the model, the optimiser state and validation live; `setup.device` is
/// ignored). Each step's `accumulation()` micro-batches go to the devices in rounds of `devices.len()`, each
/// worker on its own thread. The objective's `rng` argument is a per-micro-batch generator seeded from the
/// run's generator, so a run is reproducible and resumes exactly for a given device count; in-model device
/// noise is reseeded per step on every device, but listing one device twice shares its generator between
/// threads (ordering then varies).
pub fn train_data_parallel<O>(
    objective: &O,
    model: O::Model,
    setup: LoopSetup<'_>,
    devices: &[Device],
) -> Result<(O::Model, Outcome)>
where
    O: Objective + Sync,
{
    let Some(main) = devices.first() else {
        return Err(TrainError::Other(
            "data-parallel training needs at least one device".into(),
        ));
    };
    let model = model.fork(main);
    run_steps(objective, model, setup, &DataParallel(devices))
}

/// The data-parallel step: burn-train's `OptimMainDevice` (fork → backward on each device → gradients to the
/// main device → `GradientsAccumulator`).
struct DataParallel<'a>(&'a [Device]);

impl<O: Objective + Sync> StepGradients<O> for DataParallel<'_> {
    fn devices(&self) -> &[Device] {
        self.0
    }

    fn gradients(
        &self,
        objective: &O,
        model: &O::Model,
        state: &mut TrainState,
        cfg: &TrainConfig,
        losses: &mut StepLosses<'_>,
    ) -> Result<GradientsParams> {
        let devices = self.0;
        let Some(main) = devices.first() else {
            return Err(TrainError::Other(
                "data-parallel training needs at least one device".into(),
            ));
        };
        let mut accum = GradientsAccumulator::<O::Model>::new();
        let mut left = cfg.accumulation();
        while left > 0 {
            let round = left.min(devices.len());
            left -= round;
            let jobs: Vec<(Vec<usize>, ChaCha8Rng)> = (0..round)
                .map(|_| {
                    let idx = state.order.take(cfg.micro_batch);
                    (idx, ChaCha8Rng::seed_from_u64(state.rng.next_u64()))
                })
                .collect();
            let results: Vec<Result<MicroResult>> = std::thread::scope(|s| {
                let handles: Vec<_> = jobs
                    .into_iter()
                    .zip(devices)
                    .map(|((idx, mut rng), dev)| {
                        let worker_model = model.clone().fork(dev);
                        s.spawn(move || -> Result<MicroResult> {
                            let out = objective.loss(&worker_model, &idx, &mut rng, dev)?;
                            let weight = idx.len() as f64 / cfg.batch_size as f64;
                            let terms: Vec<f64> = out.terms.into_iter().map(scalar).collect();
                            let scaled = out.total.mul_scalar(weight);
                            let total = scalar(scaled.clone());
                            let grads = GradientsParams::from_grads(scaled.backward(), &worker_model);
                            Ok(MicroResult {
                                weight,
                                terms,
                                total,
                                grads,
                            })
                        })
                    })
                    .collect();
                handles
                    .into_iter()
                    .map(|h| {
                        h.join().unwrap_or_else(|p| {
                            Err(TrainError::Other(format!(
                                "a training worker panicked: {}",
                                panic_text(p.as_ref())
                            )))
                        })
                    })
                    .collect()
            });
            for r in results {
                let r = r?;
                losses.record(r.weight, &r.terms, r.total)?;
                // burn-train's OptimMainDevice: gradients to the main device, summed there.
                accum.accumulate(model, r.grads.to_device(main, model));
            }
        }
        Ok(accum.grads())
    }
}

struct MicroResult {
    weight: f64,
    terms: Vec<f64>,
    total: f64,
    grads: GradientsParams,
}

fn panic_text(p: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic".into()
    }
}

/// Starts a new VAE run with `cfg`, data-parallel over `devices` (`--devices`); returns the run folder and
/// the outcome. A finished run writes `latent_stats.json` (SPEC §3.4) as the single-device path does.
pub fn train_vae_data_parallel(
    cfg: &VaeRunConfig,
    opts: &VaeRunOptions,
    devices: &[DeviceSpec],
) -> Result<(RunFolder, Outcome)> {
    let plain = devices
        .iter()
        .map(|d| d.device(cfg.device.precision))
        .collect::<Result<Vec<_>>>()?;
    Store::open(&opts.data).map_err(|e| TrainError::Other(format!("{}: {e}", opts.data.display())))?;
    let run = RunFolder::create(&opts.runs_dir, &opts.name, &cfg.to_toml()?, &["rec", "kl"])?;
    let outcome = run_vae(cfg, &run, opts, plain, None)?;
    Ok((run, outcome))
}

/// Continues the VAE run in `run_dir` from its newest checkpoint, data-parallel over `devices` (config from
/// the run folder; `[device] precision` applies to every device).
pub fn resume_vae_data_parallel(run_dir: &Path, opts: &VaeRunOptions, devices: &[DeviceSpec]) -> Result<Outcome> {
    let run = RunFolder::open(run_dir)?;
    let cfg = VaeRunConfig::parse(&run.config_text()?, &run.path(crate::run_folder::CONFIG_FILE))?;
    let plain = devices
        .iter()
        .map(|d| d.device(cfg.device.precision))
        .collect::<Result<Vec<_>>>()?;
    let ckpt = checkpoint::latest(&run.path(CHECKPOINTS_DIR))?.ok_or_else(|| TrainError::Checkpoint {
        path: run_dir.to_path_buf(),
        reason: "no complete checkpoint to resume".into(),
    })?;
    run_vae(&cfg, &run, opts, plain, Some(ckpt))
}

fn run_vae(
    cfg: &VaeRunConfig,
    run: &RunFolder,
    opts: &VaeRunOptions,
    plain: Vec<Device>,
    resume: Option<PathBuf>,
) -> Result<Outcome> {
    let ad: Vec<Device> = plain.into_iter().map(|d| d.autodiff()).collect();
    let Some(main) = ad.first() else {
        return Err(TrainError::Other(
            "data-parallel training needs at least one device".into(),
        ));
    };
    main.seed(cfg.train.seed);
    match &cfg.model {
        VaeModelConfig::Framewise(m) => fit_vae(m.init(main), cfg, run, opts, &ad, resume),
        VaeModelConfig::Sequencewise(m) => fit_vae(m.init(main), cfg, run, opts, &ad, resume),
    }
}

fn fit_vae<V: MeshVae>(
    model: V,
    cfg: &VaeRunConfig,
    run: &RunFolder,
    opts: &VaeRunOptions,
    devices: &[Device],
    resume: Option<PathBuf>,
) -> Result<Outcome>
where
    VaeObjective<V>: Sync,
{
    let objective = VaeObjective::<V>::new(&opts.data, cfg.train.micro_batch)?;
    run.log(&format!(
        "VAE {:?} on {}, data-parallel over {} devices",
        cfg.vae.kind,
        opts.data.display(),
        devices.len()
    ))?;
    let setup = LoopSetup {
        run,
        train: &cfg.train,
        optim: &cfg.optim,
        device: devices[0].clone(),
        stop: opts.stop.clone(),
        progress: opts.progress,
        resume,
    };
    let (model, outcome) = train_data_parallel(&objective, model, setup, devices)?;
    if let Outcome::Finished { steps, .. } = &outcome {
        let inference = devices[0].clone().without_autodiff();
        inference.seed(cfg.train.seed);
        let store = Store::open(&opts.data).map_err(|e| TrainError::Other(format!("{}: {e}", opts.data.display())))?;
        let train_ids = store.indices(Split::Train);
        let stats = latent_stats(&model.valid(), &store, &train_ids, cfg.train.micro_batch, &inference)?;
        let json = serde_json::to_vec_pretty(&StoredLatentStats { step: *steps, stats })
            .map_err(|e| TrainError::Other(format!("serialise latent stats: {e}")))?;
        write_atomic(&run.path(LATENT_STATS_FILE), &json)?;
        run.log(&format!("latent statistics (SPEC §3.4) of step {steps}: {stats:?}"))?;
    }
    Ok(outcome)
}

//! Data-parallel training on several devices of one machine, the optional strategy of both training loops
//! (`train vae` and `train rf` with `--devices`): the shared loop of
//! [`crate::loop_common`] with each step's micro-batches spread over the devices, using burn 0.22.1's own
//! multi-device mechanisms, chosen by [`Strategy`]:
//! - main-device (burn-train's `MultiDeviceOptim::OptimMainDevice`): every worker forks the model onto its device
//!   (`Module::fork`), runs forward/backward there, the gradients move to the main device
//!   (`GradientsParams::to_device`) and burn's `GradientsAccumulator` sums them;
//! - DDP (burn-train's `ExecutionStrategy::ddp`): the forked replicas are marked distributed
//!   (`burn::train::ModuleSharder`) under a `DistributedContext`, and burn all-reduces each gradient (NCCL on cuda)
//!   inside the backward pass.
//!
//! Either way the optimiser steps once on the main device and the replicas are forked from it again next step.
//! Same global batch, same micro-batches, same checkpoints and exact resume as one device.

use burn::module::Module;
use burn::optim::{GradientsAccumulator, GradientsParams};
use burn::prelude::Device;
use burn::tensor::distributed::{DistributedConfig, DistributedContext, ReduceOperation};
use burn::train::ModuleSharder;
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::backend::{self, Backend, Precision};
use crate::checkpoint::TrainState;
use crate::config::{DeviceConfig, TrainConfig};
use crate::error::{Result, TrainError};
use crate::loop_common::{LoopSetup, MicroLoss, Objective, Outcome, StepGradients, StepLosses, micro_batch, run_steps};

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
        let bad = |reason: String| TrainError::Devices(format!("--devices entry `{text}`: {reason}"));
        let (name, index) = match text.split_once(':') {
            Some((n, i)) => (
                n,
                i.parse::<usize>()
                    .map_err(|e| bad(format!("index `{i}` is not a number ({e})")))?,
            ),
            None => (text, 0),
        };
        let backend: Backend = name.parse().map_err(bad)?;
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
            return Err(TrainError::Devices("--devices: no device given".into()));
        }
        Ok(specs)
    }

    /// The plain (non-autodiff) burn device at `precision`.
    pub fn device(self, precision: Precision) -> Result<Device> {
        if self.index == 0 {
            return Ok(backend::device(self.backend, precision)?);
        }
        if precision != Precision::F32 {
            return Err(TrainError::Devices(format!(
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
        other => Err(TrainError::Devices(format!(
            "--devices {other}:{index}: this build has no {other} backend (build with --features {other})"
        ))),
    }
}

/// How the devices of `--devices` combine one step's gradients (`--strategy`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Strategy {
    /// `ddp` when every device is a distinct cuda device, `main-device` otherwise.
    Auto,
    /// burn-train's `MultiDeviceOptim::OptimMainDevice`: each device's gradients are copied to the first device
    /// and summed there (`GradientsParams::to_device` + `GradientsAccumulator`). Any backend, any mix.
    MainDevice,
    /// burn-train's DDP: parameters are marked distributed (`burn::train::ModuleSharder`) and burn all-reduces
    /// (sums) every gradient across the devices during the backward pass (`burn::tensor::distributed`, NCCL on
    /// cuda). burn 0.22.1 implements the collective only on cuda; `flex`, `ndarray` and `vulkan` refuse it.
    Ddp,
}

impl Strategy {
    /// Every strategy, in the order `--help` lists them.
    pub const ALL: [Strategy; 3] = [Strategy::Auto, Strategy::MainDevice, Strategy::Ddp];
}

impl std::fmt::Display for Strategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Strategy::Auto => "auto",
            Strategy::MainDevice => "main-device",
            Strategy::Ddp => "ddp",
        })
    }
}

impl std::str::FromStr for Strategy {
    type Err = String;

    /// Parses `auto`, `main-device` or `ddp`.
    fn from_str(name: &str) -> std::result::Result<Self, String> {
        Strategy::ALL
            .into_iter()
            .find(|s| s.to_string() == name.trim())
            .ok_or_else(|| format!("unknown strategy `{name}` (auto, main-device, ddp)"))
    }
}

/// `--devices` with `--strategy`: which devices, and how they share a step.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Parallel {
    /// The devices; the first holds the model, the optimiser state and validation.
    pub devices: Vec<DeviceSpec>,
    /// The resolved strategy (never [`Strategy::Auto`]).
    pub strategy: Strategy,
}

impl Parallel {
    /// Parses `--devices` and resolves `strategy`; an error names what burn 0.22.1 cannot do (DDP off cuda,
    /// one device listed twice under DDP).
    pub fn parse(devices: &str, strategy: Strategy) -> Result<Self> {
        let devices = DeviceSpec::parse_list(devices)?;
        let all_cuda = devices.iter().all(|d| d.backend == Backend::Cuda);
        let mut indices: Vec<usize> = devices.iter().map(|d| d.index).collect();
        indices.sort_unstable();
        indices.dedup();
        let distinct = indices.len() == devices.len();
        let strategy = match strategy {
            Strategy::Auto if all_cuda && distinct && devices.len() > 1 => Strategy::Ddp,
            Strategy::Auto => Strategy::MainDevice,
            Strategy::Ddp if !all_cuda => {
                return Err(TrainError::Devices(
                    "--strategy ddp needs cuda devices: burn 0.22.1 implements the gradient all-reduce (NCCL) only \
                     on cuda; flex, ndarray and vulkan have no collective operations (use --strategy main-device)"
                        .into(),
                ));
            }
            Strategy::Ddp if !distinct => {
                return Err(TrainError::Devices(
                    "--strategy ddp: each cuda device may be listed once (NCCL runs one rank per GPU)".into(),
                ));
            }
            other => other,
        };
        Ok(Parallel { devices, strategy })
    }

    /// The plain (non-autodiff) burn devices at `precision`.
    pub fn plain_devices(&self, precision: Precision) -> Result<Vec<Device>> {
        self.devices.iter().map(|d| d.device(precision)).collect()
    }
}

/// [`loop_common::train`](crate::loop_common::train) data-parallel over `devices` (autodiff devices; the
/// first is the main device, where the model, the optimiser state and validation live; `setup.device` is
/// ignored) with `strategy` (resolved: [`Strategy::MainDevice`] or [`Strategy::Ddp`]). Each step's
/// `accumulation()` micro-batches go to the devices in rounds of `devices.len()`, each worker on its own
/// thread; under DDP every round must use every device, so the accumulation must be a multiple of the device
/// count. The objective's `rng` argument is a per-micro-batch generator seeded from the run's generator, so a
/// run is reproducible and resumes exactly; the RF and VAE objectives draw their noise (ξ, ε, τ) from that generator on
/// the host ([`any4d_model::noise`]), so listing one CPU device twice (`flex,flex`, one worker per core) trains the
/// same numbers as one device with the same micro-batches.
/// Under DDP a worker that fails before its backward pass leaves the others waiting in burn's all-reduce, which
/// has no timeout in 0.22.1: such a run must be killed and resumed from its last checkpoint.
pub fn train_data_parallel<O>(
    objective: &O,
    model: O::Model,
    setup: LoopSetup<'_>,
    devices: &[Device],
    strategy: Strategy,
) -> Result<(O::Model, Outcome)>
where
    O: Objective + Sync,
{
    let Some(main) = devices.first() else {
        return Err(TrainError::Devices(
            "data-parallel training needs at least one device".into(),
        ));
    };
    crate::loop_common::materialise(&model, main, setup.train.seed);
    let model = model.fork(main);
    let ddp = strategy == Strategy::Ddp;
    // Anchors burn's gradient-sync server for the whole run under DDP; dropping it tears the server down.
    let _context = if ddp {
        let accumulation = setup.train.accumulation();
        if !accumulation.is_multiple_of(devices.len()) {
            return Err(TrainError::Devices(format!(
                "--strategy ddp: batch_size / micro_batch = {accumulation} micro-batches per step is not a \
                 multiple of the {} devices (every device takes part in every all-reduce)",
                devices.len()
            )));
        }
        Some(DistributedContext::init(
            devices.to_vec(),
            DistributedConfig {
                all_reduce_op: ReduceOperation::Sum,
            },
        ))
    } else {
        None
    };
    let pools = worker_pools(devices.len())?;
    if setup.train.flush_denormals {
        for pool in &pools {
            // docs/method.md §10; the pools end with the call, so their threads need no clearing.
            pool.broadcast(|_| any4d_model::denormals::set_flush_denormals(true));
        }
    }
    run_steps(objective, model, setup, &DataParallel { devices, ddp, pools })
}

/// The data-parallel step. Main-device (`ddp` false): fork → backward on each device → gradients to the main
/// device → `GradientsAccumulator`. DDP (`ddp` true): fork → shard → backward on each device, during which
/// burn sums each gradient over the devices, so the main device's gradients already hold the round's total.
struct DataParallel<'a> {
    devices: &'a [Device],
    ddp: bool,
    /// One thread pool per worker, splitting the current rayon pool between them.
    pools: Vec<rayon::ThreadPool>,
}

/// One rayon pool per worker ([`backend::worker_pools`]).
fn worker_pools(workers: usize) -> Result<Vec<rayon::ThreadPool>> {
    backend::worker_pools(workers)
        .map_err(|e| TrainError::Devices(format!("cannot start the thread pools of {workers} workers: {e}")))
}

impl<O: Objective + Sync> StepGradients<O> for DataParallel<'_> {
    fn devices(&self) -> &[Device] {
        self.devices
    }

    fn gradients(
        &self,
        objective: &O,
        model: &O::Model,
        state: &mut TrainState,
        cfg: &TrainConfig,
        losses: &mut StepLosses<'_>,
    ) -> Result<GradientsParams> {
        let devices = self.devices;
        let Some(main) = devices.first() else {
            return Err(TrainError::Devices(
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
            let results: Vec<Result<WorkerResult>> = std::thread::scope(|s| {
                let handles: Vec<_> = jobs
                    .into_iter()
                    .zip(devices.iter().zip(&self.pools))
                    .enumerate()
                    .map(|(worker, ((idx, mut rng), (dev, pool)))| {
                        let mut worker_model = model.clone().fork(dev);
                        if self.ddp {
                            worker_model = worker_model.map(&mut ModuleSharder);
                        }
                        let keep_grads = !self.ddp || worker == 0;
                        s.spawn(move || {
                            pool.install(move || -> Result<WorkerResult> {
                                // Under DDP the backward pass inside blocks until every device has reached it.
                                let (micro, grads) = micro_batch(objective, &worker_model, &idx, &mut rng, dev, cfg)?;
                                let grads = keep_grads.then(|| GradientsParams::from_grads(grads, &worker_model));
                                Ok((micro, grads))
                            })
                        })
                    })
                    .collect();
                handles
                    .into_iter()
                    .map(|h| {
                        h.join().unwrap_or_else(|p| {
                            Err(TrainError::Loop(format!(
                                "a training worker panicked: {}",
                                panic_text(p.as_ref())
                            )))
                        })
                    })
                    .collect()
            });
            for r in results {
                let (micro, grads) = r?;
                losses.record(&micro)?;
                if let Some(grads) = grads {
                    // Main-device: burn-train's OptimMainDevice, gradients to the main device, summed there.
                    // DDP: only the main device's (already all-reduced) gradients arrive here.
                    accum.accumulate(model, grads.to_device(main, model));
                }
            }
        }
        Ok(accum.grads())
    }
}

/// A worker's micro-batch: its losses and its gradients as parameters; `None` for the secondary DDP workers, whose
/// gradients equal the main device's after the all-reduce.
type WorkerResult = (MicroLoss, Option<GradientsParams>);

fn panic_text(p: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic".into()
    }
}

/// The plain devices a run trains on: `parallel`'s, or the one of `[device] backend`. Fails before a run folder is
/// claimed when a backend is not in this binary.
pub fn run_devices(device: &DeviceConfig, parallel: Option<&Parallel>) -> Result<Vec<Device>> {
    match parallel {
        Some(p) => {
            for d in &p.devices {
                backend::check_training(d.backend, device.precision)?;
            }
            p.plain_devices(device.precision)
        }
        None => {
            backend::check_training(device.backend, device.precision)?;
            Ok(vec![backend::device(device.backend, device.precision)?])
        }
    }
}

/// [`run_devices`] for the VAE and RF loops: without `parallel`, on a CPU backend, one worker per core up to the
/// step's micro-batches (`train.batch_size / train.micro_batch`), each with its share of the cores
/// ([`worker_pools`]). Workers train the numbers of one device (host-drawn noise, parameters drawn from the seed),
/// so the split only changes the speed and the memory (one micro-batch's activations per worker); `--devices flex`
/// trains on one.
pub fn worker_devices(device: &DeviceConfig, train: &TrainConfig, parallel: Option<&Parallel>) -> Result<Vec<Device>> {
    let devices = run_devices(device, parallel)?;
    if parallel.is_some() || !device.backend.is_cpu() {
        return Ok(devices);
    }
    let workers = rayon::current_num_threads().min(train.accumulation()).max(1);
    Ok(vec![devices[0].clone(); workers])
}

/// How a run with `devices` (from [`worker_devices`]) combines its gradients: `None` for one device (the plain
/// loop), else `parallel`'s strategy, or main-device for automatic CPU workers.
pub fn run_strategy(devices: &[Device], parallel: Option<&Parallel>) -> Option<Strategy> {
    match parallel {
        _ if devices.len() < 2 => None,
        Some(p) => Some(p.strategy),
        None => Some(Strategy::MainDevice),
    }
}

/// The log line of a data-parallel run.
pub fn strategy_note(devices: &[Device], parallel: Option<&Parallel>, strategy: Strategy) -> String {
    match parallel {
        Some(_) => format!("data-parallel over {} devices ({strategy:?})", devices.len()),
        None => format!(
            "{} CPU workers, one per core, each on its own micro-batches (`--devices flex` trains on one)",
            devices.len()
        ),
    }
}

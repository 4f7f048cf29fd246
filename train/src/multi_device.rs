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

use crate::backend;
use crate::checkpoint::TrainState;
use crate::config::TrainConfig;
use crate::devices::Strategy;
use crate::error::{Result, TrainError};
use crate::loop_common::{LoopSetup, MicroLoss, Objective, Outcome, StepGradients, StepLosses, micro_batch, run_steps};

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

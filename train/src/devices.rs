//! Which devices a run trains on: `--devices` (a list of `BACKEND[:INDEX]`) and `--strategy`, resolved to burn
//! devices before a run folder is claimed, and the number of CPU workers a run starts. The data-parallel loop over
//! them is the `multi_device` module.

use burn::prelude::Device;

use crate::backend::{self, Backend, Precision};
use crate::config::{DeviceConfig, TrainConfig};
use crate::error::{Result, TrainError};

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

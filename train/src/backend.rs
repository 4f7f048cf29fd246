//! Compute backends picked at run time: burn 0.22 selects the backend through the `Device`
//! value, so one binary carries the CPU backends (`flex`, `ndarray`) and, behind cargo features, the GPU ones
//! (`vulkan`, `cuda`). Precision (docs/method.md §3.5, §4.7: FP32) is a device setting; the half precisions (f16,
//! bf16) run on the GPU backends only, where the device reports the type usable for arithmetic and products.

use std::fmt;

use burn::prelude::Device;
use serde::{Deserialize, Serialize};

/// Which burn backend runs the maths.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Backend {
    /// burn's pure-Rust CPU backend (`burn-flex`); the default (see `any4d bench train`).
    Flex,
    /// The older `burn-ndarray` CPU backend, kept working for comparison and CI.
    Ndarray,
    /// A GPU through wgpu pinned to Vulkan (cargo feature `vulkan`).
    Vulkan,
    /// An NVIDIA GPU through CUDA (cargo feature `cuda`).
    Cuda,
}

/// Floating-point precision of parameters and activations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// 32-bit floats everywhere (docs/method.md §3.5, §4.7).
    F32,
    /// IEEE half precision (GPU backends; asked for explicitly). No loss scaling: for timing and inference.
    F16,
    /// bfloat16 (GPU backends where the device computes in it, e.g. cuda; asked for explicitly).
    Bf16,
}

/// One rayon pool per CPU worker, `max(1, threads / workers)` threads each, out of the current pool's threads.
/// burn-flex runs its matrix products on the current rayon pool and its element-wise kernels on the calling thread:
/// workers that shared one pool would queue their products behind each other while their element-wise work left
/// cores idle; with a pool each, two workers on two cores keep both busy.
pub fn worker_pools(workers: usize) -> Result<Vec<rayon::ThreadPool>, rayon::ThreadPoolBuildError> {
    let threads = (rayon::current_num_threads() / workers.max(1)).max(1);
    (0..workers)
        .map(|w| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .thread_name(move |i| format!("any4d-worker{w}-{i}"))
                .build()
        })
        .collect()
}

/// Errors of [`device`].
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    /// The binary was built without the cargo feature that carries this backend.
    #[error("backend `{backend}` is not compiled into this binary; rebuild with `--features {feature}`")]
    NotCompiled { backend: Backend, feature: &'static str },
    /// The precision cannot be used on this backend, or not for this job (the reason says which).
    #[error("precision `{precision}` refused on backend `{backend}`: {reason}")]
    Precision {
        backend: Backend,
        precision: Precision,
        reason: String,
    },
}

impl Backend {
    /// Every backend, in the order `--help` lists them.
    pub const ALL: [Backend; 4] = [Backend::Flex, Backend::Ndarray, Backend::Vulkan, Backend::Cuda];

    /// The CPU backend that `any4d bench train` measured faster on the tiny preset (see README).
    pub const DEFAULT_CPU: Backend = Backend::Flex;

    /// Whether this backend runs on the CPU.
    pub fn is_cpu(self) -> bool {
        matches!(self, Backend::Flex | Backend::Ndarray)
    }

    /// Workers that encode clips with a frozen VAE on this backend: one per core on a CPU (each on its share of the
    /// cores; the latents are the same as one worker's), one on a GPU.
    pub fn encoding_workers(self) -> usize {
        if self.is_cpu() { rayon::current_num_threads() } else { 1 }
    }
}

impl fmt::Display for Backend {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = match self {
            Backend::Flex => "flex",
            Backend::Ndarray => "ndarray",
            Backend::Vulkan => "vulkan",
            Backend::Cuda => "cuda",
        };
        f.write_str(name)
    }
}

impl std::str::FromStr for Backend {
    type Err = String;

    /// Parses the name [`Backend`]'s `Display` writes (`flex`, `ndarray`, `vulkan`, `cuda`), case-insensitively.
    fn from_str(name: &str) -> Result<Self, String> {
        Backend::ALL
            .into_iter()
            .find(|b| b.to_string().eq_ignore_ascii_case(name.trim()))
            .ok_or_else(|| format!("unknown backend `{name}` (flex, ndarray, vulkan, cuda)"))
    }
}

impl Precision {
    /// Every precision, in the order `--help` lists them.
    pub const ALL: [Precision; 3] = [Precision::F32, Precision::F16, Precision::Bf16];

    /// The burn float type of a half precision (`None` for f32, the device default).
    fn half_dtype(self) -> Option<burn::tensor::FloatDType> {
        match self {
            Precision::F32 => None,
            Precision::F16 => Some(burn::tensor::FloatDType::F16),
            Precision::Bf16 => Some(burn::tensor::FloatDType::BF16),
        }
    }
}

impl fmt::Display for Precision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Precision::F32 => "f32",
            Precision::F16 => "f16",
            Precision::Bf16 => "bf16",
        })
    }
}

impl std::str::FromStr for Precision {
    type Err = String;

    /// Parses `f32`, `f16` or `bf16`, case-insensitively.
    fn from_str(name: &str) -> Result<Self, String> {
        Precision::ALL
            .into_iter()
            .find(|p| p.to_string().eq_ignore_ascii_case(name.trim()))
            .ok_or_else(|| format!("unknown precision `{name}` (f32, f16, bf16)"))
    }
}

/// Activation bound where the device's memory is not known (GPU backends): 1 TiB, beyond any single device.
pub const MAX_ACTIVATION_BYTES: u128 = 1 << 40;

/// The inference device (no autodiff) for `backend` at `precision`. Call `.autodiff()` on it for training.
///
/// Precision must be configured before the first tensor exists on the device, so call this once, at start-up.
pub fn device(backend: Backend, precision: Precision) -> Result<Device, BackendError> {
    check(backend, precision)?;
    let device = base_device(backend)?;
    match precision.half_dtype() {
        None => Ok(device),
        Some(dtype) => half_device(backend, precision, dtype, device),
    }
}

/// Checks that `backend` at `precision` is available in this binary without touching the device (so that a run
/// folder is only created for a run that can start). Whether the GPU itself computes in a half precision is known
/// only once the device is opened ([`device`]).
pub fn check(backend: Backend, precision: Precision) -> Result<(), BackendError> {
    base_device(backend)?;
    if precision != Precision::F32 && backend.is_cpu() {
        return Err(BackendError::Precision {
            backend,
            precision,
            reason: "half precisions are offered on the GPU backends only (vulkan, cuda)".into(),
        });
    }
    Ok(())
}

/// [`check`] for a training run: f16 is offered for inference and timing only. Training keeps the parameters and
/// AdamW's moments in the device's float type, with no f32 master copy and no loss scaling, and in f16 that
/// diverges: the tiny and paper RF presets turned NaN by their second step (CPU, burn-flex in f16) and the paper
/// preset at its first on an H200 over Vulkan (`experiments/2026-12-04-gpu-half-fusion`).
pub fn check_training(backend: Backend, precision: Precision) -> Result<(), BackendError> {
    if precision == Precision::F16 {
        return Err(BackendError::Precision {
            backend,
            precision,
            reason: "training in f16 diverges (parameters and optimiser state in f16, no f32 master weights or loss \
                     scaling); train in f32, or in bf16 where the device computes in it"
                .into(),
        });
    }
    check(backend, precision)
}

#[allow(deprecated)] // burn-ndarray is deprecated in burn 0.22 but kept working
fn base_device(backend: Backend) -> Result<Device, BackendError> {
    match backend {
        Backend::Flex => Ok(Device::flex()),
        Backend::Ndarray => Ok(Device::ndarray()),
        #[cfg(feature = "vulkan")]
        Backend::Vulkan => Ok(Device::vulkan(burn::tensor::DeviceKind::DiscreteGpu(0))),
        #[cfg(not(feature = "vulkan"))]
        Backend::Vulkan => Err(BackendError::NotCompiled {
            backend,
            feature: "vulkan",
        }),
        #[cfg(feature = "cuda")]
        Backend::Cuda => Ok(Device::cuda(0)),
        #[cfg(not(feature = "cuda"))]
        Backend::Cuda => Err(BackendError::NotCompiled {
            backend,
            feature: "cuda",
        }),
    }
}

/// Half-precision parameters and activations (`Device::configure`, before any tensor exists on the device), after
/// asking the device whether it computes in that type (Vulkan devices often store bf16 without computing in it).
/// The calls are backend-generic, so this compiles (and is type-checked) in every build.
fn half_device(
    backend: Backend,
    precision: Precision,
    dtype: burn::tensor::FloatDType,
    mut device: Device,
) -> Result<Device, BackendError> {
    if !device.supports_dtype(dtype) {
        return Err(BackendError::Precision {
            backend,
            precision,
            reason: "this device does not compute in it".into(),
        });
    }
    device.configure(dtype).map_err(|err| BackendError::Precision {
        backend,
        precision,
        reason: format!("{err:?}"),
    })?;
    Ok(device)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_backends_build_devices_and_half_precisions_are_refused_on_cpu() {
        assert!(device(Backend::Flex, Precision::F32).is_ok());
        assert!(device(Backend::Ndarray, Precision::F32).is_ok());
        for half in [Precision::F16, Precision::Bf16] {
            for cpu in [Backend::Flex, Backend::Ndarray] {
                let err = device(cpu, half).unwrap_err();
                assert!(err.to_string().contains("GPU backends only"), "{cpu} {half}: {err}");
                assert!(check(cpu, half).is_err());
            }
        }
    }

    #[test]
    fn training_refuses_f16_on_every_backend_and_keeps_f32() {
        for b in Backend::ALL {
            let err = check_training(b, Precision::F16).unwrap_err();
            let msg = err.to_string();
            assert!(
                msg.contains("training in f16 diverges") && msg.contains("`f16`"),
                "{b}: {msg}"
            );
        }
        assert!(check_training(Backend::Flex, Precision::F32).is_ok());
        assert!(
            check_training(Backend::Flex, Precision::Bf16).is_err(),
            "half precisions stay GPU-only"
        );
    }

    #[test]
    fn names_round_trip_and_unknown_names_are_refused() {
        for b in Backend::ALL {
            assert_eq!(b.to_string().to_uppercase().parse::<Backend>(), Ok(b));
        }
        for p in Precision::ALL {
            assert_eq!(p.to_string().parse::<Precision>(), Ok(p));
        }
        assert!("tpu".parse::<Backend>().unwrap_err().contains("unknown backend `tpu`"));
        assert!("fp8".parse::<Precision>().unwrap_err().contains("f32, f16, bf16"));
    }

    #[cfg(not(feature = "cuda"))]
    #[test]
    fn missing_feature_names_the_feature() {
        let err = device(Backend::Cuda, Precision::F32).unwrap_err();
        assert!(err.to_string().contains("--features cuda"), "{err}");
    }
}

//! Compute backends picked at run time: burn 0.22 selects the backend through the `Device`
//! value, so one binary carries the CPU backends (`flex`, `ndarray`) and, behind cargo features, the GPU ones
//! (`vulkan`, `cuda`). Precision (docs/method.md §3.5, §4.7: FP32) is a device setting; bf16 only on cuda.

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
    /// bfloat16 (cuda only; asked for explicitly).
    Bf16,
}

/// Errors of [`device`].
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    /// The binary was built without the cargo feature that carries this backend.
    #[error("backend `{backend}` is not compiled into this binary; rebuild with `--features {feature}`")]
    NotCompiled { backend: Backend, feature: &'static str },
    /// The precision is not available on this backend.
    #[error("precision {precision:?} is not supported on backend `{backend}` ({reason})")]
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
    pub const ALL: [Precision; 2] = [Precision::F32, Precision::Bf16];
}

impl fmt::Display for Precision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Precision::F32 => "f32",
            Precision::Bf16 => "bf16",
        })
    }
}

impl std::str::FromStr for Precision {
    type Err = String;

    /// Parses `f32` or `bf16`, case-insensitively.
    fn from_str(name: &str) -> Result<Self, String> {
        Precision::ALL
            .into_iter()
            .find(|p| p.to_string().eq_ignore_ascii_case(name.trim()))
            .ok_or_else(|| format!("unknown precision `{name}` (f32, bf16)"))
    }
}

/// The inference device (no autodiff) for `backend` at `precision`. Call `.autodiff()` on it for training.
///
/// Precision must be configured before the first tensor exists on the device, so call this once, at start-up.
pub fn device(backend: Backend, precision: Precision) -> Result<Device, BackendError> {
    let device = base_device(backend)?;
    match precision {
        Precision::F32 => Ok(device),
        Precision::Bf16 => bf16_device(backend, device),
    }
}

/// Checks that `backend` at `precision` is available in this binary without touching the device (so that a run
/// folder is only created for a run that can start).
pub fn check(backend: Backend, precision: Precision) -> Result<(), BackendError> {
    base_device(backend)?;
    if precision == Precision::Bf16 && backend != Backend::Cuda {
        return Err(BackendError::Precision {
            backend,
            precision,
            reason: "bf16 training is offered on cuda only".into(),
        });
    }
    Ok(())
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

/// bf16 parameters and activations on cuda (`Device::configure`, before any tensor exists on the device). The
/// call is backend-generic, so this compiles (and is type-checked) in every build; only cuda is offered.
fn bf16_device(backend: Backend, mut device: Device) -> Result<Device, BackendError> {
    if backend != Backend::Cuda {
        return Err(BackendError::Precision {
            backend,
            precision: Precision::Bf16,
            reason: "bf16 training is offered on cuda only".into(),
        });
    }
    device
        .configure(burn::tensor::FloatDType::BF16)
        .map_err(|err| BackendError::Precision {
            backend,
            precision: Precision::Bf16,
            reason: format!("{err:?}"),
        })?;
    Ok(device)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_backends_build_devices_and_bf16_is_refused_on_cpu() {
        assert!(device(Backend::Flex, Precision::F32).is_ok());
        assert!(device(Backend::Ndarray, Precision::F32).is_ok());
        let err = device(Backend::Flex, Precision::Bf16).unwrap_err();
        assert!(err.to_string().contains("cuda only"), "{err}");
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
        assert!("f16".parse::<Precision>().is_err());
    }

    #[cfg(not(feature = "cuda"))]
    #[test]
    fn missing_feature_names_the_feature() {
        let err = device(Backend::Cuda, Precision::F32).unwrap_err();
        assert!(err.to_string().contains("--features cuda"), "{err}");
    }
}

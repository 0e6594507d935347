//! [`Device`]: where a tensor's values live and its ops run.

use std::fmt;
use std::str::FromStr;

/// Where a tensor lives: host memory (the reference implementation, `f32` and `f64`) or the
/// GPU (`f32`, through `wgpu`; needs the cargo feature `gpu`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Device {
    /// Host memory; kernels in `kernels/`, parallel through rayon.
    #[default]
    Cpu,
    /// The process's GPU (module `gpu`, feature `gpu`); kernels in `gpu/`.
    Gpu,
}

impl Device {
    /// The name used in configurations and on the command line (`cpu`, `gpu`).
    pub fn name(self) -> &'static str {
        match self {
            Device::Cpu => "cpu",
            Device::Gpu => "gpu",
        }
    }

    /// Whether this build has the device (the CPU always; the GPU with the feature `gpu`).
    pub fn is_built(self) -> bool {
        match self {
            Device::Cpu => true,
            Device::Gpu => crate::gpu::BUILT,
        }
    }

    /// Waits until every kernel queued on this device has finished (nothing to wait for on
    /// the CPU, whose kernels finish before they return). Profiles time GPU ops with it.
    pub fn synchronize(self) {
        if self == Device::Gpu {
            crate::gpu::synchronize();
        }
    }
}

impl fmt::Display for Device {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Device {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "cpu" => Ok(Device::Cpu),
            "gpu" => Ok(Device::Gpu),
            other => Err(format!("unknown device {other:?}: expected \"cpu\" or \"gpu\"")),
        }
    }
}

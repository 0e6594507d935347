//! Where a training's updates run: `device = "cpu"` (the default, the reference
//! arithmetic) or `device = "gpu"` (the cargo feature `gpu`, through `tensor`'s wgpu device).
//!
//! On the GPU the trainer keeps every team's parameters and Adam moments there for the whole
//! run; each minibatch is uploaded once, its forward and backward passes, the gradient checks,
//! clipping and the Adam step run there, and values come back only for GAE's values, the loss
//! statistics, the non-finite checks' verdicts and, once per iteration, the parameters the act
//! step reads ([`crate::mappo::trainer`]). The act step (collection, evaluation) and the
//! simulator stay on the CPU. The device is not part of a run's identity: a run started on one
//! device resumes on the other (the results differ by f32 rounding, not bit for bit).
//!
//! In a configuration the device is written as its name; `config.toml` leaves it out when it
//! is `cpu`, so the files of CPU runs read as before, also in earlier builds.

use serde::{Deserialize, Deserializer, Serializer};
use tensor::Device;

use crate::error::Result;

/// Checks that this build and machine can train on `device`: for the GPU, that the program
/// was built with the feature `gpu` and that a GPU adapter answers. Returns the adapter's
/// description for the GPU (`None` for the CPU). The errors say what to do: rebuild with the
/// feature, or (from `tensor`) what adapter was looked for and how to get one.
pub fn check_device(device: Device) -> Result<Option<String>> {
    match device {
        Device::Cpu => Ok(None),
        Device::Gpu => gpu_adapter(),
    }
}

#[cfg(feature = "gpu")]
fn gpu_adapter() -> Result<Option<String>> {
    Ok(Some(tensor::gpu::gpu()?.adapter().to_string()))
}

#[cfg(not(feature = "gpu"))]
fn gpu_adapter() -> Result<Option<String>> {
    Err(crate::error::RlError::config(
        "config",
        "device",
        "gpu",
        "this build has no GPU device: rebuild with --features gpu (cargo build --release -p rl --features gpu)",
    ))
}

/// Whether `device` is the CPU (the default, left out of `config.toml`).
pub fn is_cpu(device: &Device) -> bool {
    *device == Device::Cpu
}

/// Writes a device as its name (`cpu`, `gpu`).
pub fn serialize<S: Serializer>(device: &Device, s: S) -> std::result::Result<S::Ok, S::Error> {
    s.serialize_str(device.name())
}

/// Reads a device from its name; any other value is an error saying which are accepted.
pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> std::result::Result<Device, D::Error> {
    let name = String::deserialize(d)?;
    name.parse().map_err(serde::de::Error::custom)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cpu_is_always_there() {
        assert_eq!(check_device(Device::Cpu).unwrap(), None);
    }

    #[cfg(not(feature = "gpu"))]
    #[test]
    fn a_build_without_the_feature_says_how_to_get_the_gpu() {
        let e = check_device(Device::Gpu).unwrap_err().to_string();
        assert!(e.contains("device") && e.contains("rebuild with --features gpu"), "{e}");
    }
}

//! Where a training's updates run: `device = "cpu"` (the default, the reference
//! arithmetic) or `device = "gpu"` (the cargo feature `gpu`, through `tensor`'s wgpu device).
//!
//! On the GPU the trainer keeps every team's parameters and Adam moments there for the whole
//! run; each minibatch is uploaded once, its forward and backward passes, the gradient checks,
//! clipping and the Adam step run there, and values come back only for GAE's values, the loss
//! statistics, the non-finite checks' verdicts and, once per iteration, the parameters the act
//! step's host copy ([`crate::mappo::trainer`]). The simulator stays on the CPU. The device
//! is not part of a run's identity: a run started on one device resumes on the other (the
//! results differ by f32 rounding, not bit for bit).
//!
//! `act_device` says where the act step runs: with the updates (`same`, the default; on the
//! GPU the policy's forward pass of every collection step runs there on the parameters the
//! updates write, and only its means and scales come back) or on the CPU (`cpu`, the host
//! copy of the parameters). A training's periodic evaluations act where its collection does;
//! `meben eval` on the CPU unless `--device gpu`; rendering and the Python policy on the CPU.
//!
//! In a configuration the device is written as its name; `config.toml` leaves it out when it
//! is `cpu`, so the files of CPU runs read as before, also in earlier builds.

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use tensor::Device;

use crate::error::Result;

/// Checks that this build and machine can train on `device`: for the GPU, that the program
/// was built with the feature `gpu` and that a GPU adapter answers. Returns the adapter's
/// description for the GPU (`None` for the CPU). The errors say what to do: rebuild with the
/// feature, or (from `tensor`) what adapter was looked for and how to get one.
pub fn check_device(device: Device) -> Result<Option<String>> {
    if !device.is_built() {
        return Err(crate::error::RlError::config(
            "config",
            "device",
            device.name(),
            "this build has no GPU device: rebuild with --features gpu (cargo build --release -p rl --features gpu)",
        ));
    }
    Ok(device.adapter()?)
}

/// Where a training's act step runs (`act_device`): the policy's forward pass of every
/// collection step, on that step's observations.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ActDevice {
    /// Where the updates run (`device`), the default: with `device = "gpu"` the act step
    /// reads the parameters the updates write on the GPU, and only each step's means and
    /// scales come back (one transfer); sampling and log-probabilities stay on the host.
    #[default]
    Same,
    /// On the CPU whatever the updates' device: the act step reads the host copy of the
    /// parameters, refreshed after every update phase. A GPU run then collects exactly the
    /// rollout a CPU run would from the same state.
    Cpu,
}

impl ActDevice {
    /// Whether this is the default ([`ActDevice::Same`], left out of `config.toml`).
    pub fn is_same(&self) -> bool {
        *self == Self::Same
    }

    /// The name a configuration writes (`same`, `cpu`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Same => "same",
            Self::Cpu => "cpu",
        }
    }

    /// The device the act step runs on when the updates run on `update`.
    pub fn resolve(self, update: Device) -> Device {
        match self {
            Self::Same => update,
            Self::Cpu => Device::Cpu,
        }
    }
}

/// The values `act_device` takes, as an error names them.
const ACT_DEVICE_NAMES: &str = "\"same\" or \"cpu\"";

impl std::str::FromStr for ActDevice {
    type Err = String;

    /// `same` or `cpu`; anything else is an error naming the value and those two.
    fn from_str(s: &str) -> std::result::Result<ActDevice, String> {
        match s {
            "same" => Ok(ActDevice::Same),
            "cpu" => Ok(ActDevice::Cpu),
            _ => Err(format!("unknown act_device {s:?}: expected {ACT_DEVICE_NAMES}")),
        }
    }
}

/// Reads `act_device` from its name; any other value (`act_device = 1`, which serde's enum
/// reader called an `invalid type: unit variant`) is an error naming the accepted values.
impl<'de> Deserialize<'de> for ActDevice {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<ActDevice, D::Error> {
        struct Name;
        impl serde::de::Visitor<'_> for Name {
            type Value = ActDevice;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                write!(f, "{ACT_DEVICE_NAMES}")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> std::result::Result<ActDevice, E> {
                v.parse().map_err(E::custom)
            }
        }
        d.deserialize_str(Name)
    }
}

/// Whether `device` is the CPU (the default, left out of `config.toml`).
pub fn is_cpu(device: &Device) -> bool {
    device.is_host()
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

    #[test]
    fn a_build_without_the_feature_says_how_to_get_the_gpu() {
        if Device::Gpu.is_built() {
            return;
        }
        let e = check_device(Device::Gpu).unwrap_err().to_string();
        assert!(e.contains("device") && e.contains("rebuild with --features gpu"), "{e}");
    }

    /// Issue 77: `--set act_device=1` said `invalid type: unit variant`. A value of another
    /// type, or another name, names the accepted values.
    #[test]
    fn act_device_errors_name_the_accepted_values() {
        let resolve = |v: &str| {
            crate::mappo::config::TrainConfig::resolve(None, None, &[("act_device".into(), v.into())])
                .map(|c| c.act_device)
                .map_err(|e| e.to_string())
        };
        assert_eq!(resolve("\"cpu\"").unwrap(), ActDevice::Cpu);
        assert_eq!(resolve("same").unwrap(), ActDevice::Same);
        for bad in ["1", "gpu", "true"] {
            let e = resolve(bad).unwrap_err();
            assert!(e.contains("act_device") && e.contains(bad) && e.contains("\"same\" or \"cpu\""), "{e}");
            assert!(!e.contains("unit variant"), "{e}");
        }
    }
}

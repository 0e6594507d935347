//! The `device`, `act_device` and GPU kernel-choice fields of a training configuration, in
//! any build: their validation, their place in `config.toml` (absent at their defaults, so
//! existing files read and compare as before), and that they are not part of a run's
//! identity (a checkpoint written on one device resumes on the other).

use crate::common;

use std::path::Path;

use rl::mappo::device::ActDevice;
use rl::{Preset, TrainConfig, Trainer};
use tensor::Device;

#[test]
fn an_unknown_device_is_an_error_naming_the_field_and_the_value() {
    let ov = [("device".to_string(), "tpu".to_string())];
    let e = TrainConfig::resolve(Some(Preset::Quick), None, &ov).unwrap_err().to_string();
    for w in ["command line", "`device`", "tpu", "\"cpu\" or \"gpu\""] {
        assert!(e.contains(w), "{e} (missing {w})");
    }
    let tmp = common::TempDir::new("device-config");
    let path = tmp.0.join("config.toml");
    let text = TrainConfig::preset(Preset::Quick, "team_reach/1_ant").to_toml();
    std::fs::write(&path, format!("{text}device = \"tpu\"\n")).unwrap();
    let e = TrainConfig::load(&path).unwrap_err().to_string();
    for w in ["config.toml", "device", "tpu", "\"cpu\" or \"gpu\""] {
        assert!(e.contains(w), "{e} (missing {w})");
    }
}

#[test]
fn the_device_is_written_only_when_it_is_the_gpu_and_read_in_any_build() {
    let cpu = TrainConfig::preset(Preset::Quick, "team_reach/1_ant");
    assert_eq!(cpu.device, Device::Cpu);
    assert!(!cpu.to_toml().contains("device"), "config.toml of CPU runs is unchanged");
    assert_eq!(cpu.to_full_table()["device"].as_str(), Some("cpu"), "a field a file or --set may name");
    let gpu = TrainConfig { device: Device::Gpu, ..cpu.clone() };
    assert!(gpu.to_toml().contains("device = \"gpu\""));
    // A GPU run's configuration reads in a build without the GPU (eval, report, render).
    let tmp = common::TempDir::new("device-load");
    let path = tmp.0.join("config.toml");
    gpu.save(&path).unwrap();
    assert_eq!(TrainConfig::load(&path).unwrap(), gpu);
    cpu.save(&path).unwrap();
    assert_eq!(TrainConfig::load(&path).unwrap(), cpu);
    let set = [("device".to_string(), "gpu".to_string())];
    assert_eq!(TrainConfig::resolve(Some(Preset::Quick), None, &set).unwrap(), gpu);
}

/// `act_device`: `same` by default and then absent from `config.toml` (files written before
/// the field read as `same`), `cpu` written and read back, from a file or `--set`; another
/// value is an error naming the field, the value and the accepted ones. It resolves to the
/// updates' device or the CPU, and a checkpoint resumes under the other value.
#[test]
fn the_act_device_is_written_only_away_from_its_default_and_is_not_part_of_a_runs_identity() {
    let same = TrainConfig::preset(Preset::Quick, "team_reach/1_ant");
    assert_eq!(same.act_device, ActDevice::Same);
    assert!(!same.to_toml().contains("act_device"), "config.toml of existing runs is unchanged");
    assert_eq!(same.to_full_table()["act_device"].as_str(), Some("same"), "a field a file or --set may name");
    let cpu = TrainConfig { act_device: ActDevice::Cpu, ..same.clone() };
    assert!(cpu.to_toml().contains("act_device = \"cpu\""));
    let tmp = common::TempDir::new("act-device");
    let path = tmp.0.join("config.toml");
    cpu.save(&path).unwrap();
    assert_eq!(TrainConfig::load(&path).unwrap(), cpu);
    let set = |v: &str| TrainConfig::resolve(Some(Preset::Quick), None, &[("act_device".to_string(), v.to_string())]);
    assert_eq!(set("cpu").unwrap(), cpu);
    assert_eq!(set("\"same\"").unwrap(), same);
    let e = set("gpu").unwrap_err().to_string();
    for w in ["command line", "act_device", "gpu", "same", "cpu"] {
        assert!(e.contains(w), "{e} (missing {w})");
    }
    std::fs::write(&path, format!("{}act_device = \"tpu\"\n", same.to_toml())).unwrap();
    let e = TrainConfig::load(&path).unwrap_err().to_string();
    for w in ["config.toml", "act_device", "tpu"] {
        assert!(e.contains(w), "{e} (missing {w})");
    }
    assert_eq!(ActDevice::Same.resolve(Device::Gpu), Device::Gpu);
    assert_eq!(ActDevice::Cpu.resolve(Device::Gpu), Device::Cpu);
    assert_eq!(ActDevice::Same.resolve(Device::Cpu), Device::Cpu);
    // Not part of the run's identity: a checkpoint of either value resumes, to the same bits
    // on the CPU (where both act on the CPU).
    let config = common::tiny("team_reach/1_ant", "mlp_hn", 2, &[("num_evals", "0")]);
    let mut t = Trainer::new(&config).unwrap();
    t.iterate().unwrap();
    let state = t.checkpoint(0.0, &[]).unwrap();
    let on_cpu = TrainConfig { act_device: ActDevice::Cpu, ..config };
    let mut resumed = Trainer::from_checkpoint(&state, &on_cpu, Path::new("checkpoint.json")).unwrap();
    assert_eq!(resumed.config.act_device, ActDevice::Cpu);
    assert_eq!(resumed.iterate().unwrap().losses, t.iterate().unwrap().losses);
}

/// A checkpoint whose configuration says `gpu` resumes on the CPU (the device is not part
/// of the run's identity, as `threads` is not).
#[test]
fn a_checkpoint_of_the_other_device_resumes() {
    let config = common::tiny("team_reach/1_ant", "mlp_hn", 2, &[("num_evals", "0")]);
    let mut t = Trainer::new(&config).unwrap();
    t.iterate().unwrap();
    let mut state = t.checkpoint(0.0, &[]).unwrap();
    state.config.device = Device::Gpu;
    let mut resumed = Trainer::from_checkpoint(&state, &config, Path::new("checkpoint.json")).unwrap();
    assert_eq!(resumed.config.device, Device::Cpu);
    assert_eq!(resumed.iterate().unwrap().losses, t.iterate().unwrap().losses);
    // Another learning rate is still refused.
    let other = TrainConfig { learning_rate: 1e-3, ..config.clone() };
    let e = Trainer::from_checkpoint(&state, &other, Path::new("checkpoint.json")).err().unwrap().to_string();
    assert!(e.contains("learning_rate") && !e.contains("device"), "{e}");
    // So is a field `config.toml` writes only away from its default, which the error used
    // to leave unnamed ("was written by another configuration: " and nothing).
    let per_slot = TrainConfig { train_starts: rl::TrainStarts::PerSlot, ..config };
    let e = Trainer::from_checkpoint(&state, &per_slot, Path::new("checkpoint.json")).err().unwrap().to_string();
    assert!(e.contains("train_starts = \"fresh\" in the checkpoint, \"per_slot\" now"), "{e}");
}

/// Without the feature `gpu`, asking for the GPU says how to get it.
#[cfg(not(feature = "gpu"))]
#[test]
fn a_build_without_the_gpu_says_to_rebuild() {
    let config = TrainConfig { device: Device::Gpu, ..common::tiny("team_reach/1_ant", "mlp_hn", 1, &[]) };
    let e = Trainer::new(&config).err().unwrap().to_string();
    assert!(e.contains("device") && e.contains("rebuild with --features gpu"), "{e}");
}

/// The GPU's kernel choices (`gpu_matmul_tile`, `gpu_reduce_lanes`): absent from
/// `config.toml` at their defaults, written and read back otherwise, from a file or `--set`;
/// a bad value is an error naming the field and the value; a trainer hands them to the
/// device (`tensor::gpu_config`); and they are not part of a run's identity.
#[test]
fn the_gpu_kernel_choices_are_typed_settings_of_the_configuration() {
    let quick = TrainConfig::preset(Preset::Quick, "team_reach/1_ant");
    assert_eq!((quick.gpu_matmul_tile, quick.gpu_reduce_lanes), (64, 256));
    let toml = quick.to_toml();
    assert!(!toml.contains("gpu_matmul_tile") && !toml.contains("gpu_reduce_lanes"), "existing files unchanged");
    assert_eq!(quick.to_full_table()["gpu_reduce_lanes"].as_integer(), Some(256));
    let set = |k: &str, v: &str| TrainConfig::resolve(Some(Preset::Quick), None, &[(k.to_string(), v.to_string())]);
    let tall = set("gpu_matmul_tile", "128").unwrap();
    assert!(tall.to_toml().contains("gpu_matmul_tile = 128"));
    let tmp = common::TempDir::new("gpu-config");
    let path = tmp.0.join("config.toml");
    tall.save(&path).unwrap();
    assert_eq!(TrainConfig::load(&path).unwrap(), tall);
    for (k, v) in [("gpu_matmul_tile", "96"), ("gpu_reduce_lanes", "3"), ("gpu_reduce_lanes", "512")] {
        let e = set(k, v).unwrap_err().to_string();
        assert!(e.contains(k) && e.contains(v), "{e} (missing {k} or {v})");
    }
    let typed = set("gpu_reduce_lanes", "1").unwrap().gpu_config("test").unwrap();
    assert_eq!(typed, tensor::GpuConfig { matmul_tile: tensor::MatMulTile::Rows64, reduce_lanes: 1 });
    // Handed to the device by the trainer, and resumable under other values. (Only the tile
    // is changed here: it gives the same bits, so the process's GPU tests running beside this
    // one cannot be disturbed by it.)
    let config = common::tiny("team_reach/1_ant", "mlp_hn", 2, &[("num_evals", "0"), ("gpu_matmul_tile", "128")]);
    let mut t = Trainer::new(&config).unwrap();
    assert_eq!(tensor::gpu_config().matmul_tile, tensor::MatMulTile::Rows128);
    t.iterate().unwrap();
    let state = t.checkpoint(0.0, &[]).unwrap();
    let other = TrainConfig { gpu_matmul_tile: 64, ..config };
    let mut resumed = Trainer::from_checkpoint(&state, &other, Path::new("checkpoint.json")).unwrap();
    assert_eq!(tensor::gpu_config(), tensor::GpuConfig::default());
    assert_eq!(resumed.iterate().unwrap().losses, t.iterate().unwrap().losses);
}

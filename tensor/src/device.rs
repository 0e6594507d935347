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

    /// Whether this is the host (the CPU), whose tensors are plain memory.
    pub fn is_host(self) -> bool {
        self == Device::Cpu
    }

    /// Whether this build has the device (the CPU always; the GPU with the feature `gpu`).
    pub fn is_built(self) -> bool {
        match self {
            Device::Cpu => true,
            Device::Gpu => crate::gpu::BUILT,
        }
    }

    /// A description of the device's adapter (`None` for the host, which needs none); an
    /// error saying what was looked for and how to get one when the device is missing (no
    /// adapter, or a build without it).
    pub fn adapter(self) -> crate::error::Result<Option<String>> {
        match self {
            Device::Cpu => Ok(None),
            Device::Gpu => crate::gpu::adapter_description().map(Some),
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

/// What crossed between the host and a device, and the kernels launched there, since the
/// process started ([`transfers`]): the explicit transfers of a training step, counted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Transfers {
    /// Host-to-device copies.
    pub uploads: u64,
    /// Bytes uploaded.
    pub upload_bytes: u64,
    /// Device-to-host copies.
    pub downloads: u64,
    /// Bytes downloaded.
    pub download_bytes: u64,
    /// Kernel launches on the device.
    pub launches: u64,
}

impl Transfers {
    /// The counts since `earlier` (a reading taken before).
    pub fn since(&self, earlier: &Transfers) -> Transfers {
        Transfers {
            uploads: self.uploads - earlier.uploads,
            upload_bytes: self.upload_bytes - earlier.upload_bytes,
            downloads: self.downloads - earlier.downloads,
            download_bytes: self.download_bytes - earlier.download_bytes,
            launches: self.launches - earlier.launches,
        }
    }
}

impl fmt::Display for Transfers {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} uploads ({} bytes), {} downloads ({} bytes), {} launches",
            self.uploads, self.upload_bytes, self.downloads, self.download_bytes, self.launches
        )
    }
}

/// The process's transfers so far (all zeros while no device other than the host was used,
/// and in a build without the feature `gpu`).
pub fn transfers() -> Transfers {
    crate::gpu::transfers()
}

/// The rows of the GPU's tiled product's output tile ([`GpuConfig::matmul_tile`]). Both give
/// the same bits (each output is the same sequence of fused multiply-adds); they differ in
/// speed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum MatMulTile {
    /// 64 x 64 tiles, 4 x 4 outputs a thread (the default, timed on an H100 and an H200).
    #[default]
    Rows64,
    /// 128 x 64 tiles, 8 x 4 outputs a thread, for the products with enough of them.
    Rows128,
}

impl MatMulTile {
    /// Output rows of one workgroup's tile (64 or 128), as configurations write it.
    pub fn rows(self) -> usize {
        match self {
            MatMulTile::Rows64 => 64,
            MatMulTile::Rows128 => 128,
        }
    }

    /// The tile of `rows` output rows; an error naming the value unless 64 or 128.
    pub fn from_rows(rows: usize) -> Result<Self, String> {
        match rows {
            64 => Ok(MatMulTile::Rows64),
            128 => Ok(MatMulTile::Rows128),
            other => Err(format!("matmul tile {other} is neither 64 nor 128")),
        }
    }
}

/// The GPU's kernel choices: a typed setting the training configuration (or a benchmark's
/// command line) hands the device with [`configure_gpu`], never read from the environment
/// inside a kernel. Where a choice changes bits, the training records it in `config.toml`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct GpuConfig {
    /// The tiled product's output tile (the same bits either way).
    pub matmul_tile: MatMulTile,
    /// The most threads that share one output of a reduction: a power of two from 1 to 256
    /// (1: one thread per output). Changes the order of the sums, so the bits.
    pub reduce_lanes: u32,
}

impl Default for GpuConfig {
    fn default() -> Self {
        GpuConfig { matmul_tile: MatMulTile::Rows64, reduce_lanes: GpuConfig::MAX_REDUCE_LANES }
    }
}

impl GpuConfig {
    /// The most threads per reduction output (a workgroup).
    pub const MAX_REDUCE_LANES: u32 = 256;

    /// Checks every value; the error names the field and the value.
    pub fn validate(&self) -> Result<(), String> {
        let lanes = self.reduce_lanes;
        if !lanes.is_power_of_two() || lanes > Self::MAX_REDUCE_LANES {
            return Err(format!("reduce_lanes = {lanes} is not a power of two from 1 to {}", Self::MAX_REDUCE_LANES));
        }
        Ok(())
    }
}

impl GpuConfig {
    /// The choices a benchmark program takes from its environment: `TENSOR_GPU_MATMUL_TILE`
    /// (64 or 128) and `TENSOR_GPU_REDUCE_LANES` (a power of two from 1 to 256), the defaults
    /// where unset; an error naming the variable and value. For benchmark programs and
    /// scripts that pair settings: the library itself never reads the environment.
    pub fn from_bench_env() -> Result<GpuConfig, String> {
        let mut config = GpuConfig::default();
        if let Ok(v) = std::env::var("TENSOR_GPU_MATMUL_TILE") {
            let tile = v.trim().parse::<usize>().ok().and_then(|rows| MatMulTile::from_rows(rows).ok());
            config.matmul_tile = tile.ok_or_else(|| format!("TENSOR_GPU_MATMUL_TILE={v:?} is neither 64 nor 128"))?;
        }
        if let Ok(v) = std::env::var("TENSOR_GPU_REDUCE_LANES") {
            let bad =
                || format!("TENSOR_GPU_REDUCE_LANES={v:?} is not a power of two from 1 to {}", Self::MAX_REDUCE_LANES);
            config.reduce_lanes = v.trim().parse::<u32>().map_err(|_| bad())?;
            config.validate().map_err(|_| bad())?;
        }
        Ok(config)
    }
}

/// The process's GPU kernel choices (packed: the tile's rows, then the lanes).
static GPU_CONFIG: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(pack(GpuConfig {
    matmul_tile: MatMulTile::Rows64,
    reduce_lanes: GpuConfig::MAX_REDUCE_LANES,
}));

/// `config` as one word.
const fn pack(config: GpuConfig) -> u64 {
    let tile = match config.matmul_tile {
        MatMulTile::Rows64 => 64u64,
        MatMulTile::Rows128 => 128,
    };
    (tile << 32) | config.reduce_lanes as u64
}

/// Sets the GPU's kernel choices for the kernels launched from now on (in a build without the
/// feature `gpu` it is only recorded); an error naming the field and value when one is out
/// of range, and nothing changes then.
pub fn configure_gpu(config: GpuConfig) -> Result<(), String> {
    config.validate()?;
    GPU_CONFIG.store(pack(config), std::sync::atomic::Ordering::Relaxed);
    Ok(())
}

/// The GPU's kernel choices now in force ([`configure_gpu`]; the defaults until it is
/// called).
pub fn gpu_config() -> GpuConfig {
    let word = GPU_CONFIG.load(std::sync::atomic::Ordering::Relaxed);
    let matmul_tile = if word >> 32 == 128 { MatMulTile::Rows128 } else { MatMulTile::Rows64 };
    GpuConfig { matmul_tile, reduce_lanes: (word & 0xffff_ffff) as u32 }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bad setting is refused with the field and value and leaves the old one in force;
    /// a good one is read back.
    #[test]
    fn gpu_config_is_checked_and_read_back() {
        let before = gpu_config();
        for bad in [0, 3, 512] {
            let err = configure_gpu(GpuConfig { reduce_lanes: bad, ..before }).unwrap_err();
            assert!(err.contains("reduce_lanes") && err.contains(&bad.to_string()), "{err}");
            assert_eq!(gpu_config(), before);
        }
        assert!(MatMulTile::from_rows(96).unwrap_err().contains("96"));
        let set = GpuConfig { matmul_tile: MatMulTile::Rows128, reduce_lanes: 1 };
        configure_gpu(set).unwrap();
        assert_eq!(gpu_config(), set);
        configure_gpu(before).unwrap();
    }
}

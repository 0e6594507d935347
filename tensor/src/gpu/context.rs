//! The one GPU context of the process: adapter, device, queue, compiled kernels and a pool of
//! free buffers. Every kernel launch goes through `Gpu::launch`.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use crate::error::{Result, TensorError};
use crate::gpu::timing::{self, KernelTimeline, OpLabel, TimedLaunch, Timing};

/// Threads per workgroup of the one-dimensional kernels (`@workgroup_size(256)` in WGSL).
pub(crate) const WORKGROUP: u32 = 256;
/// Launches recorded into one command buffer before it is submitted (submits cost tens of
/// microseconds each on a real GPU; a batch bounds how long the GPU waits for work).
const LAUNCHES_PER_SUBMIT: usize = 64;
/// 32-bit words of the parameter arena one batch of launches reads its parameters from.
const ARENA_WORDS: usize = 1 << 16;
/// Bytes of one chunk of the upload staging belt (a larger upload gets a chunk of its own
/// size, kept for reuse like the others).
const STAGING_CHUNK_BYTES: u64 = 16 << 20;
/// The most workgroups along one dimension of a dispatch (WebGPU's guaranteed limit).
const MAX_GROUPS_PER_DIM: u32 = 65_535;

/// The adapter a [`Gpu`] runs on, as the driver reports it.
#[derive(Clone, Debug)]
pub struct AdapterInfo {
    /// The adapter's name (e.g. `NVIDIA H100 80GB HBM3`, `llvmpipe (LLVM 15.0.6, 256 bits)`).
    pub name: String,
    /// The API wgpu drives it through (`Vulkan`, `Metal`, `Dx12`).
    pub backend: String,
    /// Discrete, integrated, virtual or CPU (lavapipe reports `Cpu`).
    pub device_type: String,
    /// The driver's name and version, when the driver says.
    pub driver: String,
}

impl std::fmt::Display for AdapterInfo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({}, {}", self.name, self.backend, self.device_type)?;
        if !self.driver.is_empty() {
            write!(f, ", {}", self.driver)?;
        }
        write!(f, ")")
    }
}

/// Counters of what the device has done since the process started.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GpuStats {
    /// Kernel launches.
    pub launches: u64,
    /// Host-to-device copies (uploads of tensors).
    pub uploads: u64,
    /// Bytes uploaded.
    pub upload_bytes: u64,
    /// Device-to-host copies (reads of tensors).
    pub downloads: u64,
    /// Bytes downloaded.
    pub download_bytes: u64,
    /// Buffer requests served from the pool.
    pub pool_hits: u64,
    /// Buffer requests that created a buffer.
    pub pool_misses: u64,
}

/// The GPU device: created once per process by [`gpu`], shared by every tensor on it.
pub struct Gpu {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    info: AdapterInfo,
    limits: wgpu::Limits,
    pipelines: Mutex<HashMap<&'static str, Arc<wgpu::ComputePipeline>>>,
    free: Mutex<HashMap<u64, Vec<wgpu::Buffer>>>,
    stats: Mutex<GpuStats>,
    pending: Mutex<Pending>,
    /// Whether the device was given timestamp queries ([`Gpu::start_timing`]).
    timestamps: bool,
}

/// Launches recorded but not yet submitted. Ordering rules that keep a batch correct:
/// commands inside one command buffer run in order (wgpu inserts the barriers), so a buffer
/// freed to the pool may be reused at once as a later kernel's output; `queue.write_buffer`
/// runs before the next submit's commands, so it must never write a pooled buffer that a
/// recorded launch still reads: an upload is written into mapped staging memory (wgpu's
/// `StagingBelt`: chunks allocated once and reused, where `queue.write_buffer` stages each
/// write in a staging buffer of its own) and copied into its buffer by a command recorded
/// in order. Every launch's parameters go into this batch's own arena,
/// written just before the batch is submitted.
struct Pending {
    encoder: Option<wgpu::CommandEncoder>,
    /// The parameters of the recorded launches, each at a 256-byte-aligned offset.
    params: Vec<u32>,
    /// The buffer `params` is written to when the batch is submitted.
    arena: wgpu::Buffer,
    /// Staging memory of the batch's uploads.
    belt: wgpu::util::StagingBelt,
    /// Whether the batch has staged an upload (the belt is closed before the submit and
    /// recalled after it).
    staged: bool,
    launches: usize,
    /// The launches' timestamps while [`Gpu::start_timing`] is on.
    timing: Option<Timing>,
}

/// The process's GPU, initialised on first use: the first adapter wgpu offers on Vulkan,
/// Metal or DX12 (high-performance preference). An error says what was looked for and how to
/// get an adapter; it is remembered, so a missing GPU is reported the same way every time.
pub fn gpu() -> Result<&'static Gpu> {
    GPU.get_or_init(Gpu::create).as_ref().map_err(|detail| TensorError::Device { op: "gpu", detail: detail.clone() })
}

/// The process's GPU, or its creation's error, once [`gpu`] was first called.
static GPU: OnceLock<std::result::Result<Gpu, String>> = OnceLock::new();

/// The process's GPU if it was started (without starting it).
pub(crate) fn started() -> Option<&'static Gpu> {
    GPU.get().and_then(|g| g.as_ref().ok())
}

/// Bytes of a buffer holding `n` 32-bit words (never 0: WebGPU cannot bind an empty buffer).
pub(crate) fn words_to_bytes(n: usize) -> u64 {
    (n.max(1) * 4) as u64
}

impl Gpu {
    fn create() -> std::result::Result<Gpu, String> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        desc.backends = wgpu::Backends::VULKAN | wgpu::Backends::METAL | wgpu::Backends::DX12;
        let instance = wgpu::Instance::new(desc);
        let options = wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            ..Default::default()
        };
        let adapter = pollster::block_on(instance.request_adapter(&options)).map_err(|e| {
            format!(
                "no GPU adapter found ({e}); looked for Vulkan, Metal or DX12 through wgpu. Install \
                 your GPU's driver with its Vulkan support, or, to test without a GPU, Mesa's \
                 lavapipe (Debian/Ubuntu: apt-get install mesa-vulkan-drivers libvulkan1)"
            )
        })?;
        let ai = adapter.get_info();
        let info = AdapterInfo {
            name: ai.name.clone(),
            backend: format!("{:?}", ai.backend),
            device_type: format!("{:?}", ai.device_type),
            driver: [ai.driver.as_str(), ai.driver_info.as_str()]
                .iter()
                .filter(|s| !s.is_empty())
                .copied()
                .collect::<Vec<_>>()
                .join(" "),
        };
        // The adapter's own limits: the default 128 MiB binding limit is smaller than the
        // activations of a paper-sized batch.
        let limits = adapter.limits();
        // Timestamp queries, where the adapter has them, for `start_timing` (they cost nothing
        // until a pass asks for one).
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("tensor"),
            required_features: if timestamps { wgpu::Features::TIMESTAMP_QUERY } else { wgpu::Features::empty() },
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| format!("the GPU adapter {info} refused a device: {e}"))?;
        let arena = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("parameters"),
            size: words_to_bytes(ARENA_WORDS),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let belt = wgpu::util::StagingBelt::new(device.clone(), STAGING_CHUNK_BYTES);
        Ok(Gpu {
            device,
            queue,
            info,
            limits,
            pipelines: Mutex::new(HashMap::new()),
            free: Mutex::new(HashMap::new()),
            stats: Mutex::new(GpuStats::default()),
            pending: Mutex::new(Pending {
                encoder: None,
                params: Vec::new(),
                arena,
                belt,
                staged: false,
                launches: 0,
                timing: None,
            }),
            timestamps,
        })
    }

    /// The adapter this device runs on.
    pub fn adapter(&self) -> &AdapterInfo {
        &self.info
    }

    /// Counters since the process started.
    pub fn stats(&self) -> GpuStats {
        *self.stats.lock().expect("gpu stats lock")
    }

    pub(crate) fn count(&self, f: impl FnOnce(&mut GpuStats)) {
        f(&mut self.stats.lock().expect("gpu stats lock"));
    }

    /// Checks that a buffer of `n` f32 values can be bound on this device.
    pub(crate) fn check_size(&self, op: &'static str, n: usize) -> Result<()> {
        let bytes = words_to_bytes(n);
        let max = self.limits.max_storage_buffer_binding_size.min(self.limits.max_buffer_size);
        if bytes > max || n > u32::MAX as usize {
            return Err(TensorError::Device {
                op,
                detail: format!(
                    "a tensor of {n} values ({bytes} bytes) is larger than the {max} bytes a buffer \
                     can hold on {}",
                    self.info
                ),
            });
        }
        Ok(())
    }

    /// A buffer of `n` 32-bit words with unspecified contents (recycled when one of that size
    /// is free).
    pub(crate) fn alloc(&self, n: usize) -> wgpu::Buffer {
        let bytes = words_to_bytes(n);
        if let Some(b) = self.free.lock().expect("gpu pool lock").get_mut(&bytes).and_then(Vec::pop) {
            self.count(|s| s.pool_hits += 1);
            return b;
        }
        self.count(|s| s.pool_misses += 1);
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// A buffer of `n` zeros.
    pub(crate) fn alloc_zeroed(&self, n: usize) -> wgpu::Buffer {
        let b = self.alloc(n);
        let mut pending = self.pending.lock().expect("gpu batch lock");
        self.encoder(&mut pending.encoder).clear_buffer(&b, 0, None);
        b
    }

    /// The batch's command encoder in `slot` (a new one when none is open).
    fn encoder<'p>(&self, slot: &'p mut Option<wgpu::CommandEncoder>) -> &'p mut wgpu::CommandEncoder {
        slot.get_or_insert_with(|| self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None }))
    }

    /// Submits the recorded launches (their parameters first).
    fn flush_locked(&self, pending: &mut Pending) {
        if let Some(mut enc) = pending.encoder.take() {
            if let Some(t) = pending.timing.as_mut() {
                self.resolve_timestamps(&mut enc, t);
            }
            if !pending.params.is_empty() {
                self.queue.write_buffer(&pending.arena, 0, bytemuck::cast_slice(&pending.params));
            }
            if pending.staged {
                pending.belt.finish();
            }
            self.queue.submit([enc.finish()]);
            if pending.staged {
                // The chunks come back for reuse once the GPU has copied them (the map
                // callbacks run at a poll: this one, or the next wait).
                pending.belt.recall();
                pending.staged = false;
                let _ = self.device.poll(wgpu::PollType::Poll);
            }
            pending.params.clear();
            pending.launches = 0;
        }
    }

    /// Records the copy of the open batch's timestamps into a buffer of their own, read
    /// when timing stops.
    fn resolve_timestamps(&self, enc: &mut wgpu::CommandEncoder, t: &mut Timing) {
        let (Some(set), n) = (t.open.take(), std::mem::take(&mut t.open_launches)) else {
            return;
        };
        let bytes = u64::from(n) * 2 * wgpu::QUERY_SIZE as u64;
        let buffer = |usage| {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps"),
                size: bytes,
                usage,
                mapped_at_creation: false,
            })
        };
        let resolved = buffer(wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC);
        let readback = buffer(wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
        enc.resolve_query_set(&set, 0..2 * n, &resolved, 0);
        enc.copy_buffer_to_buffer(&resolved, 0, &readback, 0, bytes);
        t.resolved.push((readback, n));
    }

    /// Starts timing every kernel launch on the GPU's own clock (module
    /// [`crate::gpu::timing`]) until [`Gpu::stop_timing`]. Launches are not waited for, so
    /// they run as they do untimed. An error if the adapter has no timestamp queries.
    pub fn start_timing(&self) -> Result<()> {
        if !self.timestamps {
            return Err(TensorError::Device {
                op: "start_timing",
                detail: format!("the GPU adapter {} has no timestamp queries (wgpu's TIMESTAMP_QUERY)", self.info),
            });
        }
        let mut pending = self.pending.lock().expect("gpu batch lock");
        self.flush_locked(&mut pending);
        pending.timing = Some(Timing::new());
        timing::ACTIVE.store(true, std::sync::atomic::Ordering::Relaxed);
        Ok(())
    }

    /// Whether launches are being timed ([`Gpu::start_timing`]).
    pub fn timing(&self) -> bool {
        self.pending.lock().expect("gpu batch lock").timing.is_some()
    }

    /// Gives `op` (an op's name, and whether its gradient rule ran; `None`: made outside a
    /// tape) to the launches timed since the last label; nothing when timing is off. Tapes
    /// call it after each op.
    pub fn label_launches(&self, op: OpLabel) {
        if let Some(t) = self.pending.lock().expect("gpu batch lock").timing.as_mut() {
            t.label(op);
        }
    }

    /// Runs `f` with every launch timed ([`Gpu::start_timing`] .. [`Gpu::stop_timing`]):
    /// its result and the timeline of its kernels.
    pub fn timed<R>(&self, f: impl FnOnce() -> R) -> Result<(R, KernelTimeline)> {
        self.start_timing()?;
        let r = f();
        Ok((r, self.stop_timing()?))
    }

    /// Stops timing, waits for the GPU and reads every launch's start and end: the
    /// [`KernelTimeline`] since [`Gpu::start_timing`]. An error if timing was not on.
    pub fn stop_timing(&self) -> Result<KernelTimeline> {
        let t = {
            let mut pending = self.pending.lock().expect("gpu batch lock");
            self.flush_locked(&mut pending);
            pending.timing.take()
        };
        timing::ACTIVE.store(false, std::sync::atomic::Ordering::Relaxed);
        let Some(t) = t else {
            return Err(TensorError::Device {
                op: "stop_timing",
                detail: "timing was not started (Gpu::start_timing)".into(),
            });
        };
        let (tx, rx) = std::sync::mpsc::channel();
        for (buf, _) in &t.resolved {
            let tx = tx.clone();
            buf.slice(..).map_async(wgpu::MapMode::Read, move |r| {
                let _ = tx.send(r);
            });
        }
        drop(tx);
        self.device.poll(wgpu::PollType::wait_indefinitely()).expect("the GPU device was lost");
        for r in rx {
            r.map_err(|e| TensorError::Device { op: "stop_timing", detail: format!("reading the timestamps: {e}") })?;
        }
        let mut ticks = Vec::with_capacity(t.launches.len());
        for (buf, n) in &t.resolved {
            let view = buf.slice(..).get_mapped_range().expect("mapped above");
            let words: &[u64] = bytemuck::cast_slice(&view);
            ticks.extend((0..*n as usize).map(|i| (words[2 * i], words[2 * i + 1])));
        }
        Ok(KernelTimeline::new(&t.launches, &ticks, f64::from(self.queue.get_timestamp_period())))
    }

    /// Submits every launch recorded so far.
    pub(crate) fn flush(&self) {
        self.flush_locked(&mut self.pending.lock().expect("gpu batch lock"));
    }

    /// Gives a buffer back for reuse. At most 64 free buffers of one size are kept.
    pub(crate) fn recycle(&self, b: wgpu::Buffer) {
        let mut free = self.free.lock().expect("gpu pool lock");
        let list = free.entry(b.size()).or_default();
        if list.len() < 64 {
            list.push(b);
        }
    }

    /// A buffer holding `words` (32-bit values: f32 bits or u32 indices).
    pub(crate) fn upload_words(&self, words: &[u32]) -> wgpu::Buffer {
        let b = self.alloc(words.len());
        if let Some(size) = wgpu::BufferSize::new((words.len() * 4) as u64) {
            // Staged, and copied by a command recorded in the batch's order (Pending).
            let mut guard = self.pending.lock().expect("gpu batch lock");
            let pending = &mut *guard;
            let encoder = self.encoder(&mut pending.encoder);
            pending.belt.write_buffer(encoder, &b, 0, size).copy_from_slice(bytemuck::cast_slice(words));
            pending.staged = true;
        }
        self.count(|s| {
            s.uploads += 1;
            s.upload_bytes += words.len() as u64 * 4;
        });
        b
    }

    /// The first `n` 32-bit words of `b`, copied to the host (waits for every kernel queued
    /// before).
    pub(crate) fn download_words(&self, b: &wgpu::Buffer, n: usize) -> Vec<u32> {
        self.download_many(&[(b, n)]).pop().expect("one buffer asked for")
    }

    /// The first `n` words of each buffer, in one transfer: every copy into one staging
    /// buffer, one wait, one map (counted as one download of all their bytes).
    pub(crate) fn download_many(&self, parts: &[(&wgpu::Buffer, usize)]) -> Vec<Vec<u32>> {
        let total: usize = parts.iter().map(|&(_, n)| n).sum();
        if total == 0 {
            return parts.iter().map(|_| Vec::new()).collect();
        }
        let bytes = (total * 4) as u64;
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("download"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        {
            let mut pending = self.pending.lock().expect("gpu batch lock");
            let mut at = 0u64;
            for &(b, n) in parts {
                let len = (n * 4) as u64;
                if len > 0 {
                    self.encoder(&mut pending.encoder).copy_buffer_to_buffer(b, 0, &staging, at, len);
                }
                at += len;
            }
            self.flush_locked(&mut pending);
        }
        let slice = staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device.poll(wgpu::PollType::wait_indefinitely()).expect("the GPU device was lost");
        rx.recv().expect("map callback ran").expect("the GPU device could not map a buffer for reading");
        let out = {
            let view = slice.get_mapped_range().expect("mapped above");
            let words = bytemuck::cast_slice::<u8, u32>(&view);
            let mut at = 0;
            parts
                .iter()
                .map(|&(_, n)| {
                    at += n;
                    words[at - n..at].to_vec()
                })
                .collect()
        };
        staging.unmap();
        self.count(|s| {
            s.downloads += 1;
            s.download_bytes += bytes;
        });
        out
    }

    /// The compiled kernel `entry` of the WGSL module `source` (compiled once; `name` is
    /// the cache key and the label in driver messages).
    fn pipeline(&self, name: &'static str, source: &'static str, entry: &'static str) -> Arc<wgpu::ComputePipeline> {
        let mut cache = self.pipelines.lock().expect("gpu pipeline lock");
        cache
            .entry(name)
            .or_insert_with(|| {
                let module = self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some(name),
                    source: wgpu::ShaderSource::Wgsl(source.into()),
                });
                Arc::new(self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(name),
                    layout: None,
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                }))
            })
            .clone()
    }

    /// Runs one kernel: binding 0 is a read-only array of u32 `params`, bindings 1.. are
    /// `buffers` in order (as the kernel declares them), and the grid is `groups` workgroups
    /// laid out as `(x, y)` with `x <= 65535` (kernels rebuild the linear workgroup index as
    /// `wg.x + wg.y * num_workgroups.x`).
    pub(crate) fn launch(&self, kernel: &Kernel, params: &[u32], buffers: &[&wgpu::Buffer], groups: u32) {
        if groups == 0 {
            return;
        }
        let pipeline = self.pipeline(kernel.name, kernel.source, kernel.entry);
        let mut pending = self.pending.lock().expect("gpu batch lock");
        // This launch's parameters at the next 256-byte boundary of the arena (WebGPU's
        // storage-offset alignment); a full arena submits the batch first.
        let align = (self.limits.min_storage_buffer_offset_alignment as usize / 4).max(1);
        let words = params.len().max(1);
        if pending.params.len().next_multiple_of(align) + words > ARENA_WORDS || pending.launches >= LAUNCHES_PER_SUBMIT
        {
            self.flush_locked(&mut pending);
        }
        let offset = pending.params.len().next_multiple_of(align);
        pending.params.resize(offset, 0);
        pending.params.extend_from_slice(params);
        pending.params.resize(offset + words, 0);
        let binding = wgpu::BufferBinding {
            buffer: &pending.arena,
            offset: (offset * 4) as u64,
            size: std::num::NonZeroU64::new((words * 4) as u64),
        };
        let mut entries = vec![wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::Buffer(binding) }];
        for (i, b) in buffers.iter().enumerate() {
            entries.push(wgpu::BindGroupEntry { binding: i as u32 + 1, resource: b.as_entire_binding() });
        }
        let bind = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(kernel.name),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        let x = groups.min(MAX_GROUPS_PER_DIM);
        let y = groups.div_ceil(x);
        // While timing: this launch's start and end at the next two queries of the batch's set.
        let timed = pending.timing.as_mut().map(|t| {
            let set = t.open.get_or_insert_with(|| {
                self.device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 2 * LAUNCHES_PER_SUBMIT as u32,
                })
            });
            let first = 2 * t.open_launches;
            t.open_launches += 1;
            t.launches.push(TimedLaunch { kernel: kernel.name, op: None });
            (set.clone(), first)
        });
        {
            let timestamp_writes = timed.as_ref().map(|(set, first)| wgpu::ComputePassTimestampWrites {
                query_set: set,
                beginning_of_pass_write_index: Some(*first),
                end_of_pass_write_index: Some(first + 1),
            });
            let enc = self.encoder(&mut pending.encoder);
            let mut pass =
                enc.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(kernel.name), timestamp_writes });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        pending.launches += 1;
        drop(pending);
        self.count(|s| s.launches += 1);
    }

    /// [`Gpu::launch`] with one thread per element for `n` elements (workgroups of
    /// [`WORKGROUP`] threads).
    pub(crate) fn launch_1d(&self, kernel: &Kernel, params: &[u32], buffers: &[&wgpu::Buffer], n: usize) {
        self.launch(kernel, params, buffers, (n as u32).div_ceil(WORKGROUP));
    }

    /// Waits until every queued kernel has finished.
    pub fn synchronize(&self) {
        self.flush();
        self.device.poll(wgpu::PollType::wait_indefinitely()).expect("the GPU device was lost");
    }
}

/// A compute kernel: an entry point of a WGSL module.
pub(crate) struct Kernel {
    /// Unique name (the pipeline cache's key).
    pub name: &'static str,
    /// The WGSL module.
    pub source: &'static str,
    /// The entry point's name.
    pub entry: &'static str,
}

//! Recycling of large element buffers.
//!
//! A training step allocates and frees the same large activations (tens of MB) again and
//! again. General-purpose allocators tend to hand such blocks back to the operating system,
//! which then zeroes every page again on the next touch (measured: 8-15% of a training step
//! in the kernel's page clearing). Tensors therefore return buffers of at least
//! [`MIN_POOLED`] elements to a per-type pool when their storage is dropped, and kernels take
//! their output buffers from it.

use std::collections::VecDeque;
use std::sync::Mutex;

use crate::element::Float;

/// Buffers smaller than this (in elements) are left to the allocator.
pub const MIN_POOLED: usize = 1 << 16;
/// The least the pool may keep per element type (the cap where the machine's memory is not
/// known, or is small).
const MIN_CAP_BYTES: usize = 4 << 30;

/// At most this many bytes are kept per element type; beyond it the buffers given back
/// longest ago are freed first (a buffer of a size nobody asks for again, such as a one-off
/// input, ages out instead of filling the pool for good). `TENSOR_POOL_MAX_MB` (MiB) when
/// set; else a third of the machine's memory (`/proc/meminfo`), at least 4 GiB. A training
/// step whose buffers do not all fit frees and allocates again every step, and the kernel
/// clears the fresh pages (`PoolStats::evicted` grows step after step): the 7.1 GB step of
/// `shtransformer` on `team_reach/2_ants` did under the former fixed 4 GiB.
pub fn max_pooled_bytes() -> usize {
    static CAP: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    *CAP.get_or_init(|| {
        let set = std::env::var("TENSOR_POOL_MAX_MB").ok();
        cap_bytes(set.as_deref(), physical_memory_bytes()).unwrap_or_else(|msg| {
            eprintln!("tensor: {msg}; the buffer pool keeps its default cap");
            cap_bytes(None, physical_memory_bytes()).unwrap_or(MIN_CAP_BYTES)
        })
    })
}

/// The cap for a `TENSOR_POOL_MAX_MB` setting (`None`: unset) on a machine of `memory`
/// bytes; an error naming the variable and value when it is not a whole number of MiB.
fn cap_bytes(setting: Option<&str>, memory: Option<usize>) -> Result<usize, String> {
    match setting {
        Some(v) => v
            .trim()
            .parse::<usize>()
            .map(|mb| mb.saturating_mul(1 << 20))
            .map_err(|_| format!("TENSOR_POOL_MAX_MB={v:?} is not a whole number of MiB")),
        None => Ok((memory.unwrap_or(0) / 3).max(MIN_CAP_BYTES)),
    }
}

/// The machine's memory (`MemTotal` of `/proc/meminfo`), where the system says it.
fn physical_memory_bytes() -> Option<usize> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kb: usize = line.split_whitespace().nth(1)?.parse().ok()?;
    kb.checked_mul(1024)
}

/// What a pool has done since the process started: a researcher's check that a training step
/// reuses its buffers (`misses` should stop growing after the first steps).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PoolStats {
    /// Requests for a pooled size served from a free buffer.
    pub hits: u64,
    /// Requests for a pooled size that had to allocate.
    pub misses: u64,
    /// Buffers freed to make room (oldest first).
    pub evicted: u64,
    /// Bytes held in free buffers now.
    pub pooled_bytes: usize,
    /// The most bytes ever held in free buffers.
    pub peak_pooled_bytes: usize,
}

/// The free buffers of one element type, oldest first, and the pool's counters.
struct Free<T> {
    buffers: VecDeque<Vec<T>>,
    stats: PoolStats,
}

/// A set of free buffers of one element type.
pub struct BufferPool<T> {
    free: Mutex<Free<T>>,
}

impl<T> BufferPool<T> {
    /// An empty pool (usable in a `static`).
    pub const fn new() -> Self {
        Self {
            free: Mutex::new(Free {
                buffers: VecDeque::new(),
                stats: PoolStats { hits: 0, misses: 0, evicted: 0, pooled_bytes: 0, peak_pooled_bytes: 0 },
            }),
        }
    }
}

impl<T> Default for BufferPool<T> {
    fn default() -> Self {
        Self::new()
    }
}

/// The counters of the pool of element type `T`.
pub fn stats<T: Float>() -> PoolStats {
    T::pool().free.lock().map(|f| f.stats).unwrap_or_default()
}

/// An empty vector with capacity for at least `n` elements, recycled when one fits (the
/// smallest free buffer of capacity between `n` and `2n`).
pub fn with_capacity<T: Float>(n: usize) -> Vec<T> {
    match take(n) {
        Some(mut v) => {
            v.clear();
            v
        }
        None => Vec::with_capacity(n),
    }
}

/// The smallest free buffer of capacity between `n` and `2n`, as it was recycled (its old
/// length and contents), if `n` is large enough to be pooled and one is free.
fn take<T: Float>(n: usize) -> Option<Vec<T>> {
    if n < MIN_POOLED {
        return None;
    }
    T::pool().free.lock().ok()?.take(n)
}

impl<T> Free<T> {
    /// The smallest free buffer of capacity between `n` and `2n`, counted as a hit or a miss.
    fn take(&mut self, n: usize) -> Option<Vec<T>> {
        let best = self
            .buffers
            .iter()
            .enumerate()
            .filter(|(_, v)| v.capacity() >= n && v.capacity() <= 2 * n)
            .min_by_key(|(_, v)| v.capacity())
            .map(|(i, _)| i);
        let Some(v) = best.and_then(|i| self.buffers.remove(i)) else {
            self.stats.misses += 1;
            return None;
        };
        self.stats.hits += 1;
        self.stats.pooled_bytes -= v.capacity() * std::mem::size_of::<T>();
        Some(v)
    }

    /// Keeps `v` as the newest free buffer, first freeing the oldest ones while the pool would
    /// hold more than `cap` bytes (a buffer over `cap` on its own is freed at once).
    fn put(&mut self, v: Vec<T>, cap: usize) {
        let bytes = v.capacity() * std::mem::size_of::<T>();
        if bytes > cap {
            return;
        }
        while self.stats.pooled_bytes + bytes > cap {
            let Some(old) = self.buffers.pop_front() else { break };
            self.stats.pooled_bytes -= old.capacity() * std::mem::size_of::<T>();
            self.stats.evicted += 1;
        }
        self.buffers.push_back(v);
        self.stats.pooled_bytes += bytes;
        self.stats.peak_pooled_bytes = self.stats.peak_pooled_bytes.max(self.stats.pooled_bytes);
    }
}

/// A vector of `n` elements with unspecified values, for a kernel that overwrites every one:
/// recycled storage keeps whatever it held (only a tail beyond its old length is zeroed), so
/// the output is not written twice. Never read an element before writing it.
pub fn for_overwrite<T: Float>(n: usize) -> Vec<T> {
    match take(n) {
        Some(mut v) => {
            v.resize(n, T::ZERO); // truncates, or zeroes only the new tail
            v
        }
        None => vec![T::ZERO; n],
    }
}

/// A vector of `n` copies of `value` (recycled storage when possible).
pub fn filled<T: Float>(n: usize, value: T) -> Vec<T> {
    let mut v = with_capacity(n);
    v.resize(n, value);
    v
}

/// A vector of `n` zeros (recycled storage when possible).
pub fn zeros<T: Float>(n: usize) -> Vec<T> {
    filled(n, T::ZERO)
}

/// Gives a buffer back for reuse (small ones are simply freed).
pub fn recycle<T: Float>(v: Vec<T>) {
    if v.capacity() < MIN_POOLED {
        return;
    }
    if let Ok(mut free) = T::pool().free.lock() {
        free.put(v, max_pooled_bytes());
    }
}

/// `f` applied to every element of `x`, into a recycled buffer.
pub fn map<T: Float>(x: &[T], f: impl Fn(T) -> T) -> Vec<T> {
    let mut v = with_capacity(x.len());
    v.extend(x.iter().map(|&a| f(a)));
    v
}

/// `f` applied to pairs of elements of `x` and `y` (equal lengths), into a recycled buffer.
pub fn zip_map<T: Float, U: Copy>(x: &[T], y: &[U], f: impl Fn(T, U) -> T) -> Vec<T> {
    let mut v = with_capacity(x.len());
    v.extend(x.iter().zip(y).map(|(&a, &b)| f(a, b)));
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn large_buffers_are_reused_and_handed_out_clean() {
        let n = MIN_POOLED * 3 + 5;
        let mut v: Vec<f64> = filled(n, 7.0);
        v[0] = 1.0;
        let ptr = v.as_ptr();
        recycle(v);
        // A request of the same size gets the same storage back, zeroed.
        let z: Vec<f64> = zeros(n);
        assert_eq!(z.as_ptr(), ptr);
        assert!(z.iter().all(|&x| x == 0.0));
        assert_eq!(z.len(), n);
        recycle(z);
        // A much smaller request does not take the large buffer (at most 2x its size).
        let small: Vec<f64> = zeros(n / 3);
        assert_ne!(small.as_ptr(), ptr);
        // Small buffers are not pooled at all.
        let tiny: Vec<f64> = zeros(10);
        recycle(tiny);
        let again: Vec<f64> = with_capacity(n);
        assert_eq!(again.as_ptr(), ptr);
        assert!(again.is_empty());
    }

    #[test]
    fn buffers_for_overwriting_keep_their_contents_and_zero_a_new_tail() {
        // f64 and a size no other unit test asks for (the pools are global and the GPU
        // kernels' tests use f32 buffers of similar sizes at the same time); the first test's
        // sizes are at most half of this one's.
        let n = MIN_POOLED * 7 + 3;
        let mut v: Vec<f64> = filled(n, 5.0);
        let ptr = v.as_ptr();
        v.truncate(n - 10);
        recycle(v);
        // Longer than the recycled length: the old values, then zeros.
        let w: Vec<f64> = for_overwrite(n);
        assert_eq!((w.as_ptr(), w.len()), (ptr, n));
        assert!(w[..n - 10].iter().all(|&x| x == 5.0) && w[n - 10..].iter().all(|&x| x == 0.0));
        recycle(w);
        // Shorter: truncated.
        let u: Vec<f64> = for_overwrite(n - 100);
        assert_eq!((u.as_ptr(), u.len()), (ptr, n - 100));
    }

    #[test]
    fn the_cap_is_a_third_of_the_memory_or_the_setting() {
        let gib = 1usize << 30;
        assert_eq!(cap_bytes(None, Some(24 * gib)), Ok(8 * gib));
        // Never under 4 GiB, also where the memory is unknown.
        assert_eq!(cap_bytes(None, Some(6 * gib)), Ok(4 * gib));
        assert_eq!(cap_bytes(None, None), Ok(4 * gib));
        assert_eq!(cap_bytes(Some(" 512 "), Some(24 * gib)), Ok(512 << 20));
        assert_eq!(cap_bytes(Some("0"), None), Ok(0));
        let err = cap_bytes(Some("8GB"), None).unwrap_err();
        assert!(err.contains("TENSOR_POOL_MAX_MB") && err.contains("8GB"), "{err}");
        // This machine says its memory (Linux), and the cap in force is at least 4 GiB
        // unless set.
        if cfg!(target_os = "linux") {
            assert!(physical_memory_bytes().is_some_and(|m| m > 0));
        }
        if std::env::var_os("TENSOR_POOL_MAX_MB").is_none() {
            assert!(max_pooled_bytes() >= 4 * gib);
        }
    }

    #[test]
    fn a_full_pool_frees_its_oldest_buffers_and_counts_what_it_does() {
        let mut free = Free::<f32> { buffers: VecDeque::new(), stats: PoolStats::default() };
        let kb = |v: &Vec<f32>| v.capacity() * 4;
        let (a, b, c) = (vec![1.0f32; 1000], vec![2.0f32; 2000], vec![3.0f32; 1500]);
        let (pa, pb, pc) = (a.as_ptr(), b.as_ptr(), c.as_ptr());
        let cap = kb(&b) + kb(&c) + 100;
        free.put(a, cap);
        free.put(b, cap);
        assert_eq!((free.stats.pooled_bytes, free.stats.evicted), (12000, 0));
        // `c` does not fit beside both: the oldest (`a`) goes, `b` stays.
        free.put(c, cap);
        assert_eq!((free.stats.evicted, free.stats.pooled_bytes, free.stats.peak_pooled_bytes), (1, 14000, 14000));
        assert!(free.buffers.iter().all(|v| v.as_ptr() != pa));
        // Requests are served by size (capacity between n and 2n), counted as hits and misses.
        assert_eq!(free.take(1400).map(|v| v.as_ptr()), Some(pc));
        assert!(free.take(5000).is_none());
        assert_eq!(free.take(1000).map(|v| v.as_ptr()), Some(pb));
        assert_eq!((free.stats.hits, free.stats.misses, free.stats.pooled_bytes), (2, 1, 0));
        // A buffer over the cap on its own is not kept.
        free.put(vec![0.0f32; 10_000], cap);
        assert_eq!((free.buffers.len(), free.stats.evicted), (0, 1));
    }
}

//! Index lists kept on the device while they recur.
//!
//! The index ops (`index_select`, `index_add`, `gather`, the segment ops and their adjoints)
//! take their index lists from the host. A model's lists are the same from one call to the
//! next: the edges of a graph feed every message-passing layer, forward and backward, and
//! every minibatch of one size has the same graph. Uploading each list per call, and
//! rebuilding the sorted source lists of a scatter on the host per call, was most of the
//! index ops' cost at paper sizes (`docs/PERFORMANCE.md`). [`ListCache`] keeps what was
//! derived from a list (its device copy, or a scatter's CSR lists), keyed by the list's
//! contents and what was derived: a call whose list equals a kept one (compared in full,
//! never by hash alone) reuses its buffers, so results are the same bits as uploading again.
//! The least recently used entries go when the kept lists exceed a size bound.

use std::sync::{Arc, Mutex};

/// What an entry derived from its list, with the sizes the derivation depends on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum ListKind {
    /// The indices as u32.
    Indices,
    /// A scatter's CSR lists (`dests`, `offsets`, `srcs`) into `n` destinations of an axis.
    Scatter { n: usize },
    /// The CSR lists of `gather`'s adjoint over `[outer, n, inner]` from `[outer, m, inner]`.
    GatherScatter { outer: usize, n: usize, inner: usize, m: usize },
    /// A segment reduction's row offsets and `1 / count` scales, `num_segments` segments.
    SegmentRows { num_segments: usize },
    /// A segment adjoint's ids (as u32) and scales, `num_segments` segments.
    SegmentIds { num_segments: usize },
}

/// One kept derivation.
struct Entry<V> {
    kind: ListKind,
    hash: u64,
    key: Vec<u32>,
    value: Arc<V>,
    words: usize,
    used: u64,
}

/// Values derived from index lists, keyed by `(kind, list)` (module docs), least recently
/// used first out once more than `max_words` words (keys and values) are kept.
pub(crate) struct ListCache<V> {
    entries: Vec<Entry<V>>,
    words: usize,
    max_words: usize,
    clock: u64,
}

/// A 64-bit hash of a kind and list (FxHash-style steps): a quick filter before the full
/// comparison.
fn hash_list(kind: ListKind, key: &[u32]) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    kind.hash(&mut h);
    let mut x = h.finish();
    for &w in key {
        x = (x.rotate_left(5) ^ u64::from(w)).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
    x
}

impl<V> ListCache<V> {
    /// An empty cache keeping at most `max_words` words.
    pub(crate) const fn new(max_words: usize) -> Self {
        Self { entries: Vec::new(), words: 0, max_words, clock: 0 }
    }

    /// The kept value derived from `key` as `kind`, if any (marked as just used).
    fn find(&mut self, kind: ListKind, hash: u64, key: &[u32]) -> Option<Arc<V>> {
        self.clock += 1;
        let clock = self.clock;
        let e = self.entries.iter_mut().find(|e| e.kind == kind && e.hash == hash && e.key == key)?;
        e.used = clock;
        Some(e.value.clone())
    }

    /// Keeps `value` (of `value_words` words) for `key`, then drops the least recently used
    /// entries until the bound holds. An entry larger than the bound is not kept.
    fn insert(&mut self, kind: ListKind, hash: u64, key: Vec<u32>, value: Arc<V>, value_words: usize) {
        let words = key.len() + value_words;
        if words > self.max_words {
            return;
        }
        self.clock += 1;
        self.words += words;
        self.entries.push(Entry { kind, hash, key, value, words, used: self.clock });
        while self.words > self.max_words {
            let oldest =
                (0..self.entries.len()).min_by_key(|&i| self.entries[i].used).expect("over the bound, so not empty");
            let gone = self.entries.swap_remove(oldest);
            self.words -= gone.words;
        }
    }

    /// Number of kept entries.
    #[cfg(test)]
    fn len(&self) -> usize {
        self.entries.len()
    }
}

/// The value derived from `idx` as `kind`: the kept one when `cache` holds the same list
/// for the same kind, else `build(list as u32)` (returning the value and its size in
/// words), kept for later calls. `cache` is locked only to look up and to insert, not while
/// building.
pub(crate) fn derived<V>(
    cache: &Mutex<ListCache<V>>,
    kind: ListKind,
    idx: &[usize],
    build: impl FnOnce(&[u32]) -> (V, usize),
) -> Arc<V> {
    let key: Vec<u32> = idx.iter().map(|&i| u32::try_from(i).expect("device indices fit in u32")).collect();
    let hash = hash_list(kind, &key);
    if let Some(v) = cache.lock().unwrap_or_else(|e| e.into_inner()).find(kind, hash, &key) {
        return v;
    }
    let (value, words) = build(&key);
    let value = Arc::new(value);
    cache.lock().unwrap_or_else(|e| e.into_inner()).insert(kind, hash, key, value.clone(), words);
    value
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cache of built values counting the builds.
    fn get(cache: &Mutex<ListCache<Vec<u32>>>, kind: ListKind, idx: &[usize], builds: &mut usize) -> Arc<Vec<u32>> {
        derived(cache, kind, idx, |k| {
            *builds += 1;
            (k.iter().map(|v| v * 2).collect(), k.len())
        })
    }

    #[test]
    fn equal_lists_reuse_what_was_built_and_other_lists_or_kinds_do_not() {
        let cache = Mutex::new(ListCache::new(1000));
        let mut builds = 0;
        let a = get(&cache, ListKind::Indices, &[3, 1, 2], &mut builds);
        let again = get(&cache, ListKind::Indices, &[3, 1, 2], &mut builds);
        assert_eq!(builds, 1);
        assert!(Arc::ptr_eq(&a, &again));
        assert_eq!(*a, vec![6, 2, 4]);
        get(&cache, ListKind::Indices, &[3, 1, 4], &mut builds);
        get(&cache, ListKind::Scatter { n: 5 }, &[3, 1, 2], &mut builds);
        get(&cache, ListKind::Scatter { n: 6 }, &[3, 1, 2], &mut builds);
        get(&cache, ListKind::Indices, &[3, 1], &mut builds);
        assert_eq!(builds, 5);
        assert_eq!(cache.lock().unwrap().len(), 5);
    }

    #[test]
    fn the_least_recently_used_lists_go_first_past_the_bound() {
        // Each entry is 2 (key) + 2 (value) words; the bound holds two.
        let cache = Mutex::new(ListCache::new(8));
        let mut builds = 0;
        get(&cache, ListKind::Indices, &[0, 0], &mut builds);
        get(&cache, ListKind::Indices, &[1, 1], &mut builds);
        get(&cache, ListKind::Indices, &[0, 0], &mut builds); // used again: [1, 1] is older
        get(&cache, ListKind::Indices, &[2, 2], &mut builds); // evicts [1, 1]
        assert_eq!((builds, cache.lock().unwrap().len()), (3, 2));
        get(&cache, ListKind::Indices, &[0, 0], &mut builds);
        get(&cache, ListKind::Indices, &[2, 2], &mut builds);
        assert_eq!(builds, 3, "kept lists were rebuilt");
        get(&cache, ListKind::Indices, &[1, 1], &mut builds);
        assert_eq!(builds, 4, "an evicted list was found");
        // A list larger than the bound is built, returned and not kept, nor does it push
        // the kept ones out.
        let big = get(&cache, ListKind::Indices, &[5; 10], &mut builds);
        assert_eq!((big.len(), builds), (10, 5));
        let kept = cache.lock().unwrap();
        assert_eq!((kept.len(), kept.words), (2, 8));
        drop(kept);
        get(&cache, ListKind::Indices, &[1, 1], &mut builds);
        get(&cache, ListKind::Indices, &[2, 2], &mut builds);
        assert_eq!(builds, 5);
    }
}

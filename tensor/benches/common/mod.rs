//! What the `tensor` benches share: the median of timed calls.

use std::time::Instant;

/// Timed calls of one measurement.
pub const SAMPLES: usize = 15;

/// The median wall time of `f` in milliseconds over [`SAMPLES`] calls, after 3 warm-up calls.
#[allow(dead_code)]
pub fn median_ms(mut f: impl FnMut()) -> f64 {
    for _ in 0..3 {
        f();
    }
    let mut t: Vec<f64> = (0..SAMPLES)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[SAMPLES / 2]
}

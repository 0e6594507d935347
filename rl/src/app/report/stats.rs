//! The statistics of a group's final values: mean ± standard error (and the standard
//! deviation, which the paper's tables give), and, since a handful of
//! seeds is all a group has, the interquartile mean and percentile-bootstrap confidence
//! intervals that rliable (Agarwal et al., "Deep RL at the Edge of the Statistical
//! Precipice", NeurIPS 2021) recommends for few runs.
//!
//! - [`iqm`]: rliable's `aggregate_iqm`, i.e. scipy's `trim_mean(x, 0.25)`: sort, drop
//!   `floor(n / 4)` values from each end, average the rest (no fractional weights: with 1
//!   to 3 runs it is the mean; with 4 or 5 it drops the lowest and the highest).
//! - [`bootstrap_ci`]: the percentile bootstrap over runs: [`BOOTSTRAP_RESAMPLES`]
//!   resamples of `n` runs drawn with replacement, the statistic of each, and the 2.5th and
//!   97.5th percentiles of those (numpy's linear interpolation between order statistics).
//!   The resamples come from a ChaCha8 stream with the fixed seed [`BOOTSTRAP_SEED`], so a
//!   report is the same every time it is written.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Resamples of a bootstrap interval.
pub const BOOTSTRAP_RESAMPLES: usize = 2000;

/// Seed of the bootstrap's random stream (module docs).
pub const BOOTSTRAP_SEED: u64 = 0;

/// Mean and standard error (sample standard deviation / sqrt(n); 0 for one value) of
/// `values`; `(NaN, NaN)` for none.
pub fn mean_and_se(values: &[f64]) -> (f64, f64) {
    let (mean, var) = mean_and_variance(values);
    (mean, (var / values.len() as f64).sqrt())
}

/// Mean and sample standard deviation (divisor n - 1; 0 for one value) of `values`;
/// `(NaN, NaN)` for none.
pub fn mean_and_sd(values: &[f64]) -> (f64, f64) {
    let (mean, var) = mean_and_variance(values);
    (mean, var.sqrt())
}

/// Mean and sample variance (divisor n - 1; 0 for one value); `(NaN, NaN)` for none.
fn mean_and_variance(values: &[f64]) -> (f64, f64) {
    let n = values.len();
    if n == 0 {
        return (f64::NAN, f64::NAN);
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    if n == 1 {
        return (mean, 0.0);
    }
    (mean, values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64)
}

/// The mean of `values` (NaN for none).
pub fn mean(values: &[f64]) -> f64 {
    mean_and_se(values).0
}

/// The interquartile mean of `values` (module docs); NaN for none.
pub fn iqm(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let cut = sorted.len() / 4;
    mean(&sorted[cut..sorted.len() - cut])
}

/// The 95% percentile-bootstrap confidence interval `(low, high)` of `statistic` over
/// `values` (module docs); `(NaN, NaN)` for none.
pub fn bootstrap_ci(values: &[f64], statistic: fn(&[f64]) -> f64) -> (f64, f64) {
    let n = values.len();
    if n == 0 {
        return (f64::NAN, f64::NAN);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(BOOTSTRAP_SEED);
    let mut sample = vec![0.0; n];
    let mut stats: Vec<f64> = (0..BOOTSTRAP_RESAMPLES)
        .map(|_| {
            for s in sample.iter_mut() {
                // Drawn as u64, so that the stream is the same on 32- and 64-bit machines.
                *s = values[rng.random_range(0..n as u64) as usize];
            }
            statistic(&sample)
        })
        .collect();
    stats.sort_by(f64::total_cmp);
    (percentile(&stats, 2.5), percentile(&stats, 97.5))
}

/// The `q`-th percentile (0 to 100) of the sorted, non-empty `sorted`, interpolating
/// linearly between the order statistics (numpy's default).
fn percentile(sorted: &[f64], q: f64) -> f64 {
    let at = q / 100.0 * (sorted.len() - 1) as f64;
    let (lo, hi) = (at.floor() as usize, at.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (at - lo as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_standard_error() {
        let (m, s) = mean_and_se(&[10.0, 20.0, 30.0]);
        assert!((m - 20.0).abs() < 1e-12);
        // sample std 10, / sqrt(3)
        assert!((s - 10.0 / 3f64.sqrt()).abs() < 1e-12);
        assert_eq!(mean_and_se(&[7.0]), (7.0, 0.0));
        assert!(mean_and_se(&[]).0.is_nan());
        let (m, sd) = mean_and_sd(&[10.0, 20.0, 30.0]);
        assert!((m - 20.0).abs() < 1e-12 && (sd - 10.0).abs() < 1e-12);
        assert_eq!(mean_and_sd(&[7.0]), (7.0, 0.0));
        assert!(mean_and_sd(&[]).1.is_nan());
    }

    /// Values by hand (and scipy.stats.trim_mean(x, 0.25), rliable's IQM).
    #[test]
    fn the_interquartile_mean_drops_a_quarter_of_the_runs_at_each_end() {
        // Fewer than 4 runs: nothing to drop.
        assert_eq!(iqm(&[50.0, 60.0, 90.0]), mean(&[50.0, 60.0, 90.0]));
        assert_eq!(iqm(&[7.0]), 7.0);
        // 4 runs: the middle two, in any order.
        assert_eq!(iqm(&[100.0, 0.0, 40.0, 20.0]), 30.0);
        // 5 runs: drops 1 at each end.
        assert_eq!(iqm(&[1.0, 2.0, 3.0, 4.0, 1000.0]), 3.0);
        // 8 runs: drops 2 at each end, the mean of 3, 4, 5, 6.
        assert_eq!(iqm(&[8.0, 1.0, 7.0, 2.0, 6.0, 3.0, 5.0, 4.0]), 4.5);
        // 10 runs: floor(10 / 4) = 2 at each end, the mean of the middle 6.
        let ten: Vec<f64> = (1..=10).map(f64::from).collect();
        assert_eq!(iqm(&ten), 5.5);
        assert!(iqm(&[]).is_nan());
    }

    #[test]
    fn percentiles_interpolate_linearly_between_order_statistics() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(percentile(&v, 0.0), 1.0);
        assert_eq!(percentile(&v, 50.0), 3.0);
        assert_eq!(percentile(&v, 100.0), 5.0);
        // numpy.percentile([1, 2, 3, 4, 5], 2.5) = 1.1, 97.5 -> 4.9
        assert!((percentile(&v, 2.5) - 1.1).abs() < 1e-12);
        assert!((percentile(&v, 97.5) - 4.9).abs() < 1e-12);
    }

    #[test]
    fn bootstrap_intervals_are_deterministic_and_behave() {
        let v = [50.0, 60.0, 90.0, 75.0, 40.0];
        let (lo, hi) = bootstrap_ci(&v, mean);
        // The same interval every time (a fixed stream).
        assert_eq!(bootstrap_ci(&v, mean), (lo, hi));
        // It holds the mean, and lies within the range of the data.
        assert!(lo < mean(&v) && mean(&v) < hi, "[{lo}, {hi}]");
        assert!(40.0 <= lo && hi <= 90.0, "[{lo}, {hi}]");
        // Resampled means of 5 values spread as these (population s.d. 17.8) have a s.d. of
        // 17.8 / √5 ≈ 8.0: a 95% interval about 2 x 1.96 x 8.0 ≈ 31 wide, between 2 and 4
        // standard errors (s.e. 8.9).
        let se = mean_and_se(&v).1;
        assert!(hi - lo > 2.0 * se && hi - lo < 2.0 * 2.0 * se, "[{lo}, {hi}], s.e. {se}");
        // The IQM's interval holds the IQM.
        let (ilo, ihi) = bootstrap_ci(&v, iqm);
        assert!(ilo <= iqm(&v) && iqm(&v) <= ihi, "[{ilo}, {ihi}]");
        // Constant data, and a single run: a point.
        assert_eq!(bootstrap_ci(&[12.5; 4], mean), (12.5, 12.5));
        assert_eq!(bootstrap_ci(&[12.5; 4], iqm), (12.5, 12.5));
        assert_eq!(bootstrap_ci(&[3.0], mean), (3.0, 3.0));
        assert!(bootstrap_ci(&[], mean).0.is_nan());
        // More runs of the same spread: a narrower interval.
        let many: Vec<f64> = (0..40).map(|i| v[i % 5]).collect();
        let (mlo, mhi) = bootstrap_ci(&many, mean);
        assert!(mhi - mlo < 0.6 * (hi - lo), "[{mlo}, {mhi}] against [{lo}, {hi}]");
    }
}

//! The statistics of a group's final values: mean ± standard error.

/// Mean and standard error (sample standard deviation / sqrt(n); 0 for one value) of
/// `values`; `(NaN, NaN)` for none.
pub fn mean_and_se(values: &[f64]) -> (f64, f64) {
    let n = values.len();
    if n == 0 {
        return (f64::NAN, f64::NAN);
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    if n == 1 {
        return (mean, 0.0);
    }
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    (mean, (var / n as f64).sqrt())
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
    }
}

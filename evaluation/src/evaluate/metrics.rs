//! Error measures of the evaluation.

/// RMS of `estimate - measured`.
#[must_use]
pub fn rms(estimate: &[f64], measured: &[f64]) -> f64 {
    let (norm, count) = norm_and_count(estimate, measured);
    if count == 0 { f64::NAN } else { norm / (count as f64).sqrt() }
}

/// The 2-norm of `estimate - measured` (the paper's eqs. 13 and 14) and the number of samples.
#[must_use]
pub fn norm_and_count(estimate: &[f64], measured: &[f64]) -> (f64, usize) {
    let sum: f64 = estimate.iter().zip(measured).map(|(e, m)| (e - m).powi(2)).sum();
    (sum.sqrt(), estimate.len().min(measured.len()))
}

/// Pearson's correlation coefficient (NaN for fewer than two samples or no variance).
#[must_use]
pub fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    if n < 2 {
        return f64::NAN;
    }
    let (mean_a, mean_b) = (a[..n].iter().sum::<f64>() / n as f64, b[..n].iter().sum::<f64>() / n as f64);
    let (mut cov, mut var_a, mut var_b) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        cov += (x - mean_a) * (y - mean_b);
        var_a += (x - mean_a).powi(2);
        var_b += (y - mean_b).powi(2);
    }
    cov / (var_a * var_b).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn measures_match_hand_values() {
        let (estimate, measured) = ([1.0, 2.0, 3.0], [1.0, 2.0, 5.0]);
        assert!((rms(&estimate, &measured) - (4.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert!((norm_and_count(&estimate, &measured).0 - 2.0).abs() < 1e-12);
        assert!((correlation(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.0]) - 1.0).abs() < 1e-12);
        assert!((correlation(&[1.0, 2.0, 3.0], &[3.0, 2.0, 1.0]) + 1.0).abs() < 1e-12);
    }
}

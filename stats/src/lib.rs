//! Summary statistics, one definition each: the fits, the evaluation, the diagnosis and the
//! campaign tables all call these, so a median or a quantile means the same thing in every
//! table and every decision.
//!
//! Order statistics take a mutable slice and reorder it in place (no copy; `select_nth` where
//! one order statistic is needed). statrs's order statistics sort an owned copy, and its
//! `quantile` is Hyndman and Fan's type 8, where the campaign tables state type 7, numpy's and
//! R's default; statrs's distributions serve the diagnosis's tests instead (`diagnose::ledger`).
//! Every function returns `None` without values, never a panic.

/// `1 / Phi^-1(3/4)`: the median absolute deviation of a Gaussian sample times this is its
/// standard deviation (Hampel, J. Am. Stat. Assoc. 69, 1974).
pub const MAD_TO_STD: f64 = 1.482_602_218_505_602;

/// The arithmetic mean.
#[must_use]
pub fn mean(values: &[f64]) -> Option<f64> {
    (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
}

/// The root mean square, `sqrt(sum x^2 / n)`.
#[must_use]
pub fn rms(values: &[f64]) -> Option<f64> {
    (!values.is_empty()).then(|| (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt())
}

/// The population standard deviation, `sqrt(sum (x - mean)^2 / n)`, in two passes (the centred
/// sum does not cancel as `E[x^2] - E[x]^2` would).
#[must_use]
pub fn population_std_dev(values: &[f64]) -> Option<f64> {
    let centre = mean(values)?;
    (!values.is_empty())
        .then(|| (values.iter().map(|value| (value - centre).powi(2)).sum::<f64>() / values.len() as f64).sqrt())
}

/// The median: the middle value, or the mean of the two middle values for an even count.
/// Reorders `values`.
#[must_use]
pub fn median(values: &mut [f64]) -> Option<f64> {
    let upper = median_high(values)?;
    if values.len().is_multiple_of(2) {
        let middle = values.len() / 2;
        let lower = values[..middle].iter().copied().max_by(f64::total_cmp)?;
        Some(0.5 * (lower + upper))
    } else {
        Some(upper)
    }
}

/// The high median: the middle value, or the larger of the two middle values for an even
/// count (Python's `statistics.median_high`): always one of the values, so a median of
/// quantised readings stays on their grid. Reorders `values`.
#[must_use]
pub fn median_high(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let middle = values.len() / 2;
    Some(*values.select_nth_unstable_by(middle, f64::total_cmp).1)
}

/// The `q` quantile (clamped to [0, 1]) of ascending `sorted` values, interpolated linearly
/// between order statistics (Hyndman and Fan's type 7, Am. Stat. 50, 1996; numpy's and R's
/// default).
#[must_use]
pub fn quantile_sorted(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let pos = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    Some(sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64))
}

/// [`quantile_sorted`] of `values` after sorting them in place.
#[must_use]
pub fn quantile(values: &mut [f64], q: f64) -> Option<f64> {
    values.sort_by(f64::total_cmp);
    quantile_sorted(values, q)
}

/// [`MAD_TO_STD`] times the median absolute deviation about the high median: the standard
/// deviation of a Gaussian sample, unmoved by outliers. Reorders `values` and leaves the
/// absolute deviations in it.
#[must_use]
pub fn mad_sigma(values: &mut [f64]) -> Option<f64> {
    let centre = median_high(values)?;
    for value in values.iter_mut() {
        *value = (*value - centre).abs();
    }
    Some(MAD_TO_STD * median_high(values)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The textbook values on small samples, odd and even.
    #[test]
    fn medians_and_quantiles_have_their_textbook_values() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), Some(2.5));
        assert_eq!(median_high(&mut [4.0, 1.0, 3.0, 2.0]), Some(3.0));
        // numpy.quantile([1, 2, 3, 4], 0.25) = 1.75 (type 7).
        assert_eq!(quantile(&mut [4.0, 1.0, 3.0, 2.0], 0.25), Some(1.75));
        assert_eq!(quantile(&mut [4.0, 1.0, 3.0, 2.0], 1.0), Some(4.0));
    }

    /// Means, RMS and the population standard deviation of a known sample.
    #[test]
    fn moments_have_their_textbook_values() {
        let values = [2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0];
        assert_eq!(mean(&values), Some(5.0));
        assert_eq!(population_std_dev(&values), Some(2.0));
        assert_eq!(rms(&[3.0, -4.0]), Some(12.5f64.sqrt()));
    }

    /// An outlier of 1e9 leaves the scale at the other samples' (high median 0.5, absolute
    /// deviations 0, 0.5, 0.5, 1, 1.5 and the outlier's: their high median is 1).
    #[test]
    fn mad_sigma_ignores_an_outlier() {
        let mut values = [-1.0, -0.5, 0.0, 0.5, 1.0, 1e9];
        assert_eq!(mad_sigma(&mut values), Some(MAD_TO_STD));
    }

    /// Without values every statistic is `None`, never a panic.
    #[test]
    fn empty_samples_have_no_statistic() {
        assert_eq!(mean(&[]), None);
        assert_eq!(rms(&[]), None);
        assert_eq!(population_std_dev(&[]), None);
        assert_eq!(median(&mut []), None);
        assert_eq!(median_high(&mut []), None);
        assert_eq!(quantile(&mut [], 0.5), None);
        assert_eq!(mad_sigma(&mut []), None);
    }
}

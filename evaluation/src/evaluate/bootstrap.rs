//! Confidence intervals of the held-out comparisons by the moving-block bootstrap (Künsch,
//! Ann. Statist. 17(3), 1989; Lahiri, Resampling Methods for Dependent Data, 2003, chapter 2):
//! whole blocks of consecutive samples are drawn with replacement, so the errors' correlation
//! in time, which makes neighbouring samples nearly copies of each other, is kept inside each
//! block. Whether the operator's change of a correlation in the fourth decimal means anything
//! is a question of this interval, not of the point value.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use model_fit::fit::sparse_fit::lag_one_autocorrelation;

/// Number of bootstrap resamples.
pub const RESAMPLES: usize = 1000;

/// A two-sided 95 % percentile interval.
pub type Interval = [f64; 2];

/// Block length for a series whose lag-one autocorrelation is that of `errors`: the number of
/// samples per independent one of an AR(1) process, `(1 + r1) / (1 - r1)` (the factor of
/// [`model_fit::fit::sparse_fit::effective_samples`]), kept between 1 and a quarter of the series so
/// that a resample draws at least four blocks.
#[must_use]
pub fn block_length(errors: &[f64]) -> usize {
    let r1 = lag_one_autocorrelation(errors).max(0.0);
    let samples_per_independent = ((1.0 + r1) / (1.0 - r1)).ceil() as usize;
    samples_per_independent.clamp(1, (errors.len() / 4).max(1))
}

/// The 95 % percentile interval of `statistic` over [`RESAMPLES`] moving-block resamples of
/// the indices `0..n` with blocks of `block` samples, drawn from `seed`. `None` for fewer than
/// eight samples or when no resample gives a finite statistic.
#[must_use]
pub fn interval(n: usize, block: usize, seed: u64, statistic: impl Fn(&[usize]) -> f64) -> Option<Interval> {
    if n < 8 {
        return None;
    }
    let block = block.clamp(1, n);
    let starts = n - block + 1;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut indices = Vec::with_capacity(n + block);
    let mut values: Vec<f64> = (0..RESAMPLES)
        .filter_map(|_| {
            indices.clear();
            while indices.len() < n {
                let start = rng.random_range(0..starts);
                indices.extend(start..start + block);
            }
            indices.truncate(n);
            let value = statistic(&indices);
            value.is_finite().then_some(value)
        })
        .collect();
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let at = |q: f64| values[((q * (values.len() - 1) as f64).round() as usize).min(values.len() - 1)];
    Some([at(0.025), at(0.975)])
}

/// `values` picked at `indices`.
#[must_use]
pub fn gather(values: &[f64], indices: &[usize]) -> Vec<f64> {
    indices.iter().map(|&idx| values[idx]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The interval of a mean of independent unit-variance draws has the textbook width,
    /// `2 * 1.96 / sqrt(n)`, within 15 %, and covers the true mean.
    #[test]
    fn interval_of_a_mean_has_the_textbook_width() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let values: Vec<f64> = (0..4000).map(|_| rng.random_range(-3f64.sqrt()..3f64.sqrt())).collect();
        let mean = |idx: &[usize]| idx.iter().map(|&k| values[k]).sum::<f64>() / idx.len() as f64;
        let [low, high] = interval(values.len(), 1, 3, mean).unwrap();
        let expected = 2.0 * 1.96 / (values.len() as f64).sqrt();
        assert!(((high - low) / expected - 1.0).abs() < 0.15, "{low} {high} {expected}");
        assert!(low < 0.0 && high > 0.0);
    }

    /// For a strongly autocorrelated series the blocks are long, and the interval is wider than
    /// one that treats every sample as independent (which would claim a false precision).
    #[test]
    fn correlated_series_get_long_blocks_and_wide_intervals() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut state = 0.0;
        let values: Vec<f64> = (0..4000)
            .map(|_| {
                state = 0.98 * state + rng.random_range(-1.0..1.0);
                state
            })
            .collect();
        let block = block_length(&values);
        assert!((60..=150).contains(&block), "{block}");
        let mean = |idx: &[usize]| idx.iter().map(|&k| values[k]).sum::<f64>() / idx.len() as f64;
        let [low_b, high_b] = interval(values.len(), block, 5, mean).unwrap();
        let [low_1, high_1] = interval(values.len(), 1, 5, mean).unwrap();
        assert!(high_b - low_b > 3.0 * (high_1 - low_1), "{low_b} {high_b} {low_1} {high_1}");
        assert_eq!(interval(5, 1, 0, mean), None);
    }
}

//! Where the residual energy lives: its share and mean square per regime bin, with
//! block-bootstrap intervals (docs/diagnosis.md, Regimes).
//!
//! Bins are whatever the caller stratifies by (angle of attack, `|φ|`, `sign(φ̇)` for
//! hysteresis, blowing on/off, phase in the cycle). Residuals are autocorrelated, so an i.i.d.
//! bootstrap would understate the uncertainty; the interval comes from the stationary bootstrap
//! (Politis & Romano 1994), whose random block lengths keep the dependence and which, unlike the
//! moving-block bootstrap, does not under-sample the ends of a series.
//!
//! # Examples
//!
//! ```
//! use diagnosis::diagnose::ledger::regime_shares;
//!
//! let residual = [0.1, -0.1, 0.1, -0.1, 1.0, -1.0, 1.0, -1.0];
//! let bins = [0, 0, 0, 0, 1, 1, 1, 1];
//! let labels = vec!["upstroke".to_owned(), "downstroke".to_owned()];
//! let shares = regime_shares(&[&residual], &[&bins], &labels, 7, 100);
//! assert!((shares[1].share - 4.0 / 4.04).abs() < 1e-12);
//! assert!((shares[1].mse - 1.0).abs() < 1e-12);
//! ```

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use stats::quantile_sorted;

/// Share of residual energy in one regime bin, with a stationary-bootstrap 95 % interval of
/// its mean square.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RegimeShare {
    /// The bin's label.
    pub label: String,
    /// Finite residual samples in the bin.
    pub n_samples: usize,
    /// `Σ_{t∈b} e² / Σ_t e²`; the shares of all bins sum to 1.
    pub share: f64,
    /// Mean square residual in the bin (`NaN` when the bin is empty), in squared residual units.
    pub mse: f64,
    /// Percentile 95 % interval of `mse` over the bootstrap resamples (`NaN` when no resample
    /// put a sample in the bin, for example with zero resamples).
    pub mse_ci95: [f64; 2],
}

/// Residual energy per bin: `bins[s][t]` is the index into `labels` of sample `t` of segment
/// `s`.
///
/// Samples with a non-finite residual or a bin index outside `labels` are skipped (and split
/// their segment, as missing samples do elsewhere in the ledger), and so is a whole segment
/// whose bin slice has a different length (or that has no bin slice): pairing samples with the
/// wrong bins would be worse than leaving them out.
///
/// The interval resamples the whole pooled series `resamples` times with the stationary
/// bootstrap: a block starts at a uniformly drawn sample, continues with probability `1 − 1/b`
/// per step, and wraps around inside its own segment (never across a join, the circular scheme
/// of Politis & Romano 1994 applied per segment). The mean block length `b` is the
/// Politis–White (2004) optimum with the Patton–Politis–White (2009) correction, computed as
/// `arch.bootstrap.optimal_block_length` does, on the pooled squared residual (the statistic
/// is a mean of `e²`).
pub fn regime_shares(
    segments: &[&[f64]],
    bins: &[&[usize]],
    labels: &[String],
    seed: u64,
    resamples: usize,
) -> Vec<RegimeShare> {
    let data = PooledBins::new(segments, bins, labels.len());
    let point = data.bin_sums(labels.len());
    let total_energy: f64 = point.iter().map(|(sum, _)| sum).sum();
    let boot = data.bootstrap_mses(seed, resamples, labels.len());
    labels
        .iter()
        .enumerate()
        .map(|(bin, label)| {
            let (sum, count) = point[bin];
            let mut draws = boot[bin].clone();
            draws.sort_by(f64::total_cmp);
            RegimeShare {
                label: label.clone(),
                n_samples: count,
                share: if total_energy > 0.0 { sum / total_energy } else { 0.0 },
                mse: if count > 0 { sum / count as f64 } else { f64::NAN },
                mse_ci95: [0.025, 0.975].map(|q| quantile_sorted(&draws, q).unwrap_or(f64::NAN)),
            }
        })
        .collect()
}

/// The usable samples: squared residual and bin, flat, with each segment's index range.
struct PooledBins {
    squared: Vec<f64>,
    bin: Vec<usize>,
    /// `[start, end)` of each segment in the flat arrays.
    ranges: Vec<(usize, usize)>,
    /// For each flat index, the index of its segment in `ranges`.
    segment_of: Vec<usize>,
}

impl PooledBins {
    /// Usable samples of every segment; a skipped sample splits its segment, so that bootstrap
    /// blocks never bridge a gap, as elsewhere in the ledger.
    fn new(segments: &[&[f64]], bins: &[&[usize]], n_labels: usize) -> Self {
        let mut pooled =
            PooledBins { squared: Vec::new(), bin: Vec::new(), ranges: Vec::new(), segment_of: Vec::new() };
        for (residual, bin) in segments.iter().zip(bins) {
            if residual.len() != bin.len() {
                continue;
            }
            let mut start = pooled.squared.len();
            for (e, &b) in residual.iter().zip(bin.iter()) {
                if e.is_finite() && b < n_labels {
                    pooled.squared.push(e * e);
                    pooled.bin.push(b);
                    pooled.segment_of.push(pooled.ranges.len());
                } else {
                    start = pooled.close_range(start);
                }
            }
            pooled.close_range(start);
        }
        pooled
    }

    /// Ends the range that began at `start` (if it holds a sample); returns the next start.
    fn close_range(&mut self, start: usize) -> usize {
        let end = self.squared.len();
        if end > start {
            self.ranges.push((start, end));
        }
        end
    }

    /// `(Σ e², count)` per bin.
    fn bin_sums(&self, n_labels: usize) -> Vec<(f64, usize)> {
        let mut sums = vec![(0.0, 0); n_labels];
        for (&squared, &bin) in self.squared.iter().zip(&self.bin) {
            sums[bin].0 += squared;
            sums[bin].1 += 1;
        }
        sums
    }

    /// Bootstrap draws of every bin's mean square (resamples where a bin is empty add none).
    fn bootstrap_mses(&self, seed: u64, resamples: usize, n_labels: usize) -> Vec<Vec<f64>> {
        let mut draws = vec![Vec::with_capacity(resamples); n_labels];
        let n = self.squared.len();
        if n == 0 {
            return draws;
        }
        let block_len = politis_white_block_length(&self.squared, &self.ranges);
        let continue_prob = 1.0 - 1.0 / block_len;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut sums = vec![(0.0, 0usize); n_labels];
        for _ in 0..resamples {
            sums.iter_mut().for_each(|s| *s = (0.0, 0));
            let mut idx = rng.random_range(0..n);
            for drawn in 0..n {
                if drawn > 0 {
                    idx = if rng.random::<f64>() < continue_prob {
                        let (start, end) = self.ranges[self.segment_of[idx]];
                        if idx + 1 == end { start } else { idx + 1 }
                    } else {
                        rng.random_range(0..n)
                    };
                }
                let entry = &mut sums[self.bin[idx]];
                entry.0 += self.squared[idx];
                entry.1 += 1;
            }
            for (bin, &(sum, count)) in sums.iter().enumerate() {
                if count > 0 {
                    draws[bin].push(sum / count as f64);
                }
            }
        }
        draws
    }
}

/// Mean block length of the stationary bootstrap: Politis & White (2004) with the correction
/// of Patton, Politis & White (2009), as in `arch.bootstrap.optimal_block_length`.
///
/// `b = (2 G²/D)^{1/3} n^{1/3}` with `G = Σ_{|k|≤m} λ(k/m)|k| γ̂_k`, `D = 2 ĝ²`,
/// `ĝ = Σ_{|k|≤m} λ(k/m) γ̂_k` and the flat-top kernel `λ(x) = min(1, 2(1−|x|))`
/// (docs/diagnosis.md, Regimes). The bandwidth `m` is twice the first lag after which
/// `K_n = max(5, log₁₀ n)` autocorrelations in a row are insignificant (below `2√(log₁₀ n / n)`),
/// capped at `⌈√n⌉ + K_n`; `b` is capped at `min(3√n, n/3)` and floored at 1. Autocovariances are
/// pooled within segments (each segment demeaned), normalised by the total `n`.
fn politis_white_block_length(values: &[f64], ranges: &[(usize, usize)]) -> f64 {
    let n = values.len();
    let n_f = n as f64;
    if n < 8 {
        return 1.0;
    }
    let runs: Vec<Vec<f64>> = ranges
        .iter()
        .map(|&(start, end)| {
            let seg = &values[start..end];
            let mean = seg.iter().sum::<f64>() / seg.len() as f64;
            seg.iter().map(|x| x - mean).collect()
        })
        .collect();
    let k_n = 5usize.max(n_f.log10() as usize);
    let m_max = n_f.sqrt().ceil() as usize + k_n;
    let pairs: Vec<(&[f64], &[f64])> = runs.iter().map(|r| (r.as_slice(), r.as_slice())).collect();
    let (sums, _) = super::pooled_lagged_products(&pairs, m_max);
    if sums[0].is_nan() || sums[0] <= 0.0 {
        return 1.0;
    }
    let acv: Vec<f64> = sums.iter().map(|s| s / n_f).collect();
    let critical = 2.0 * (n_f.log10() / n_f).sqrt();
    let insignificant = |lag: usize| (acv[lag] / acv[0]).abs() < critical;
    let first_quiet = (1..=m_max.saturating_sub(k_n) + 1)
        .find(|&start| (start..start + k_n).all(|lag| lag <= m_max && insignificant(lag)));
    let m = first_quiet.map_or(m_max, |start| (2 * (start - 1).max(1)).min(m_max));
    let (mut g, mut long_run) = (0.0, acv[0]);
    for (lag, &gamma) in acv.iter().enumerate().take(m + 1).skip(1) {
        let x = lag as f64 / m as f64;
        let weight = if x <= 0.5 { 1.0 } else { 2.0 * (1.0 - x) };
        g += 2.0 * weight * lag as f64 * gamma;
        long_run += 2.0 * weight * gamma;
    }
    let d = 2.0 * long_run * long_run;
    let b_max = (3.0 * n_f.sqrt()).min(n_f / 3.0).ceil();
    let b = (2.0 * g * g / d).cbrt() * n_f.cbrt();
    if b.is_finite() { b.clamp(1.0, b_max) } else { 1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::ledger::test_signals::{ar1, white};

    fn labels(n: usize) -> Vec<String> {
        (0..n).map(|k| format!("bin {k}")).collect()
    }

    #[test]
    fn shares_sum_to_one_and_intervals_hold_the_estimate() {
        let e1 = ar1(1, 3000, 0.8);
        let e2: Vec<f64> = white(2, 2000).iter().map(|x| 3.0 * x).collect();
        let b1: Vec<usize> = (0..3000).map(|t| (t / 50) % 3).collect();
        let b2: Vec<usize> = (0..2000).map(|t| (t / 70) % 3).collect();
        let shares = regime_shares(&[&e1, &e2], &[&b1, &b2], &labels(3), 42, 300);
        assert_eq!(shares.len(), 3);
        let total: f64 = shares.iter().map(|s| s.share).sum();
        assert!((total - 1.0).abs() < 1e-12);
        for s in &shares {
            assert!(s.mse_ci95[0] <= s.mse && s.mse <= s.mse_ci95[1], "{s:?}");
            assert!(s.mse_ci95[1] > s.mse_ci95[0]);
        }
        assert_eq!(shares.iter().map(|s| s.n_samples).sum::<usize>(), 5000);
    }

    #[test]
    fn a_bin_with_larger_errors_holds_most_energy() {
        let noise = white(3, 4000);
        let bins: Vec<usize> = (0..4000).map(|t| usize::from(t % 100 < 50)).collect();
        let residual: Vec<f64> = noise.iter().zip(&bins).map(|(e, &b)| if b == 1 { 3.0 * e } else { *e }).collect();
        let shares = regime_shares(&[&residual], &[&bins], &labels(2), 7, 200);
        assert!(shares[1].share > 0.85, "{}", shares[1].share);
        assert!(shares[0].mse_ci95[1] < shares[1].mse_ci95[0], "intervals separate");
    }

    #[test]
    fn same_seed_same_intervals() {
        let e = ar1(4, 1000, 0.5);
        let bins: Vec<usize> = (0..1000).map(|t| t % 2).collect();
        let a = regime_shares(&[&e], &[&bins], &labels(2), 9, 100);
        let b = regime_shares(&[&e], &[&bins], &labels(2), 9, 100);
        assert_eq!(a, b);
    }

    #[test]
    fn block_length_grows_with_dependence() {
        let white_len = politis_white_block_length(&white(5, 5000), &[(0, 5000)]);
        let coloured_len = politis_white_block_length(&ar1(6, 5000, 0.9), &[(0, 5000)]);
        assert!(white_len < 3.0, "{white_len}");
        assert!(coloured_len > 3.0 * white_len, "{coloured_len} vs {white_len}");
    }

    #[test]
    fn skips_bad_samples_and_mismatched_segments() {
        let e = [1.0, f64::NAN, 2.0, 3.0];
        let bins = [0, 0, 5, 1];
        let mismatched = [1.0, 2.0];
        let shares = regime_shares(&[&e, &mismatched], &[&bins, &[0]], &labels(2), 1, 0);
        assert_eq!(shares[0].n_samples, 1);
        assert_eq!(shares[1].n_samples, 1);
        assert!((shares[1].share - 0.9).abs() < 1e-12);
        assert!(shares[0].mse_ci95[0].is_nan());
        let pooled = PooledBins::new(&[&e, &mismatched], &[&bins, &[0]], 2);
        assert_eq!(pooled.ranges, vec![(0, 1), (1, 2)]);
        let empty = regime_shares(&[], &[], &labels(2), 1, 10);
        assert!(empty.iter().all(|s| s.n_samples == 0 && s.share == 0.0 && s.mse.is_nan()));
    }
}

//! Kalman-filter innovations per measurement channel, for localising a sensor fault to one
//! channel (docs/diagnosis.md, Pressure innovations per channel), and the difference-based noise
//! floor of a channel.
//!
//! For a correct filter the innovation `ν` of each channel is white with standard deviation
//! `√S_ii`. One channel failing these checks points to its port, tube or transducer; all
//! channels failing together point to a global effect.
//!
//! # Examples
//!
//! ```
//! use diagnosis::diagnose::ledger::channel_innovation;
//!
//! // A port that froze for four samples (30 ms at 100 Hz) and one spike of 8 σ.
//! let raw = [1.00, 1.02, 1.01, 1.01, 1.01, 1.01, 0.99, 1.03];
//! let innovation = [0.01, -0.02, 0.08, -0.01, 0.00, 0.01, -0.01, 0.02];
//! let stats = channel_innovation("p4", &[&raw], &[&innovation], 0.01, 100.0);
//! assert!((stats.longest_constant_run_s - 0.03).abs() < 1e-12);
//! assert_eq!(stats.outlier_fraction, 1.0 / 8.0);
//! ```

use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF};

use super::ljung_box;

/// `|ν/σ|` beyond which a normalised innovation counts as a spike.
pub const OUTLIER_SIGMA: f64 = 5.0;

/// Largest number of lags of the innovation whiteness test (Box & Jenkins' customary 20).
pub const INNOVATION_WHITENESS_LAGS: usize = 20;

/// Relative tolerance under which two consecutive raw samples count as the same value (a stuck
/// sensor repeats its last reading, possibly through a float round trip).
pub const STUCK_RELATIVE_TOLERANCE: f64 = 1e-9;

/// Per-channel innovation statistics of a Kalman filter, normalised by the expected innovation
/// standard deviation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChannelInnovation {
    /// Channel name.
    pub channel: String,
    /// Innovation samples offered, missing ones included.
    pub n_samples: usize,
    /// Fraction of innovation samples that are non-finite.
    pub missing_fraction: f64,
    /// Mean of `ν/σ` (a bias in units of the expected standard deviation).
    pub mean_sigma: f64,
    /// Sample standard deviation of `ν/σ`: 1 when `S` is right.
    pub std_ratio: f64,
    /// Mean normalised innovation squared, `(1/N) Σ ν²/σ²`.
    pub nis_mean: f64,
    /// Two-sided 99 % acceptance interval of `nis_mean`: `χ²(N)/N` quantiles at 0.5 % and
    /// 99.5 %.
    pub nis_bounds_99: [f64; 2],
    /// `nis_mean` inside `nis_bounds_99`.
    pub consistent: bool,
    /// Fraction of finite innovations with `|ν/σ| > 5`.
    pub outlier_fraction: f64,
    /// Longest time the raw channel held one value (`(k − 1)/fs` for `k` equal samples in a
    /// row), in seconds; 0 for a channel that never repeats.
    pub longest_constant_run_s: f64,
    /// Ljung–Box p-value of the innovation (`NaN` when too short to test).
    pub whiteness_p: f64,
}

/// Innovation statistics of one channel: `raw` is the channel's measurement, `innovation` the
/// filter's `ν = y − H x̂(k|k−1)` for it (the two need not be aligned: `raw` serves only the
/// stuck-value check), `expected_std` the filter's `√S_ii`, assumed constant, `sample_hz` the
/// sample rate.
///
/// NIS consistency follows kalman-filter.com (docs/diagnosis.md, Pressure innovations per channel):
/// for `N` samples of one channel, `N·NIS̄ ~ χ²(N)` under a correct filter, so `NIS̄` is accepted
/// inside the `χ²(N)/N` quantiles. That assumes independent innovations; a coloured innovation is
/// flagged by `whiteness_p` (Ljung–Box with `min(20, N/5)` lags, segments pooled as in
/// [`ljung_box`]).
///
/// Never fails: statistics that cannot be computed (no finite sample, `expected_std` not
/// positive, an invalid `sample_hz`) are `NaN`, and `consistent` is then false.
pub fn channel_innovation(
    channel: &str,
    raw: &[&[f64]],
    innovation: &[&[f64]],
    expected_std: f64,
    sample_hz: f64,
) -> ChannelInnovation {
    let n_samples: usize = innovation.iter().map(|s| s.len()).sum();
    let sigma = if expected_std.is_finite() && expected_std > 0.0 { expected_std } else { f64::NAN };
    let normalised: Vec<f64> =
        innovation.iter().flat_map(|s| s.iter()).filter(|x| x.is_finite()).map(|x| x / sigma).collect();
    let n_finite = normalised.len();
    let n = n_finite as f64;
    let mean_sigma = normalised.iter().sum::<f64>() / n;
    let nis_mean = normalised.iter().map(|z| z * z).sum::<f64>() / n;
    let std_ratio = (normalised.iter().map(|z| (z - mean_sigma).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let nis_bounds_99 = nis_bounds_99(n_finite);
    let lags = INNOVATION_WHITENESS_LAGS.min(n_finite / 5);
    ChannelInnovation {
        channel: channel.to_owned(),
        n_samples,
        missing_fraction: ratio(n_samples - n_finite, n_samples),
        mean_sigma,
        std_ratio,
        nis_mean,
        nis_bounds_99,
        consistent: nis_mean >= nis_bounds_99[0] && nis_mean <= nis_bounds_99[1],
        outlier_fraction: if sigma.is_nan() {
            f64::NAN
        } else {
            ratio(normalised.iter().filter(|z| z.abs() > OUTLIER_SIGMA).count(), n_finite)
        },
        longest_constant_run_s: longest_constant_run_s(raw, sample_hz),
        whiteness_p: ljung_box(innovation, lags, 0).map_or(f64::NAN, |w| w.p_value),
    }
}

/// White measurement-noise variance under a smooth signal from first differences (von Neumann
/// et al. 1941): `Var(Δx)/2`, since `Δ` of white noise of variance `σ²` has variance `2σ²` while
/// a smooth signal's differences are small.
///
/// Differences are taken within finite runs (segments split at non-finite samples) and each
/// run's mean difference (a linear trend) is removed; the sum of squares is pooled over runs
/// with `n − 1` degrees of freedom per run. `None` when no run has at least two differences.
pub fn difference_noise_var(segments: &[&[f64]]) -> Option<f64> {
    pooled_difference_var(segments, 1).map(|v| v / 2.0)
}

/// The same noise variance from second differences, `Var(Δ²x)/6` (`Δ²` of white noise of
/// variance `σ²` has variance `(1 + 4 + 1)σ² = 6σ²`), as a cross-check of
/// [`difference_noise_var`]: the two agree when the noise is white and the signal is smooth at
/// the sample rate, and disagree for coloured noise or signal power near the Nyquist frequency.
pub fn second_difference_noise_var(segments: &[&[f64]]) -> Option<f64> {
    pooled_difference_var(segments, 2).map(|v| v / 6.0)
}

/// Pooled variance of the `order`-th differences within finite runs, each run demeaned.
fn pooled_difference_var(segments: &[&[f64]], order: usize) -> Option<f64> {
    let (mut sum_sq, mut dof) = (0.0, 0usize);
    for segment in segments {
        for run in segment.split(|x| !x.is_finite()) {
            let mut diffs = run.to_vec();
            for _ in 0..order {
                diffs = diffs.windows(2).map(|w| w[1] - w[0]).collect();
            }
            if diffs.len() < 2 {
                continue;
            }
            let mean = diffs.iter().sum::<f64>() / diffs.len() as f64;
            sum_sq += diffs.iter().map(|d| (d - mean).powi(2)).sum::<f64>();
            dof += diffs.len() - 1;
        }
    }
    (dof > 0).then(|| sum_sq / dof as f64)
}

/// `[χ²_{0.005}(N)/N, χ²_{0.995}(N)/N]`, or `NaN`s without samples.
fn nis_bounds_99(n_finite: usize) -> [f64; 2] {
    match ChiSquared::new(n_finite as f64) {
        Ok(chi2) if n_finite > 0 => {
            let n = n_finite as f64;
            [chi2.inverse_cdf(0.005) / n, chi2.inverse_cdf(0.995) / n]
        }
        _ => [f64::NAN; 2],
    }
}

/// Longest run of equal consecutive finite samples within a segment, as `(k − 1)/fs` seconds.
fn longest_constant_run_s(raw: &[&[f64]], sample_hz: f64) -> f64 {
    if !(sample_hz.is_finite() && sample_hz > 0.0) {
        return f64::NAN;
    }
    let mut longest = 0usize;
    for segment in raw {
        let mut run = 0usize;
        for pair in segment.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let same =
                a.is_finite() && b.is_finite() && (a - b).abs() <= STUCK_RELATIVE_TOLERANCE * a.abs().max(b.abs());
            run = if same { run + 1 } else { 0 };
            longest = longest.max(run);
        }
    }
    longest as f64 / sample_hz
}

/// `part/whole`, `NaN` when `whole` is 0.
fn ratio(part: usize, whole: usize) -> f64 {
    if whole == 0 { f64::NAN } else { part as f64 / whole as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::ledger::test_signals::{ar1, white};

    const FS_HZ: f64 = 100.0;

    #[test]
    fn a_consistent_channel_passes() {
        let innovation: Vec<f64> = white(1, 5000).iter().map(|x| 0.2 * x).collect();
        let raw: Vec<f64> = innovation.iter().map(|x| 10.0 + x).collect();
        let stats = channel_innovation("p3", &[&raw], &[&innovation], 0.2, FS_HZ);
        assert!(stats.consistent, "{stats:?}");
        assert!((stats.std_ratio - 1.0).abs() < 0.05);
        assert!(stats.mean_sigma.abs() < 0.1);
        assert!(stats.whiteness_p > 0.01);
        assert_eq!(stats.outlier_fraction, 0.0);
        assert_eq!(stats.longest_constant_run_s, 0.0);
        assert_eq!(stats.missing_fraction, 0.0);
    }

    #[test]
    fn localises_faults_on_a_channel() {
        let mut innovation: Vec<f64> = ar1(2, 5000, 0.7).iter().map(|x| 0.5 * x).collect();
        innovation[100] = 50.0;
        innovation[200] = f64::NAN;
        let mut raw: Vec<f64> = white(3, 5000);
        raw[1000..1250].fill(0.75);
        let stats = channel_innovation("p7", &[&raw], &[&innovation], 0.2, FS_HZ);
        assert!(!stats.consistent);
        assert!(stats.std_ratio > 2.0);
        assert!(stats.whiteness_p < 0.01);
        assert!(stats.outlier_fraction > 0.0);
        assert!((stats.missing_fraction - 1.0 / 5000.0).abs() < 1e-12);
        assert!((stats.longest_constant_run_s - 2.49).abs() < 1e-9);
    }

    #[test]
    fn nis_bounds_are_chi2_over_n() {
        let [lo, hi] = nis_bounds_99(1000);
        // χ²(1000) quantiles at 0.5 % and 99.5 % (scipy.stats.chi2.ppf): 888.564 and 1118.948.
        assert!((lo - 0.888564).abs() < 1e-5 && (hi - 1.118948).abs() < 1e-5, "{lo} {hi}");
    }

    #[test]
    fn degenerate_channels_give_nan_not_panics() {
        let stats = channel_innovation("x", &[], &[], 0.0, 0.0);
        assert!(stats.mean_sigma.is_nan() && !stats.consistent);
        assert!(stats.longest_constant_run_s.is_nan());
        let stats = channel_innovation("x", &[&[1.0, 1.0]], &[&[0.5, -0.5, 9.0]], -1.0, 10.0);
        assert!(stats.nis_mean.is_nan() && stats.outlier_fraction.is_nan() && !stats.consistent);
        assert_eq!(stats.longest_constant_run_s, 0.1);
        let stats = channel_innovation("x", &[&[f64::NAN; 3]], &[&[f64::NAN; 3]], 1.0, 10.0);
        assert_eq!(stats.missing_fraction, 1.0);
        assert!(stats.whiteness_p.is_nan());
    }

    #[test]
    fn difference_variances_recover_noise_under_a_slow_sine() {
        let sigma = 0.1;
        let n = 50_000;
        let noise = white(4, n);
        let series: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / 1000.0;
                (2.0 * std::f64::consts::PI * 0.5 * t).sin() + sigma * noise[k]
            })
            .collect();
        let (first, second) = series.split_at(n / 2);
        let from_first = difference_noise_var(&[first, second]).unwrap();
        let from_second = second_difference_noise_var(&[first, second]).unwrap();
        let truth = sigma * sigma;
        assert!((from_first / truth - 1.0).abs() < 0.03, "{from_first}");
        assert!((from_second / truth - 1.0).abs() < 0.03, "{from_second}");
    }

    #[test]
    fn difference_variance_needs_data() {
        assert!(difference_noise_var(&[]).is_none());
        assert!(difference_noise_var(&[&[1.0, 2.0]]).is_none());
        assert!(second_difference_noise_var(&[&[1.0, f64::NAN, 2.0, 3.0]]).is_none());
    }
}

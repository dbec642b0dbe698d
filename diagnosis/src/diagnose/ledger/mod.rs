//! The residual ledger: the classical tests a sim-to-real gap diagnosis runs on a model's
//! residuals (docs/diagnosis.md, The gap ledger; sections named below are its subsections).
//!
//! - [`whiteness`]: residual autocorrelation and the Ljung–Box portmanteau test (Whiteness);
//! - [`crosscorr`]: residual–input cross-correlation with the bound for coloured signals
//!   (Cross-correlation with the inputs);
//! - [`spectrum`]: Welch spectra, band shares, narrow peaks and residual–input coherence
//!   (Spectrum and coherence);
//! - [`regimes`]: residual energy per regime bin with stationary-bootstrap intervals (Regimes);
//! - [`innovations`]: per-channel Kalman innovation statistics and the difference-based noise
//!   floor (Pressure innovations per channel).
//!
//! # Data layout and missing samples
//!
//! Data arrive as several contiguous segments (one per run, for example the held-out part of
//! each run), so every function takes `segments: &[&[f64]]`, and two-signal tests take paired
//! segments of equal lengths. Statistics are pooled across segments without ever pairing samples
//! across a join: lagged products are summed within a segment, Welch windows never straddle a
//! join, and bootstrap blocks wrap around inside their own segment.
//!
//! A non-finite sample (NaN or ±∞) is treated as missing by **splitting the segment at it**: the
//! finite runs on either side become separate segments (for paired signals, a sample missing in
//! either signal splits both). Each of these runs then has **its own mean removed** where a test
//! needs zero-mean data (whiteness, cross-correlation, Welch windows), so different offsets
//! between runs (a drifting balance zero, a different tare per run) do not show up as spurious
//! low-frequency correlation at the joins.
//!
//! Every function returns `None` (or skips the item) rather than panicking on empty, too short
//! or non-finite input, and every random thing takes a seed.
//!
//! # Examples
//!
//! ```
//! use diagnosis::diagnose::ledger::ljung_box;
//!
//! // Two runs of an alternating residual: strongly negatively correlated at lag 1.
//! let run_a: Vec<f64> = (0..200).map(|k| if k % 2 == 0 { 1.0 } else { -1.0 }).collect();
//! let run_b: Vec<f64> = run_a.iter().map(|e| 3.0 + e).collect();
//! let test = ljung_box(&[&run_a, &run_b], 10, 0).unwrap();
//! assert!(!test.white);
//! assert!(test.acf[0] < -0.9);
//! ```

pub mod crosscorr;
pub mod innovations;
pub mod regimes;
pub mod spectrum;
pub mod whiteness;

#[cfg(test)]
mod test_signals;

pub use crosscorr::{CrossCorrelation, cross_correlation};
pub use innovations::{ChannelInnovation, channel_innovation, difference_noise_var, second_difference_noise_var};
pub use regimes::{RegimeShare, regime_shares};
pub use spectrum::{
    BandShare, Coherence, SpectralPeak, Spectrum, band_shares, coherence, local_peak_ratio, spectral_peak, welch_psd,
};
pub use whiteness::{Whiteness, ljung_box};

use statrs::distribution::{ContinuousCDF, Normal};

/// Two-sided 99 % quantile of the standard normal, `Φ⁻¹(0.995) ≈ 2.576`.
///
/// Computed from statrs rather than typed in, so every 99 % band in the ledger uses the same
/// number (Whiteness: `±z/√N` with `z = 2.58` at 99 %).
pub(crate) fn z_two_sided_99() -> f64 {
    Normal::standard().inverse_cdf(0.995)
}

/// The finite runs of every segment (split at non-finite samples), each with its mean removed;
/// runs shorter than `min_len` samples are dropped.
pub(crate) fn demeaned_runs(segments: &[&[f64]], min_len: usize) -> Vec<Vec<f64>> {
    let mut runs = Vec::new();
    for segment in segments {
        for run in segment.split(|x| !x.is_finite()) {
            if run.len() >= min_len.max(1) {
                runs.push(demeaned(run));
            }
        }
    }
    runs
}

/// Paired finite runs of two signals (split where either is non-finite), each demeaned.
///
/// Returns `None` when the signals do not pair up: a different number of segments or a pair of
/// segments of different lengths (aligning them is the caller's job, and guessing would pair
/// samples from different times).
pub(crate) fn demeaned_paired_runs(
    first: &[&[f64]],
    second: &[&[f64]],
    min_len: usize,
) -> Option<Vec<(Vec<f64>, Vec<f64>)>> {
    if first.len() != second.len() || first.iter().zip(second).any(|(a, b)| a.len() != b.len()) {
        return None;
    }
    let mut runs = Vec::new();
    for (a, b) in first.iter().zip(second) {
        let mut start = 0;
        for idx in 0..=a.len() {
            let missing = idx == a.len() || !a[idx].is_finite() || !b[idx].is_finite();
            if missing {
                if idx - start >= min_len.max(1) {
                    runs.push((demeaned(&a[start..idx]), demeaned(&b[start..idx])));
                }
                start = idx + 1;
            }
        }
    }
    Some(runs)
}

/// A copy of `run` with its mean removed.
fn demeaned(run: &[f64]) -> Vec<f64> {
    let mean = run.iter().sum::<f64>() / run.len() as f64;
    run.iter().map(|x| x - mean).collect()
}

/// Lagged cross-products `Σ a[t]·b[t−k]` for `k = 0..=max_lag`, summed within each run pair
/// and never across a join, with the number of products at each lag.
///
/// With `a == b` this is the pooled (unnormalised) autocovariance of the whiteness test.
pub(crate) fn pooled_lagged_products(pairs: &[(&[f64], &[f64])], max_lag: usize) -> (Vec<f64>, Vec<usize>) {
    let mut sums = vec![0.0; max_lag + 1];
    let mut counts = vec![0usize; max_lag + 1];
    for (a, b) in pairs {
        let len = a.len().min(b.len());
        for lag in 0..=max_lag.min(len.saturating_sub(1)) {
            sums[lag] += a[lag..len].iter().zip(&b[..len - lag]).map(|(x, y)| x * y).sum::<f64>();
            counts[lag] += len - lag;
        }
    }
    (sums, counts)
}

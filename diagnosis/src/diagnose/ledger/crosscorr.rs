//! Independence of residual and input: their cross-correlation, with the bound that holds when
//! both are coloured (docs/diagnosis.md, Cross-correlation with the inputs).
//!
//! A peak outside the band at lag `k > 0` means the part of the output caused by `u(t−k)` is not
//! described by the model (unmodelled dynamics or a wrong delay). Only lags `k ≥ 0` are computed:
//! under closed-loop blowing control negative lags show feedback, not model error.
//!
//! # Examples
//!
//! ```
//! use diagnosis::diagnose::ledger::cross_correlation;
//!
//! // An irregular input, and a residual that still holds it three samples late.
//! let input: Vec<f64> = (0..2000).map(|k| ((k * k % 997) as f64 * 0.37).sin()).collect();
//! let residual: Vec<f64> = (0..2000).map(|k| if k >= 3 { input[k - 3] } else { 0.0 }).collect();
//! let test = cross_correlation("c_mu", &[&residual], &[&input], 10).unwrap();
//! assert_eq!(test.peak_lag, 3);
//! assert!(test.significant);
//! ```

use serde::Serialize;
use statrs::distribution::{ContinuousCDF, Normal};

use super::{demeaned_paired_runs, pooled_lagged_products, z_two_sided_99};

/// Residual–input cross-correlation with the coloured-signal bound (Bartlett-window estimate of
/// `P = Σ R_e(k) R_u(k)`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CrossCorrelation {
    /// Name of the input signal.
    pub input: String,
    /// Largest lag computed.
    pub max_lag: usize,
    /// `r_eu(k)` for `k = 0..=max_lag`: residual at `t` against input at `t − k`.
    pub ccf: Vec<f64>,
    /// The per-lag 99 % band `z·√(P/(N R_e(0) R_u(0)))`, valid for coloured signals
    /// (docs/diagnosis.md, Cross-correlation with the inputs).
    pub bound_99: f64,
    /// The 99 % band for the largest `|r_eu(k)|` over all `max_lag + 1` lags (Šidák correction
    /// of [`Self::bound_99`]); this is the band `significant` uses.
    pub family_bound_99: f64,
    /// Lag of the largest `|r_eu(k)|`.
    pub peak_lag: usize,
    /// `r_eu(peak_lag)` (signed).
    pub peak: f64,
    /// `|peak| > family_bound_99`: residual and input are dependent at 1 % family-wise.
    pub significant: bool,
    /// Finite sample pairs used.
    pub n_samples: usize,
    /// Largest lag of the Bartlett window used to estimate `P`.
    pub bartlett_lag: usize,
}

/// Cross-correlation of paired residual and input segments at lags `0..=max_lag`.
///
/// `r_eu(k) = R_eu(k)/√(R_e(0) R_u(0))` with `R_eu(k) = (1/N) Σ e[t] u[t−k]`, every product
/// taken within one demeaned run pair (see [the module docs](super)). Under independence
/// `r_eu(k)` is asymptotically `N(0, P/(N R_e(0) R_u(0)))` with `P = Σ_k R_e(k) R_u(k)`, which
/// holds for coloured `e` and `u` (dsmc `validation/cross_correlation.rs`; docs/diagnosis.md,
/// Cross-correlation with the inputs); the naive `z/√N` band, right only when one of them is
/// white, gives many false alarms on two coloured signals. `P` is estimated with Bartlett weights
/// `1 − |k|/(M+1)` over `|k| ≤ M`, which keeps the estimate non-negative; `M = max(max_lag, ⌈√N⌉)`
/// so that slowly decaying autocorrelations (an AR(1) with φ = 0.9 needs tens of lags) are not
/// cut short, which would make the band too narrow.
///
/// Testing `max_lag + 1` lags at 1 % each would raise a false alarm far more often than 1 %, so
/// `significant` compares the peak with the Šidák family band
/// `Φ⁻¹(1 − (1 − 0.99^{1/(max_lag+1)})/2)·√(P/(N R_e(0) R_u(0)))`, which is conservative when
/// neighbouring lags are correlated. On independent AR(1) pairs (φ from 0 to 0.95, 500 to 2000
/// samples, 20 to 40 lags) flagging any lag outside the per-lag band gave 6–19 % false alarms,
/// the family band 0.25–1.25 %.
///
/// Returns `None` when the segments do not pair up (count or lengths differ), there are not more
/// than `max_lag + 1` finite pairs, or either signal is constant.
pub fn cross_correlation(
    input_name: &str,
    residual: &[&[f64]],
    input: &[&[f64]],
    max_lag: usize,
) -> Option<CrossCorrelation> {
    let runs = demeaned_paired_runs(residual, input, 1)?;
    let n_samples: usize = runs.iter().map(|(e, _)| e.len()).sum();
    if n_samples <= max_lag + 1 {
        return None;
    }
    let bartlett_lag = max_lag.max((n_samples as f64).sqrt().ceil() as usize).min(n_samples - 1);
    let e_pairs: Vec<(&[f64], &[f64])> = runs.iter().map(|(e, _)| (e.as_slice(), e.as_slice())).collect();
    let u_pairs: Vec<(&[f64], &[f64])> = runs.iter().map(|(_, u)| (u.as_slice(), u.as_slice())).collect();
    let (auto_e, _) = pooled_lagged_products(&e_pairs, bartlett_lag);
    let (auto_u, _) = pooled_lagged_products(&u_pairs, bartlett_lag);
    if auto_e[0].is_nan() || auto_u[0].is_nan() || auto_e[0] <= 0.0 || auto_u[0] <= 0.0 {
        return None;
    }
    let cross_pairs: Vec<(&[f64], &[f64])> = runs.iter().map(|(e, u)| (e.as_slice(), u.as_slice())).collect();
    let (cross, _) = pooled_lagged_products(&cross_pairs, max_lag);
    let scale = (auto_e[0] * auto_u[0]).sqrt();
    let ccf: Vec<f64> = cross.iter().map(|c| c / scale).collect();
    let std_ccf = coloured_ccf_std(&auto_e, &auto_u, n_samples);
    let (peak_lag, peak) = ccf.iter().copied().enumerate().max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))?;
    let family_bound_99 = sidak_z_99(max_lag + 1) * std_ccf;
    Some(CrossCorrelation {
        input: input_name.to_owned(),
        max_lag,
        ccf,
        bound_99: z_two_sided_99() * std_ccf,
        family_bound_99,
        peak_lag,
        peak,
        significant: peak.abs() > family_bound_99,
        n_samples,
        bartlett_lag,
    })
}

/// Standard deviation of `r_eu(k)` under independence, `√(P/(N R_e(0) R_u(0)))` (docs/diagnosis.md,
/// Cross-correlation with the inputs), from pooled sums of lagged products up to the Bartlett lag
/// `M = auto_e.len() − 1`.
///
/// The sums are `N·R(k)`, so the Bartlett-weighted `Σ_{|k|≤M} (1 − |k|/(M+1)) S_e(k) S_u(k)` is
/// `N²·P` and dividing it by `N·S_e(0)·S_u(0)` gives the variance.
fn coloured_ccf_std(auto_e: &[f64], auto_u: &[f64], n_samples: usize) -> f64 {
    let bartlett_lag = auto_e.len().min(auto_u.len()) - 1;
    let p_sum: f64 = (0..=bartlett_lag)
        .map(|lag| {
            let weight = 1.0 - lag as f64 / (bartlett_lag + 1) as f64;
            let both_sides = if lag == 0 { 1.0 } else { 2.0 };
            both_sides * weight * auto_e[lag] * auto_u[lag]
        })
        .sum();
    (p_sum.max(0.0) / (n_samples as f64 * auto_e[0] * auto_u[0])).sqrt()
}

/// Two-sided normal quantile for a family-wise 1 % level over `tests` tests (Šidák 1967).
fn sidak_z_99(tests: usize) -> f64 {
    let per_test_alpha = 1.0 - 0.99_f64.powf(1.0 / tests.max(1) as f64);
    Normal::standard().inverse_cdf(1.0 - per_test_alpha / 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::ledger::test_signals::{ar1, white};

    const LEN: usize = 2000;
    const MAX_LAG: usize = 20;

    #[test]
    fn independent_coloured_signals_rarely_alarm_but_the_naive_band_does() {
        let mut alarms = 0;
        let mut naive_alarms = 0;
        for seed in 0..100 {
            let residual = ar1(1000 + seed, LEN, 0.9);
            let input = ar1(5000 + seed, LEN, 0.9);
            let test = cross_correlation("u", &[&residual], &[&input], MAX_LAG).unwrap();
            alarms += usize::from(test.significant);
            let naive_bound = sidak_z_99(MAX_LAG + 1) / (LEN as f64).sqrt();
            naive_alarms += usize::from(test.peak.abs() > naive_bound);
        }
        assert!(alarms <= 5, "{alarms} false alarms in 100");
        assert!(naive_alarms >= 30, "naive band: only {naive_alarms} false alarms in 100");
    }

    #[test]
    fn finds_a_seven_sample_delay() {
        let input = ar1(21, LEN + 7, 0.5);
        let noise = white(22, LEN);
        let residual: Vec<f64> = (0..LEN).map(|t| 0.5 * input[t] + noise[t]).collect();
        let delayed_input = &input[7..];
        let test = cross_correlation("u", &[&residual], &[delayed_input], MAX_LAG).unwrap();
        assert!(test.significant);
        assert_eq!(test.peak_lag, 7);
        assert!(test.peak > 0.3);
    }

    #[test]
    fn segment_offsets_do_not_correlate_at_the_joins() {
        let e1: Vec<f64> = ar1(31, 1000, 0.5).iter().map(|e| e + 4.0).collect();
        let e2: Vec<f64> = ar1(32, 1000, 0.5).iter().map(|e| e - 4.0).collect();
        let u1: Vec<f64> = ar1(33, 1000, 0.5).iter().map(|u| u + 2.0).collect();
        let u2: Vec<f64> = ar1(34, 1000, 0.5).iter().map(|u| u - 2.0).collect();
        let split = cross_correlation("u", &[&e1, &e2], &[&u1, &u2], MAX_LAG).unwrap();
        assert!(!split.significant, "peak {} at {}", split.peak, split.peak_lag);
        let joined_e: Vec<f64> = e1.iter().chain(&e2).copied().collect();
        let joined_u: Vec<f64> = u1.iter().chain(&u2).copied().collect();
        let joined = cross_correlation("u", &[&joined_e], &[&joined_u], MAX_LAG).unwrap();
        assert!(joined.peak > 0.5, "joined peak {}", joined.peak);
    }

    #[test]
    fn white_signals_reduce_to_the_textbook_band() {
        let test = cross_correlation("u", &[&white(41, 4000)], &[&white(42, 4000)], 10).unwrap();
        let textbook = 2.576 / 4000f64.sqrt();
        assert!((test.bound_99 / textbook - 1.0).abs() < 0.15, "{}", test.bound_99 / textbook);
    }

    #[test]
    fn mismatched_or_degenerate_inputs_give_none() {
        let a = white(1, 100);
        assert!(cross_correlation("u", &[&a], &[&a[..99]], 5).is_none());
        assert!(cross_correlation("u", &[&a], &[], 5).is_none());
        assert!(cross_correlation("u", &[&a], &[&[1.0; 100]], 5).is_none());
        assert!(cross_correlation("u", &[&a[..5]], &[&a[..5]], 5).is_none());
        let mut gappy = a.clone();
        gappy[50] = f64::NAN;
        let test = cross_correlation("u", &[&gappy], &[&a], 5).unwrap();
        assert_eq!(test.n_samples, 99);
    }
}

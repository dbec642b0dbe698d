//! Whiteness of a residual: its autocorrelation and the Ljung–Box portmanteau test
//! (docs/diagnosis.md, Whiteness).
//!
//! A one-step prediction error or a Kalman innovation of a correct model is white; colour means
//! the dynamics or the noise model are wrong. For an output-error residual colour may only mean
//! coloured noise, so read this test together with the cross-correlation of
//! [`super::crosscorr`].

use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF};

use super::{demeaned_runs, pooled_lagged_products, z_two_sided_99};

/// Significance level of the whiteness verdict: white unless rejected at 1 %.
pub const WHITENESS_ALPHA: f64 = 0.01;

/// Ljung–Box portmanteau test on the residual autocorrelation (Ljung & Box 1978).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Whiteness {
    /// Finite samples used (over all segments).
    pub n_samples: usize,
    /// Number of lags `h` in the statistic.
    pub lags: usize,
    /// Normalised autocorrelation `r(τ)` at lags `1..=lags` (index 0 is lag 1).
    pub acf: Vec<f64>,
    /// The per-lag 99 % band `z/√N` with `z = Φ⁻¹(0.995) ≈ 2.576` (Whiteness). Deliberately not
    /// sysidentpy's `1.96/√(2N−1)`, which is about √2 too narrow.
    pub acf_bound_99: f64,
    /// The Ljung–Box statistic `Q`.
    pub q: f64,
    /// Degrees of freedom of the χ² reference: `lags − fitted_params`, at least 1.
    pub dof: usize,
    /// `P(χ²(dof) > Q)`.
    pub p_value: f64,
    /// `p_value ≥ 0.01`: whiteness not rejected at 1 %.
    pub white: bool,
}

/// The Ljung–Box test of `lags` lags on residual segments pooled as described in
/// [the module docs](super).
///
/// The autocorrelation is `r(τ) = R(τ)/R(0)` with `R(τ) = (1/N) Σ e[k] e[k−τ]`, every product
/// taken within one demeaned run (docs/diagnosis.md, Whiteness). The statistic generalises
/// `Q = N(N+2) Σ_{τ=1}^{h} r(τ)²/(N−τ)` (Ljung & Box 1978) to several runs by replacing `N−τ`
/// with `n_τ`, the number of products at lag `τ`, and centring each `r(τ)` on its mean under
/// the null (see `null_mean_acf`; for one run this changes `Q` by `O(h/N)`). `Q` is
/// compared with `χ²(h − fitted_params)`, the correction for a residual of a fitted ARMA-type
/// model (Boost `fit_dof`; MATLAB `lbqtest`), floored at one degree of freedom as pub.dev's
/// `max(1, h − nParams)`.
///
/// Returns `None` when `lags` is zero, there are not more than `lags + 1` finite samples, some
/// lag has no product at all (every run too short), or the residual is constant.
pub fn ljung_box(segments: &[&[f64]], lags: usize, fitted_params: usize) -> Option<Whiteness> {
    if lags == 0 {
        return None;
    }
    // A run of one sample is all mean: it carries no information about the correlation.
    let runs = demeaned_runs(segments, 2);
    let n_samples: usize = runs.iter().map(Vec::len).sum();
    if n_samples <= lags + 1 {
        return None;
    }
    let pairs: Vec<(&[f64], &[f64])> = runs.iter().map(|r| (r.as_slice(), r.as_slice())).collect();
    let (sums, counts) = pooled_lagged_products(&pairs, lags);
    let variance_sum = sums[0];
    if variance_sum.is_nan() || variance_sum <= 0.0 || counts.contains(&0) {
        return None;
    }
    let acf: Vec<f64> = sums[1..].iter().map(|s| s / variance_sum).collect();
    let n = n_samples as f64;
    let run_lens: Vec<usize> = runs.iter().map(Vec::len).collect();
    let q = n
        * (n + 2.0)
        * acf
            .iter()
            .enumerate()
            .zip(&counts[1..])
            .map(|((idx, r), &count)| (r - null_mean_acf(&run_lens, idx + 1)).powi(2) / count as f64)
            .sum::<f64>();
    let dof = lags.saturating_sub(fitted_params).max(1);
    let p_value = ChiSquared::new(dof as f64).ok()?.sf(q);
    Some(Whiteness {
        n_samples,
        lags,
        acf,
        acf_bound_99: z_two_sided_99() / n.sqrt(),
        q,
        dof,
        p_value,
        white: p_value >= WHITENESS_ALPHA,
    })
}

/// Mean of the pooled `r(lag)` of demeaned white runs of lengths `run_lens`.
///
/// Removing a run's mean makes its lagged products slightly negative on average:
/// `E[Σ_t e[t] e[t−k]] = −(n−k)σ²/n` and `E[Σ_t e[t]²] = (n−1)σ²` for i.i.d. data, so
/// `E[r(k)] ≈ −Σ_runs (n−k)/n / Σ_runs (n−1)`, which is `−(N−k)/(N(N−1))` for one run (Dufour &
/// Roy 1985). For one long run this is negligible, but for many short runs (20 runs of 50
/// samples) the bias adds up over the lags and inflates `Q` (a 1 % test rejected 7 % of white
/// series in our check), so `Q` uses `r(k)` centred on this mean.
fn null_mean_acf(run_lens: &[usize], lag: usize) -> f64 {
    let products: f64 = run_lens.iter().map(|&len| len.saturating_sub(lag) as f64 / len as f64).sum();
    let dof: usize = run_lens.iter().map(|&len| len - 1).sum();
    -products / dof as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::ledger::test_signals::{ar1, white};

    #[test]
    fn size_on_white_noise_is_near_nominal() {
        let rejections = (0..200).filter(|&seed| !ljung_box(&[&white(seed, 500)], 20, 0).unwrap().white).count();
        assert!(rejections <= 8, "{rejections} of 200 white series rejected at 1 %");
    }

    #[test]
    fn size_holds_for_many_short_segments() {
        // Without centring r(τ) on its null mean, 20 demeaned runs of 50 samples gave 28
        // rejections in 400 at 1 %.
        let rejections = (0..200)
            .filter(|&seed| {
                let runs: Vec<Vec<f64>> = (0..20).map(|run| white(1000 * seed + run, 50)).collect();
                let segments: Vec<&[f64]> = runs.iter().map(Vec::as_slice).collect();
                !ljung_box(&segments, 20, 0).unwrap().white
            })
            .count();
        assert!(rejections <= 8, "{rejections} of 200 segmented white series rejected at 1 %");
    }

    #[test]
    fn rejects_ar1_with_phi_0_3() {
        let test = ljung_box(&[&ar1(7, 1000, 0.3)], 20, 0).unwrap();
        assert!(!test.white, "p = {}", test.p_value);
        assert!(test.acf[0] > test.acf_bound_99);
        assert!((test.acf[0] - 0.3).abs() < 0.1, "r(1) = {}", test.acf[0]);
    }

    #[test]
    fn acf_bound_is_textbook_99_percent_not_sysidentpy() {
        let n = 400;
        let test = ljung_box(&[&white(1, n)], 10, 0).unwrap();
        assert!((test.acf_bound_99 - 2.576 / (n as f64).sqrt()).abs() < 1e-4);
        let sysidentpy = 1.96 / ((2 * n - 1) as f64).sqrt();
        assert!(test.acf_bound_99 > 1.8 * sysidentpy);
    }

    #[test]
    fn fitted_params_reduce_dof_to_at_least_one() {
        let series = white(3, 300);
        assert_eq!(ljung_box(&[&series], 10, 3).unwrap().dof, 7);
        assert_eq!(ljung_box(&[&series], 10, 30).unwrap().dof, 1);
    }

    #[test]
    fn segments_with_different_offsets_stay_white() {
        // Concatenated, the offset step is a strong low-frequency component; as two segments,
        // each demeaned, the joins add nothing.
        let first: Vec<f64> = white(11, 400).iter().map(|e| e + 5.0).collect();
        let second: Vec<f64> = white(12, 400).iter().map(|e| e - 5.0).collect();
        let split = ljung_box(&[&first, &second], 20, 0).unwrap();
        assert!(split.white, "p = {}", split.p_value);
        assert!(split.acf.iter().all(|r| r.abs() < split.acf_bound_99));
        let joined: Vec<f64> = first.iter().chain(&second).copied().collect();
        assert!(!ljung_box(&[&joined], 20, 0).unwrap().white);
    }

    #[test]
    fn non_finite_samples_split_the_segment() {
        let mut series = white(5, 600);
        series[100] = f64::NAN;
        series[300] = f64::INFINITY;
        let test = ljung_box(&[&series], 10, 0).unwrap();
        // 100 + 199 + 299 finite samples in three runs.
        assert_eq!(test.n_samples, 598);
        assert!(test.q.is_finite() && test.p_value.is_finite());
    }

    #[test]
    fn degenerate_inputs_give_none() {
        assert!(ljung_box(&[], 10, 0).is_none());
        assert!(ljung_box(&[&[1.0, 2.0, 3.0]], 10, 0).is_none());
        assert!(ljung_box(&[&[2.0; 100]], 10, 0).is_none());
        assert!(ljung_box(&[&[f64::NAN; 100]], 10, 0).is_none());
        assert!(ljung_box(&[&white(1, 100)], 0, 0).is_none());
    }
}

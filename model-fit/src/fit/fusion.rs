//! Fit of the fusion filter (estimator_core::fusion): the correlation time of the eGK's error
//! and the steady-state gain of the scalar Kalman filter that observes it through the pressure
//! path, chosen on the training samples of the roll runs to minimise the fused estimate's
//! error against the balance (docs/equations.md, Fusion design: "set Q by grid search minimising
//! the error, then check the innovations").
//!
//! For a given correlation `rho` and a ratio `q / r` of process to measurement noise, the
//! steady-state gain of the scalar filter solves the scalar Riccati equation
//! `P = rho^2 P r / (P + r) + q` in closed form; the grid runs over `q / r` and `T_e`.

use std::ops::Range;

use estimator_core::coeffs::FusionParams;
use estimator_core::fusion::Fusion;
use serde::Serialize;

/// Correlation times of the eGK error tried, s.
const CORRELATION_TIMES_S: [f64; 7] = [0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0];

/// Ratios `q / r` tried (log-spaced).
fn noise_ratios() -> impl Iterator<Item = f64> {
    (0..=24).map(|step| 10f64.powf(-8.0 + 0.333 * f64::from(step)))
}

/// One run's stage outputs for the fusion fit.
#[derive(Debug, Clone)]
pub struct FusionData<'a> {
    /// eGK estimate per sample.
    pub cl_egk: &'a [f64],
    /// Pressure-path estimate per sample (NaN where the pressure path measured nothing).
    pub cl_pressure: &'a [f64],
    /// Balance roll moment (NaN where missing).
    pub cl: &'a [f64],
    /// Samples to score.
    pub range: Range<usize>,
}

/// The chosen fusion and its training errors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FusionFit {
    /// Correlation time of the eGK error, s.
    pub correlation_time_s: f64,
    /// `rho = exp(-dt / T_e)`.
    pub rho: f64,
    /// Steady-state gain.
    pub gain: f64,
    /// Training RMS of the fused estimate.
    pub rms_fused: f64,
    /// Training RMS of the eGK alone.
    pub rms_egk: f64,
    /// Training RMS of the pressure path alone.
    pub rms_pressure: f64,
}

impl FusionFit {
    /// The core's parameters.
    #[must_use]
    pub fn params(&self) -> FusionParams {
        FusionParams { rho: self.rho as f32, gain: self.gain as f32 }
    }
}

/// Steady-state gain of `e[k] = rho e[k-1] + w` (variance q) observed with noise of variance
/// r, for `ratio = q / r`: the positive root of `P^2 + (r (1 - rho^2) - q) P - q r = 0` for the
/// prior variance P, then `L = P / (P + r)`.
#[must_use]
pub fn steady_gain(rho: f64, ratio: f64) -> f64 {
    let (q, r) = (ratio, 1.0);
    let b = r * (1.0 - rho * rho) - q;
    let prior = 0.5 * (-b + (b * b + 4.0 * q * r).sqrt());
    prior / (prior + r)
}

/// Runs the core's fusion ([`estimator_core::fusion::Fusion`]) in f64 and returns the fused
/// estimate; a non-finite pressure estimate is a step the pressure path measured nothing.
#[must_use]
pub fn fuse(rho: f64, gain: f64, cl_egk: &[f64], cl_pressure: &[f64]) -> Vec<f64> {
    let params = FusionParams { rho, gain };
    let mut fusion = Fusion::new();
    cl_egk
        .iter()
        .zip(cl_pressure)
        .map(|(&egk, &pressure)| fusion.step(&params, egk, pressure.is_finite().then_some(pressure)).0)
        .collect()
}

/// Grid search over the correlation time and the noise ratio.
#[must_use]
pub fn fit_fusion(dt_s: f64, data: &[FusionData<'_>]) -> FusionFit {
    let score = |estimate: &dyn Fn(&FusionData<'_>) -> Vec<f64>| rms(data, estimate);
    let rms_egk = score(&|d| d.cl_egk.to_vec());
    let rms_pressure = score(&|d| d.cl_pressure.to_vec());
    let mut best =
        FusionFit { correlation_time_s: f64::INFINITY, rho: 1.0, gain: 0.0, rms_fused: rms_egk, rms_egk, rms_pressure };
    for correlation_time_s in CORRELATION_TIMES_S {
        let rho = (-dt_s / correlation_time_s).exp();
        for ratio in noise_ratios() {
            let gain = steady_gain(rho, ratio);
            let fused = score(&|d| fuse(rho, gain, d.cl_egk, d.cl_pressure));
            if fused < best.rms_fused {
                best = FusionFit { correlation_time_s, rho, gain, rms_fused: fused, rms_egk, rms_pressure };
            }
        }
    }
    best
}

fn rms(data: &[FusionData<'_>], estimate: &dyn Fn(&FusionData<'_>) -> Vec<f64>) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    for d in data {
        let values = estimate(d);
        for idx in d.range.clone() {
            let (value, measured) = (values[idx], d.cl[idx]);
            if value.is_finite() && measured.is_finite() {
                sum += (value - measured).powi(2);
                count += 1;
            }
        }
    }
    if count == 0 { f64::NAN } else { (sum / count as f64).sqrt() }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steady_gain_satisfies_the_scalar_riccati_equation() {
        for (rho, ratio) in [(0.999, 1e-4), (0.9, 0.5), (0.0, 2.0)] {
            let gain = steady_gain(rho, ratio);
            let prior = gain / (1.0 - gain);
            let posterior = prior * 1.0 / (prior + 1.0);
            assert!((rho * rho * posterior + ratio - prior).abs() < 1e-12, "{rho} {ratio}");
        }
    }

    #[test]
    fn fusion_recovers_a_slow_bias_from_a_noisy_pressure_path() {
        let n = 20_000;
        let truth: Vec<f64> = (0..n).map(|k| (k as f64 * 0.01).sin() * 0.01).collect();
        let egk: Vec<f64> = truth.iter().map(|t| t + 0.002).collect();
        let pressure: Vec<f64> =
            truth.iter().enumerate().map(|(k, t)| t + 0.003 * ((k * 7919 % 101) as f64 / 50.0 - 1.0)).collect();
        let data = [FusionData { cl_egk: &egk, cl_pressure: &pressure, cl: &truth, range: 2000..n }];
        let fit = fit_fusion(1e-3, &data);
        assert!(fit.rms_fused < 0.3 * fit.rms_egk, "{fit:?}");
        assert!(fit.rms_fused < fit.rms_pressure, "{fit:?}");
    }
}

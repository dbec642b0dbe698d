//! Signals the fits derive from a run, computed in f64 exactly as the core computes them in
//! f32: held inputs (a missing sample holds the last valid one), the filtered roll rate and
//! acceleration (`estimator_core::rate`), and the angle of attack per sample.

use estimator_core::coeffs::RateFilter;
use estimator_core::rate::RateEstimator;
use firmware_sim::dataset::Run;

/// The kinematic and actuation signals of one run, sample by sample.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSignals {
    /// Roll angle, rad (held over missing samples).
    pub phi_rad: Vec<f64>,
    /// Filtered roll rate, rad/s.
    pub phi_dot_rad_s: Vec<f64>,
    /// Filtered roll acceleration, rad/s^2.
    pub phi_ddot_rad_s2: Vec<f64>,
    /// Angle of attack, deg (held over missing samples).
    pub alpha_deg: Vec<f64>,
    /// Port and starboard Cmu (held over missing samples, never below zero).
    pub cmu: [Vec<f64>; 2],
    /// Measured roll moment (NaN where missing).
    pub cl: Vec<f64>,
}

impl RunSignals {
    /// Derives the signals of `run` with the core's rate filter at step `dt_s`.
    #[must_use]
    pub fn new(run: &Run, filter: &RateFilter, dt_s: f64) -> Self {
        let channels = &run.channels;
        let phi_rad: Vec<f64> = hold_missing(&channels.phi_deg, 0.0).iter().map(|phi| phi.to_radians()).collect();
        let alpha: Vec<f64> = (0..channels.len()).map(|idx| channels.alpha_at(idx, run.meta.alpha_deg)).collect();
        let (phi_dot_rad_s, phi_ddot_rad_s2) = differentiate(&phi_rad, filter, dt_s);
        Self {
            phi_rad,
            phi_dot_rad_s,
            phi_ddot_rad_s2,
            alpha_deg: hold_missing(&alpha, run.meta.alpha_deg),
            cmu: [hold_missing(&channels.cmu_port, 0.0), hold_missing(&channels.cmu_stbd, 0.0)]
                .map(|cmu| cmu.into_iter().map(|value| value.max(0.0)).collect()),
            cl: channels.cl.clone(),
        }
    }

    /// Number of samples.
    #[must_use]
    pub fn len(&self) -> usize {
        self.phi_rad.len()
    }

    /// True when the run has no samples.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.phi_rad.is_empty()
    }
}

/// Replaces each missing (non-finite) sample by the last valid one (`initial` before the first).
#[must_use]
pub fn hold_missing(values: &[f64], initial: f64) -> Vec<f64> {
    let mut held = initial;
    values
        .iter()
        .map(|&value| {
            if value.is_finite() {
                held = value;
            }
            held
        })
        .collect()
}

/// First-order lag `tau y' + y = u`, discretised exactly for an input held over each step,
/// started at the first input (steady state).
#[must_use]
pub fn first_order_lag(values: &[f64], tau_s: f64, dt_s: f64) -> Vec<f64> {
    let pole = (-dt_s / tau_s.max(1e-12)).exp();
    let mut state = values.first().copied().unwrap_or(0.0);
    values
        .iter()
        .map(|&u| {
            let out = state;
            state = pole * state + (1.0 - pole) * u;
            out
        })
        .collect()
}

/// The core's cascaded filtered differentiators ([`RateEstimator`]) in f64: `y[k] = p y[k-1] +
/// (1 - p) (u[k] - u[k-1]) / dt`, first for the rate, then for the acceleration. The angle must
/// be finite (hold missing samples first, as the estimator does).
#[must_use]
pub fn differentiate(phi_rad: &[f64], filter: &RateFilter, dt_s: f64) -> (Vec<f64>, Vec<f64>) {
    let filter = filter.cast::<f64>();
    let mut rates = RateEstimator::new();
    phi_rad
        .iter()
        .map(|&phi| rates.step(&filter, 1.0 / dt_s, phi))
        .map(|r| (r.phi_dot_rad_s, r.phi_ddot_rad_s2))
        .unzip()
}

/// Zero-phase low-pass: a second-order Butterworth filter (bilinear transform with
/// pre-warping) run forwards then backwards (`filtfilt`), so the result has no lag and an
/// effective fourth-order magnitude response. Used to denoise regressors of the one-step SINDy
/// fits (errors in the regressors bias least squares towards zero; Söderström & Stoica,
/// System Identification, section 7.6). Non-finite samples are bridged by holding.
#[must_use]
pub fn zero_phase_lowpass(values: &[f64], corner_hz: f64, sample_hz: f64) -> Vec<f64> {
    let held = hold_missing(values, values.iter().copied().find(|v| v.is_finite()).unwrap_or(0.0));
    let (b, a) = butterworth2(corner_hz, sample_hz);
    let forward = biquad(&held, &b, &a);
    let mut backward: Vec<f64> = forward.into_iter().rev().collect();
    backward = biquad(&backward, &b, &a);
    backward.reverse();
    backward
}

/// [`zero_phase_lowpass`] with the ends extended by odd reflection (`2 x_0 - x_k`, as SciPy's
/// `filtfilt` with `padtype="odd"`), so that a signal still moving at an end keeps its value
/// and its slope there. For signals that are differentiated: started at rest, each pass flattens
/// a moving signal at its edges, and the second derivative of a roll angle still rolling at a
/// run's end came out five to eight times its RMS over the last 0.1 s (a 40 Hz corner); a lightly
/// damped resonator driven by it then rang through the held-out part.
#[must_use]
pub fn zero_phase_lowpass_extended(values: &[f64], corner_hz: f64, sample_hz: f64) -> Vec<f64> {
    let n = values.len();
    if n < 2 {
        return zero_phase_lowpass(values, corner_hz, sample_hz);
    }
    let held = hold_missing(values, values.iter().copied().find(|v| v.is_finite()).unwrap_or(0.0));
    // Twenty radians of the corner: the start-up transient (damping ratio 0.71) has decayed to
    // below 1e-6 of itself by then.
    let pad = ((20.0 * sample_hz / (std::f64::consts::TAU * corner_hz.max(f64::MIN_POSITIVE))).ceil() as usize)
        .clamp(1, n - 1);
    let (first, last) = (held[0], held[n - 1]);
    let extended: Vec<f64> = (1..=pad)
        .rev()
        .map(|k| 2.0 * first - held[k])
        .chain(held.iter().copied())
        .chain((1..=pad).map(|k| 2.0 * last - held[n - 1 - k]))
        .collect();
    zero_phase_lowpass(&extended, corner_hz, sample_hz)[pad..pad + n].to_vec()
}

/// Coefficients of a second-order Butterworth low-pass at `corner_hz`.
fn butterworth2(corner_hz: f64, sample_hz: f64) -> ([f64; 3], [f64; 3]) {
    let warped = (std::f64::consts::PI * corner_hz / sample_hz).tan();
    let k2 = warped * warped;
    let norm = 1.0 + std::f64::consts::SQRT_2 * warped + k2;
    let b = [k2 / norm, 2.0 * k2 / norm, k2 / norm];
    let a = [1.0, 2.0 * (k2 - 1.0) / norm, (1.0 - std::f64::consts::SQRT_2 * warped + k2) / norm];
    (b, a)
}

/// Direct form II transposed, started in steady state at the first sample (no start-up step).
fn biquad(values: &[f64], b: &[f64; 3], a: &[f64; 3]) -> Vec<f64> {
    let first = values.first().copied().unwrap_or(0.0);
    // Steady state for a constant input equal to the first sample.
    let mut z1 = first * (b[1] + b[2] - a[1] - a[2]);
    let mut z2 = first * (b[2] - a[2]);
    values
        .iter()
        .map(|&x| {
            let y = b[0] * x + z1;
            z1 = b[1] * x - a[1] * y + z2;
            z2 = b[2] * x - a[2] * y;
            y
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_extended_lowpass_keeps_a_ramps_slope_at_both_ends() {
        // A ramp through the whole record: its second derivative is zero everywhere.
        let ramp: Vec<f64> = (0..2000).map(|i| 0.5 + 1e-3 * i as f64).collect();
        let second =
            |x: &[f64]| -> f64 { x.windows(3).map(|w| (w[2] - 2.0 * w[1] + w[0]).abs()).fold(0.0, f64::max) / 1e-6 };
        let extended = zero_phase_lowpass_extended(&ramp, 40.0, 1000.0);
        assert!(second(&extended) < 1e-3, "{}", second(&extended));
        let worst = extended.iter().zip(&ramp).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-6, "{worst}");
        // Started at rest, the plain filter bends it at the ends.
        assert!(second(&zero_phase_lowpass(&ramp, 40.0, 1000.0)) > 10.0);
    }

    #[test]
    fn lowpass_keeps_slow_content_without_lag_and_removes_fast_content() {
        let n = 4000;
        let slow: Vec<f64> = (0..n).map(|k| (std::f64::consts::TAU * 2.0 * k as f64 / 1000.0).sin()).collect();
        let fast: Vec<f64> = (0..n).map(|k| 0.3 * (std::f64::consts::TAU * 200.0 * k as f64 / 1000.0).sin()).collect();
        let mixed: Vec<f64> = slow.iter().zip(&fast).map(|(s, f)| s + f).collect();
        let filtered = zero_phase_lowpass(&mixed, 30.0, 1000.0);
        let worst = (500..n - 500).map(|k| (filtered[k] - slow[k]).abs()).fold(0.0, f64::max);
        assert!(worst < 0.01, "{worst}");
        let constant = zero_phase_lowpass(&[1.0; 10], 30.0, 1000.0);
        assert!(constant.iter().all(|v| (v - 1.0).abs() < 1e-12), "{constant:?}");
    }

    #[test]
    fn differentiator_matches_the_core_in_f64() {
        let filter = estimator_core::prior::PRIOR.rate_filter;
        let phi: Vec<f64> = (0..3000).map(|k| 0.4 * (k as f64 * 3e-3).sin()).collect();
        let (rate, _) = differentiate(&phi, &filter, 1e-3);
        let mut core = estimator_core::rate::RateEstimator::new();
        for (k, &value) in phi.iter().enumerate() {
            let core_rate = core.step(&filter, 1e3, value as f32).phi_dot_rad_s;
            assert!((f64::from(core_rate) - rate[k]).abs() < 1e-3, "{k}");
        }
    }
}

//! The plant's input path (G5): the recorded Cmu reaches the jets late (a pure delay of the
//! pneumatic line) or smoothed (a first-order lag of valve and plenum). Both re-run the sim's own
//! plant (estimator-core) on the modified Cmu; the column is the change of its moment.

use firmware_sim::effect::Effect;

use super::{BalanceCandidate, Context, Params, Shape, difference, first_order_lag, gains, log_grid};
use crate::diagnose::streams::RunStreams;

/// `actuator_delay`: the plant driven by `Cmu(t - d)`, d from half a sample to 250 ms (a long
/// pneumatic line at the speed of sound, docs/equations.md, Actuator and plant magnitudes).
#[derive(Debug, Clone, Copy)]
pub struct ActuatorDelay;

/// `actuator_lag`: the plant driven by a first-order lag of Cmu, tau from one sample to 0.5 s.
#[derive(Debug, Clone, Copy)]
pub struct ActuatorLag;

const SEPARATOR: &str = "a bench step test of the valve and runs at a second free-stream speed (the pneumatic part is fixed in seconds, the aerodynamic part scales with c/U)";

impl BalanceCandidate for ActuatorDelay {
    fn regressors(&self) -> &'static str {
        "the sim's plant re-run on the recorded Cmu delayed by d, less its moment"
    }

    fn effect(&self) -> Option<Effect> {
        Some(Effect::ActuatorDelay)
    }

    fn separating_experiment(&self) -> &'static str {
        SEPARATOR
    }

    fn shapes(&self, sample_hz: f64, _context: &Context<'_>) -> Vec<Shape> {
        log_grid(0.5 / sample_hz, 0.25, 40).into_iter().map(|delay_s| Shape::Delay { delay_s }).collect()
    }

    fn columns(&self, shape: &Shape, run: &RunStreams, _run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        let Shape::Delay { delay_s } = *shape else { return Vec::new() };
        if !run.blows() {
            return vec![vec![0.0; run.len()]];
        }
        let delay_samples = delay_s / (1.0 / run.sample_hz);
        let delayed = run.cmu.clone().map(|cmu| fractional_delay(&cmu, delay_samples));
        vec![difference(&run.plant_response(context.set, &delayed), &run.cl_afc())]
    }

    fn params(&self, _shape: &Shape, beta: &[f64], _context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        gains(&["gain"], beta)
    }
}

impl BalanceCandidate for ActuatorLag {
    fn regressors(&self) -> &'static str {
        "the sim's plant re-run on the recorded Cmu through a first-order lag, less its moment"
    }

    fn effect(&self) -> Option<Effect> {
        Some(Effect::ActuatorLag)
    }

    fn separating_experiment(&self) -> &'static str {
        SEPARATOR
    }

    fn shapes(&self, sample_hz: f64, _context: &Context<'_>) -> Vec<Shape> {
        log_grid(1.0 / sample_hz, 0.5, 36).into_iter().map(|tau_s| Shape::Lag { tau_s }).collect()
    }

    fn columns(&self, shape: &Shape, run: &RunStreams, _run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        let Shape::Lag { tau_s } = *shape else { return Vec::new() };
        if !run.blows() {
            return vec![vec![0.0; run.len()]];
        }
        let lagged = run.cmu.clone().map(|cmu| first_order_lag(&cmu, tau_s, 1.0 / run.sample_hz));
        vec![difference(&run.plant_response(context.set, &lagged), &run.cl_afc())]
    }

    fn params(&self, _shape: &Shape, beta: &[f64], _context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        gains(&["gain"], beta)
    }
}

/// `x(t - d)` for a delay of `d` samples (fractional: linear interpolation between samples;
/// the first sample is held before the start).
#[must_use]
pub fn fractional_delay(values: &[f64], delay_samples: f64) -> Vec<f64> {
    let whole = delay_samples.floor();
    let frac = delay_samples - whole;
    let whole = whole as usize;
    let first = values.first().copied().unwrap_or(0.0);
    let at = |idx: isize| if idx < 0 { first } else { values[idx as usize] };
    (0..values.len())
        .map(|idx| {
            let base = idx as isize - whole as isize;
            (1.0 - frac) * at(base) + frac * at(base - 1)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fractional_delay_interpolates() {
        let ramp: Vec<f64> = (0..10).map(f64::from).collect();
        let delayed = fractional_delay(&ramp, 2.5);
        assert!((delayed[6] - 3.5).abs() < 1e-12);
        assert_eq!(delayed[0], 0.0);
    }
}

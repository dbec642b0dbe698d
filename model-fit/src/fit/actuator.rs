//! The jets' actuator response (`estimator_core::coeffs::ActuatorResponse`):
//! the measured Cmu against the commanded one (the dataset's optional `cmu_port_cmd` and
//! `cmu_stbd_cmd` columns), `Cmu[k] = p Cmu[k-1] + (1 - p) g cmd[k - 1 - d]`, fitted on the
//! training part of every run that commands the jet.
//!
//! The dead time `d` is chosen on a grid (0 to `DEMAND_SLOTS - 1` steps) by least squares of the
//! one-step equation (ARX: `Cmu[k]` on `Cmu[k-1]` and `cmd[k-1-d]`; Ljung, System
//! Identification, 2nd ed., section 4.2). The core runs the response on the demands alone while
//! the measurement is lost (for seconds), so pole and gain are then refined for the free run
//! (output error, Ljung section 4.3) at that dead time and its neighbours: a golden-section
//! search on the pole with the gain by least squares, which is linear in it.
//!
//! Without command columns, or without a commanded jet, the response is the identity (the Cmu is
//! the demand) or the other jet's, and the report says so.

use estimator_core::actuator::DemandHistory;
use estimator_core::coeffs::{ActuatorResponse, DEMAND_SLOTS};
use firmware_sim::dataset::Dataset;
use serde::Serialize;

use super::split::Split;

/// Largest pole searched by the free-run refinement (a time constant of 1,000 steps).
const POLE_MAX: f64 = 0.999;
/// Golden-section iterations on the pole: the bracket shrinks to 0.618^60 of [0, 0.999].
const GOLDEN_ITERATIONS: usize = 60;
/// Dead times either side of the one-step choice also tried for the free run, steps.
const DELAY_NEIGHBOURS: usize = 2;

/// How a jet's response was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ResponseSource {
    /// Fitted on this jet's command and measurement.
    Fitted,
    /// The other jet's fitted response (this jet is never commanded).
    Mirrored,
    /// The identity: no command columns, or no commanded jet, or a fit out of range.
    Identity,
}

/// One jet's response and the numbers behind it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ActuatorFit {
    /// How it was obtained.
    pub source: ResponseSource,
    /// Dead time, steps.
    pub delay_steps: u8,
    /// Pole of the lag.
    pub pole: f64,
    /// Steady-state gain.
    pub gain: f64,
    /// Training samples used.
    pub n_samples: usize,
    /// RMS of the measured Cmu over them.
    pub rms_cmu: f64,
    /// RMS error of the one-step prediction (from the measured previous Cmu).
    pub rms_one_step: Option<f64>,
    /// RMS error of the response run on the commands alone (what the core does when the
    /// measurement is lost).
    pub rms_free_run: Option<f64>,
    /// RMS error of the identity run on the commands alone (Cmu = last command), for comparison.
    pub rms_identity: Option<f64>,
}

/// One jet's training samples: per run, the measured and commanded Cmu over the training part.
struct JetData<'a> {
    runs: Vec<(&'a [f64], &'a [f64])>,
}

/// Fits both jets' responses on the training part of `dataset`; `notes` gets what was not
/// fitted.
#[must_use]
pub fn fit_actuators(dataset: &Dataset, split: &Split, notes: &mut Vec<String>) -> [ActuatorFit; 2] {
    let fits = [0, 1].map(|side| jet_data(dataset, split, side).and_then(|data| fit_jet(&data)));
    match fits {
        [Some(port), Some(starboard)] => [port, starboard],
        [Some(port), None] => {
            notes.push("the starboard jet is never commanded: its actuator response is the port jet's".into());
            let mirrored = ActuatorFit { source: ResponseSource::Mirrored, ..identity_fit() };
            [port.clone(), ActuatorFit { delay_steps: port.delay_steps, pole: port.pole, gain: port.gain, ..mirrored }]
        }
        [None, Some(starboard)] => {
            notes.push("the port jet is never commanded: its actuator response is the starboard jet's".into());
            let mirrored = ActuatorFit { source: ResponseSource::Mirrored, ..identity_fit() };
            let port = ActuatorFit {
                delay_steps: starboard.delay_steps,
                pole: starboard.pole,
                gain: starboard.gain,
                ..mirrored
            };
            [port, starboard]
        }
        [None, None] => {
            notes.push(
                "no commanded Cmu (`cmu_port_cmd`, `cmu_stbd_cmd`) with blowing in the training part, or no usable fit: \
                 the actuator response is the identity (a missing Cmu is the last demand)"
                    .into(),
            );
            [identity_fit(), identity_fit()]
        }
    }
}

impl ActuatorFit {
    /// The core's table.
    #[must_use]
    pub fn response(&self) -> ActuatorResponse {
        ActuatorResponse { delay_steps: self.delay_steps, pole: self.pole as f32, gain: self.gain as f32 }
    }
}

fn identity_fit() -> ActuatorFit {
    ActuatorFit {
        source: ResponseSource::Identity,
        delay_steps: 0,
        pole: 0.0,
        gain: 1.0,
        n_samples: 0,
        rms_cmu: 0.0,
        rms_one_step: None,
        rms_free_run: None,
        rms_identity: None,
    }
}

/// The training parts of the runs that command jet `side` (a command above zero).
fn jet_data<'a>(dataset: &'a Dataset, split: &Split, side: usize) -> Option<JetData<'a>> {
    let runs: Vec<(&[f64], &[f64])> = dataset
        .runs
        .iter()
        .filter_map(|run| {
            let channels = &run.channels;
            let (measured, command) = if side == 0 {
                (&channels.cmu_port, channels.cmu_port_cmd.as_ref()?)
            } else {
                (&channels.cmu_stbd, channels.cmu_stbd_cmd.as_ref()?)
            };
            let training = split.training(channels.len().min(command.len()).min(measured.len()));
            let (measured, command) = (&measured[training.clone()], &command[training]);
            command.iter().any(|&cmd| cmd > 0.0).then_some((measured, command))
        })
        .collect();
    (!runs.is_empty()).then_some(JetData { runs })
}

/// The dead time by one-step least squares, then pole and gain for the free run.
fn fit_jet(data: &JetData<'_>) -> Option<ActuatorFit> {
    let (delay_steps, one_step_rms) = (0..DEMAND_SLOTS)
        .filter_map(|delay| one_step(data, delay).map(|(_, _, rms)| (delay, rms)))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    let low = delay_steps.saturating_sub(DELAY_NEIGHBOURS);
    let high = (delay_steps + DELAY_NEIGHBOURS).min(DEMAND_SLOTS - 1);
    let (delay_steps, pole, gain, free_rms) = (low..=high)
        .filter_map(|delay| {
            let (pole, gain, rms) = free_run_fit(data, delay)?;
            Some((delay, pole, gain, rms))
        })
        .min_by(|a, b| a.3.total_cmp(&b.3))?;
    let in_range = (0.0..1.0).contains(&pole) && gain > 0.0 && gain <= 10.0;
    let (sum_sq, n_samples) = data
        .runs
        .iter()
        .flat_map(|(measured, _)| measured.iter())
        .filter(|cmu| cmu.is_finite())
        .fold((0.0, 0usize), |(sum, n), cmu| (sum + cmu * cmu, n + 1));
    in_range.then(|| ActuatorFit {
        source: ResponseSource::Fitted,
        delay_steps: delay_steps as u8,
        pole,
        gain,
        n_samples,
        rms_cmu: (sum_sq / n_samples.max(1) as f64).sqrt(),
        rms_one_step: Some(one_step_rms),
        rms_free_run: Some(free_rms),
        rms_identity: Some(free_run_rms(data, 0, 0.0, 1.0)),
    })
}

/// One-step least squares at dead time `delay`: `(pole, gain, rms)` of
/// `Cmu[k] = a Cmu[k-1] + b cmd[k-1-delay]`, pole `a`, gain `b / (1 - a)`.
fn one_step(data: &JetData<'_>, delay: usize) -> Option<(f64, f64, f64)> {
    let (mut sxx, mut sxu, mut suu, mut sxy, mut suy, mut syy, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0usize);
    for (measured, command) in &data.runs {
        for k in (delay + 1)..measured.len() {
            let (y, x, u) = (measured[k], measured[k - 1], command[k - 1 - delay]);
            if !(y.is_finite() && x.is_finite() && u.is_finite()) {
                continue;
            }
            (sxx, sxu, suu, sxy, suy, syy) =
                (sxx + x * x, sxu + x * u, suu + u * u, sxy + x * y, suy + u * y, syy + y * y);
            n += 1;
        }
    }
    let det = sxx * suu - sxu * sxu;
    if n < 3 || det.abs() <= 1e-12 * sxx * suu {
        return None;
    }
    let a = (sxy * suu - suy * sxu) / det;
    let b = (suy * sxx - sxy * sxu) / det;
    let sum_sq = (syy - a * sxy - b * suy).max(0.0);
    let gain = if (1.0 - a).abs() > 1e-9 { b / (1.0 - a) } else { f64::NAN };
    Some((a, gain, (sum_sq / n as f64).sqrt()))
}

/// Pole (golden section on `[0, POLE_MAX]`) and gain (least squares) of the free run at dead
/// time `delay`: `(pole, gain, rms)`.
fn free_run_fit(data: &JetData<'_>, delay: usize) -> Option<(f64, f64, f64)> {
    let cost = |pole: f64| {
        let gain = free_run_gain(data, delay, pole);
        (gain, free_run_rms(data, delay, pole, gain))
    };
    let ratio = (5f64.sqrt() - 1.0) / 2.0;
    let (mut low, mut high) = (0.0, POLE_MAX);
    let (mut left, mut right) = (high - ratio * (high - low), low + ratio * (high - low));
    let (mut cost_left, mut cost_right) = (cost(left).1, cost(right).1);
    for _ in 0..GOLDEN_ITERATIONS {
        if cost_left <= cost_right {
            (high, right, cost_right) = (right, left, cost_left);
            left = high - ratio * (high - low);
            cost_left = cost(left).1;
        } else {
            (low, left, cost_left) = (left, right, cost_right);
            right = low + ratio * (high - low);
            cost_right = cost(right).1;
        }
    }
    let pole = 0.5 * (low + high);
    let (gain, rms) = cost(pole);
    (gain.is_finite() && rms.is_finite()).then_some((pole, gain, rms))
}

/// The unit-gain response to the commands, per run (started at rest): the core's demand
/// history and response ([`DemandHistory`], [`ActuatorResponse`]) in f64, each command noted
/// after its step (a command is never above the jet's range here: no limit).
fn unit_response(command: &[f64], delay: usize, pole: f64) -> Vec<f64> {
    let response = ActuatorResponse { delay_steps: u8::try_from(delay).unwrap_or(u8::MAX), pole, gain: 1.0 };
    let mut history = DemandHistory::new();
    let mut cmu = 0.0;
    command
        .iter()
        .map(|&demand| {
            let value = cmu;
            history.note([demand, demand], f64::INFINITY);
            cmu = history.predict(&response, 0, cmu);
            value
        })
        .collect()
}

/// Least-squares gain of the free run at `(delay, pole)`.
fn free_run_gain(data: &JetData<'_>, delay: usize, pole: f64) -> f64 {
    let (mut ss, mut sy) = (0.0, 0.0);
    for (measured, command) in &data.runs {
        for (s, y) in unit_response(command, delay, pole).iter().zip(measured.iter()) {
            if y.is_finite() {
                (ss, sy) = (ss + s * s, sy + s * y);
            }
        }
    }
    if ss > 0.0 { sy / ss } else { f64::NAN }
}

/// RMS error of the free run at `(delay, pole, gain)`.
fn free_run_rms(data: &JetData<'_>, delay: usize, pole: f64, gain: f64) -> f64 {
    let (mut sum_sq, mut n) = (0.0, 0usize);
    for (measured, command) in &data.runs {
        for (s, y) in unit_response(command, delay, pole).iter().zip(measured.iter()) {
            if y.is_finite() {
                sum_sq += (gain * s - y).powi(2);
                n += 1;
            }
        }
    }
    (sum_sq / n.max(1) as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A first-order-plus-dead-time valve with multiplicative noise, on a sequence of holds.
    fn valve(delay: usize, pole: f64, gain: f64, n: usize) -> (Vec<f64>, Vec<f64>) {
        let command: Vec<f64> = (0..n).map(|k| [0.0, 0.006, 0.002, 0.009, 0.004][(k / 173) % 5]).collect();
        let mut state = 0.0;
        let measured = (0..n)
            .map(|k| {
                let value = state * (1.0 + 0.005 * ((k as f64 * 12.9898).sin() * 43758.5453).fract());
                let delayed = k.checked_sub(delay).map_or(0.0, |idx| command[idx]);
                state = pole * state + (1.0 - pole) * gain * delayed;
                value
            })
            .collect();
        (measured, command)
    }

    #[test]
    fn a_first_order_valve_with_dead_time_is_recovered() {
        let (measured, command) = valve(5, 0.72, 0.95, 20_000);
        let data = JetData { runs: vec![(&measured, &command)] };
        let fit = fit_jet(&data).expect("fits");
        assert_eq!(fit.delay_steps, 5, "{fit:?}");
        assert!((fit.pole - 0.72).abs() < 0.01, "{fit:?}");
        assert!((fit.gain - 0.95).abs() < 0.01, "{fit:?}");
        assert!(fit.rms_free_run.unwrap() < 0.2 * fit.rms_identity.unwrap(), "{fit:?}");
    }
}

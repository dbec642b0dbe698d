//! The plant's input path (G5): the recorded Cmu reaches the jets late (a pure delay of the
//! pneumatic line, alone or followed by a short smoothing) or smoothed (a low-pass of valve and
//! plenum of first or second order, or a valve whose stroke is rate limited), on one jet or both
//! (docs/diagnosis.md, Actuator delay and lag). Every form re-runs the sim's own plant
//! (estimator-core) on the modified Cmu; the column is the change of its moment, one gain.

use firmware_sim::effect::Effect;

use super::{
    BalanceCandidate, Context, Jets, Params, Shape, around, difference, first_order_lag, gains, grid_ratio, log_grid,
    resonator,
};
use crate::diagnose::streams::RunStreams;

/// `actuator_delay`: the plant driven by `Cmu(t - d)` of one jet or both, d from half a sample to
/// 0.5 s (the contract's range: a long pneumatic line at the speed of sound, docs/equations.md,
/// Actuator and plant magnitudes), alone or followed by a smoothing of at most a quarter of the
/// delay.
#[derive(Debug, Clone, Copy)]
pub struct ActuatorDelay;

/// `actuator_lag`: the plant driven by a unit-gain low-pass of Cmu (first order, tau 5 ms to
/// 0.5 s; second order with real or lightly damped poles), or by a rate-limited valve, each on
/// one jet or both (a valve is each jet's own).
#[derive(Debug, Clone, Copy)]
pub struct ActuatorLag;

const SEPARATOR: &str = "a bench step test of the valve and runs at a second free-stream speed (the pneumatic part is fixed in seconds, the aerodynamic part scales with c/U)";

/// Longest delay, s (the contract's range).
const DELAY_MAX_S: f64 = 0.5;

/// Shortest and longest time constant of the lag family, s (the contract's range).
const LAG_RANGE_S: (f64, f64) = (0.005, 0.5);

/// Damping ratios of the second-order valve on the coarse grid, and on the refined one: from a
/// lightly damped pair to two real poles (`zeta >= 1`; a real-pole pair far apart is a first-order
/// lag and its delay, which the first-order form and the delay family hold).
const VALVE_ZETA_COARSE: [f64; 2] = [0.4, 1.0];
const VALVE_ZETA_FINE: [f64; 5] = [0.2, 0.3, 0.45, 0.7, 1.0];

/// Shares of the delay a smoothing after it may take ("well under the delay").
const SMOOTHING_SHARES: [f64; 2] = [0.1, 0.25];

/// Delays of each jet tried around the best delay of both, as multiples of it: one line may be
/// a few times the other's length (a valve near one jet, a long hose to the other), so from a
/// third to twice the shared delay, eleven values a jet, each a fifth above the one before (the
/// pair is not refined further).
const PER_JET_RANGE: (f64, f64) = (1.0 / 3.0, 2.0);
const PER_JET_VALUES: usize = 11;

impl ActuatorDelay {
    const COARSE: usize = 24;

    fn delay_low_s(sample_hz: f64) -> f64 {
        0.5 / sample_hz
    }
}

impl BalanceCandidate for ActuatorDelay {
    fn regressors(&self) -> &'static str {
        "the sim's plant re-run on the recorded Cmu of one jet or both delayed by d (and smoothed), less its moment"
    }

    fn effect(&self) -> Option<Effect> {
        Some(Effect::ActuatorDelay)
    }

    fn separating_experiment(&self) -> &'static str {
        SEPARATOR
    }

    /// A delay per jet is named as one jet's, then the other's on the remainder.
    fn repeatable(&self) -> bool {
        true
    }

    fn unit_gain(&self) -> bool {
        true
    }

    fn shapes(&self, sample_hz: f64, context: &Context<'_>) -> Vec<Shape> {
        let grid = log_grid(Self::delay_low_s(sample_hz), DELAY_MAX_S, Self::COARSE);
        Jets::choices(context)
            .iter()
            .flat_map(|&jets| grid.iter().map(move |&delay_s| Shape::Delay { delay_s, jets, smoothing_s: 0.0 }))
            .collect()
    }

    fn refine(&self, best: &Shape, sample_hz: f64, context: &Context<'_>) -> Vec<Shape> {
        let Shape::Delay { delay_s, jets, .. } = *best else { return Vec::new() };
        let low = Self::delay_low_s(sample_hz);
        let ratio = grid_ratio(low, DELAY_MAX_S, Self::COARSE);
        let mut shapes = Vec::new();
        for delay_s in around(delay_s, ratio, 9, low, DELAY_MAX_S) {
            shapes.push(Shape::Delay { delay_s, jets, smoothing_s: 0.0 });
            for share in SMOOTHING_SHARES {
                // The smoothing adds about its own time constant to the delay: keep the sum.
                let smoothing_s = share * delay_s;
                shapes.push(Shape::Delay { delay_s: delay_s - smoothing_s, jets, smoothing_s });
            }
        }
        // A delay per jet where a shared delay (or one jet's) led: a sum of two moments each
        // delayed its own way otherwise reads as one smoothed by a low-pass. Pure delays only:
        // they shift the sim's own moments, where a smoothing re-runs the plant for every pair
        // (a third more time per diagnosis), and a smoothing "well under the delay" moves the
        // fit little beside a delay per jet.
        if context.two_jets {
            let per_jet = log_grid(PER_JET_RANGE.0 * delay_s, PER_JET_RANGE.1 * delay_s, PER_JET_VALUES);
            for &port_s in &per_jet {
                for &starboard_s in per_jet.iter().filter(|&&other| other != port_s) {
                    let (port_s, starboard_s) = (port_s.clamp(low, DELAY_MAX_S), starboard_s.clamp(low, DELAY_MAX_S));
                    shapes.push(Shape::DelayPerJet { port_s, starboard_s });
                }
            }
        }
        shapes
    }

    /// The plant is time invariant at a run's angle of attack and starts at rest, so its
    /// response to `Cmu(t - d)` is its response to `Cmu` delayed by `d`: the delay shifts the
    /// sim's own moment of the chosen jets, and only a smoothing re-runs the plant.
    fn columns(&self, shape: &Shape, run: &RunStreams, _run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        // Per jet: the delay, s, or none (a jet the form leaves alone).
        let (delays_s, jets, smoothing_s) = match *shape {
            Shape::Delay { delay_s, jets, smoothing_s } => {
                let of = |side: Jets| (jets == Jets::Both || jets == side).then_some(delay_s);
                ([of(Jets::Port), of(Jets::Starboard)], jets, smoothing_s)
            }
            Shape::DelayPerJet { port_s, starboard_s } => ([Some(port_s), Some(starboard_s)], Jets::Both, 0.0),
            _ => return Vec::new(),
        };
        if !run.blows() {
            return vec![vec![0.0; run.len()]];
        }
        let dt_s = 1.0 / run.sample_hz;
        let moments: [Vec<f64>; 2] = if smoothing_s > 0.0 {
            let smoothed = jets.apply(&run.cmu, |cmu| first_order_lag(cmu, smoothing_s, dt_s));
            run.plant_sides(context.set, &smoothed)
        } else {
            run.cl_afc_side.clone()
        };
        let shifted: [Vec<f64>; 2] = [0, 1].map(|side| match delays_s[side] {
            Some(delay_s) => fractional_delay(&moments[side], delay_s * run.sample_hz),
            None => moments[side].clone(),
        });
        vec![
            (0..run.len())
                .map(|i| shifted[0][i] + shifted[1][i] - run.cl_afc_side[0][i] - run.cl_afc_side[1][i])
                .collect(),
        ]
    }

    fn params(&self, _shape: &Shape, beta: &[f64], _context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        gains(&["gain"], beta)
    }
}

impl ActuatorLag {
    const COARSE: usize = 14;
    const VALVE_COARSE: usize = 8;
}

impl BalanceCandidate for ActuatorLag {
    fn regressors(&self) -> &'static str {
        "the sim's plant re-run on the recorded Cmu of one jet or both through a unit-gain low-pass (first or second order) or a rate limit, less its moment"
    }

    fn effect(&self) -> Option<Effect> {
        Some(Effect::ActuatorLag)
    }

    fn separating_experiment(&self) -> &'static str {
        SEPARATOR
    }

    /// A lag per jet is named as one jet's, then the other's on the remainder.
    fn repeatable(&self) -> bool {
        true
    }

    fn unit_gain(&self) -> bool {
        true
    }

    fn shapes(&self, sample_hz: f64, context: &Context<'_>) -> Vec<Shape> {
        let low = LAG_RANGE_S.0.max(1.0 / sample_hz);
        let first = log_grid(low, LAG_RANGE_S.1, Self::COARSE);
        let mut shapes: Vec<Shape> = Jets::choices(context)
            .iter()
            .flat_map(|&jets| first.iter().map(move |&tau_s| Shape::Lag { tau_s, jets }))
            .collect();
        for &jets in Jets::choices(context) {
            for tau_s in log_grid(low, LAG_RANGE_S.1, Self::VALVE_COARSE) {
                shapes.extend(VALVE_ZETA_COARSE.map(|zeta| Shape::SecondOrderLag { tau_s, zeta, jets }));
                // A full stroke as fast as the time constants span.
                shapes.push(Shape::RateLimit { full_stroke_s: tau_s, jets });
            }
        }
        shapes
    }

    fn refine(&self, best: &Shape, sample_hz: f64, _context: &Context<'_>) -> Vec<Shape> {
        let low = LAG_RANGE_S.0.max(1.0 / sample_hz);
        let high = LAG_RANGE_S.1;
        match *best {
            Shape::Lag { tau_s, jets } => around(tau_s, grid_ratio(low, high, Self::COARSE), 9, low, high)
                .into_iter()
                .map(|tau_s| Shape::Lag { tau_s, jets })
                .collect(),
            Shape::SecondOrderLag { tau_s, jets, .. } => {
                around(tau_s, grid_ratio(low, high, Self::VALVE_COARSE), 7, low, high)
                    .into_iter()
                    .flat_map(|tau_s| VALVE_ZETA_FINE.map(|zeta| Shape::SecondOrderLag { tau_s, zeta, jets }))
                    .collect()
            }
            Shape::RateLimit { full_stroke_s, jets } => {
                around(full_stroke_s, grid_ratio(low, high, Self::VALVE_COARSE), 7, low, high)
                    .into_iter()
                    .map(|full_stroke_s| Shape::RateLimit { full_stroke_s, jets })
                    .collect()
            }
            _ => Vec::new(),
        }
    }

    fn columns(&self, shape: &Shape, run: &RunStreams, _run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        if !run.blows() {
            return vec![vec![0.0; run.len()]];
        }
        let dt_s = 1.0 / run.sample_hz;
        let effective = match *shape {
            Shape::Lag { tau_s, jets } => jets.apply(&run.cmu, |cmu| first_order_lag(cmu, tau_s, dt_s)),
            Shape::SecondOrderLag { tau_s, zeta, jets } => {
                jets.apply(&run.cmu, |cmu| resonator(cmu, 1.0 / (std::f64::consts::TAU * tau_s), zeta, dt_s))
            }
            Shape::RateLimit { full_stroke_s, jets } => {
                let step = context.cmu_ref * dt_s / full_stroke_s;
                jets.apply(&run.cmu, |cmu| rate_limited(cmu, step))
            }
            _ => return Vec::new(),
        };
        vec![difference(&run.plant_response(context.set, &effective), &run.cl_afc())]
    }

    fn params(&self, _shape: &Shape, beta: &[f64], _context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        gains(&["gain"], beta)
    }
}

/// `values` followed by a valve that moves at most `step` per sample (a slew-rate limit), from
/// the first value.
#[must_use]
pub fn rate_limited(values: &[f64], step: f64) -> Vec<f64> {
    let mut state = values.first().copied().unwrap_or(0.0);
    values
        .iter()
        .map(|&target| {
            state += (target - state).clamp(-step, step);
            state
        })
        .collect()
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

    /// A rate limit follows a step at its slope, then holds the target.
    #[test]
    fn rate_limit_ramps_to_a_step() {
        let step: Vec<f64> = [vec![0.0; 3], vec![1.0; 10]].concat();
        let limited = rate_limited(&step, 0.25);
        assert_eq!(&limited[2..8], &[0.0, 0.25, 0.5, 0.75, 1.0, 1.0]);
    }

    /// An actuation run of `n` samples at 1 kHz whose jets each blow one 0.2 s pulse, from the
    /// samples `starts` (port, starboard), with the sim's plant moments of that blowing.
    fn blowing_run(context: &Context<'_>, n: usize, starts: [usize; 2]) -> RunStreams {
        let mut run = crate::diagnose::streams::synthetic_run(1000.0, vec![vec![0.0; n]], vec![vec![0.0; n]]);
        run.kind = firmware_sim::dataset::RunKind::Actuation;
        run.cmu =
            starts.map(|start| (0..n).map(|i| if (start..start + 200).contains(&i) { 0.01 } else { 0.0 }).collect());
        run.cl_afc_side = run.plant_sides(context.set, &run.cmu);
        run
    }

    /// The delay's column shifts the sim's own plant moment of the chosen jet: the plant is time
    /// invariant, so delaying its input delays its output. A port-only delay leaves the
    /// starboard jet's moment as it was.
    #[test]
    fn a_delay_of_one_jet_shifts_that_jets_moment() {
        let context = crate::diagnose::candidates::test_context();
        let n = 600;
        let run = blowing_run(&context, n, [100, 100]);
        let shape = Shape::Delay { delay_s: 0.02, jets: Jets::Port, smoothing_s: 0.0 };
        let column = &ActuatorDelay.columns(&shape, &run, 0, &context)[0];
        let rerun = run.plant_sides(context.set, &Jets::Port.apply(&run.cmu, |c| fractional_delay(c, 20.0)));
        let want: Vec<f64> = (0..n).map(|i| rerun[0][i] - run.cl_afc_side[0][i]).collect();
        let peak = want.iter().fold(0.0, |acc: f64, v| acc.max(v.abs()));
        // Equal but for the plant's own start from rest, which the shift moves too.
        let worst = column.iter().zip(&want).map(|(c, w)| (c - w).abs()).fold(0.0, f64::max);
        assert!(peak > 0.0 && worst <= 0.01 * peak, "worst {worst} of {peak}");
    }

    /// A delay per jet shifts each jet's plant moment by its own delay, and a shared delay
    /// anywhere between the two fits that worse: the form a line per jet needs.
    #[test]
    fn a_delay_per_jet_shifts_each_jets_moment_by_its_own_delay() {
        let context = crate::diagnose::candidates::test_context();
        let n = 800;
        let run = blowing_run(&context, n, [100, 300]);
        let shape = Shape::DelayPerJet { port_s: 0.03, starboard_s: 0.08 };
        let column = &ActuatorDelay.columns(&shape, &run, 0, &context)[0];
        let (port, starboard) =
            (fractional_delay(&run.cl_afc_side[0], 30.0), fractional_delay(&run.cl_afc_side[1], 80.0));
        let want: Vec<f64> =
            (0..n).map(|i| port[i] + starboard[i] - run.cl_afc_side[0][i] - run.cl_afc_side[1][i]).collect();
        let worst = column.iter().zip(&want).map(|(c, w)| (c - w).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-15, "{worst}");
        let sse = |shape: &Shape| {
            let column = &ActuatorDelay.columns(shape, &run, 0, &context)[0];
            column.iter().zip(&want).map(|(c, w)| (c - w).powi(2)).sum::<f64>()
        };
        let total: f64 = want.iter().map(|w| w * w).sum();
        for delay_s in [0.03, 0.045, 0.055, 0.065, 0.08] {
            let shared = sse(&Shape::Delay { delay_s, jets: Jets::Both, smoothing_s: 0.0 });
            assert!(shared > 0.05 * total, "{delay_s}: {shared} of {total}");
        }
    }
}

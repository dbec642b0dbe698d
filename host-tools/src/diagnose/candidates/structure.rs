//! The balance's own behaviour (G7, G8): a lightly damped structural mode of balance and sting
//! excited by the load and the motion, and a slow drift of its zero (gap-diagnosis.md sections
//! 2.5 and 2.6).

use firmware_sim::effect::Effect;

use super::{BalanceCandidate, Context, Params, Shape, difference, log_grid};
use crate::diagnose::streams::RunStreams;

/// Damping ratios of the balance-resonance candidate: from 0.005 (a bolted steel sting) to 0.1,
/// the span of "lightly damped" in the contract's definition (gap-diagnosis.md section 2.3); a
/// more damped "mode" is a broad filter that any error of the sim's dynamics can feed.
pub const RESONANCE_DAMPING: [f64; 6] = [0.005, 0.01, 0.02, 0.04, 0.07, 0.1];

/// Knot spacings of the drift's piecewise-linear form, s: a zero that wanders (a random walk)
/// rather than a smooth trend.
pub const DRIFT_KNOT_SPACING_S: [f64; 2] = [4.0, 2.0];

/// `balance_resonance`: a mode from [`Context::resonance_min_hz`] to 0.35 of the sample rate
/// (at most 250 Hz), damping [`RESONANCE_DAMPING`], driven by the sim's load and the inertial
/// load of the motion.
#[derive(Debug, Clone, Copy)]
pub struct BalanceResonance;

/// `bias_drift`: a slow drift of the zero per run, from the run's own tare at its start: a
/// smooth trend (powers of time, degree 1 to 3) or a zero that wanders (piecewise linear between
/// knots [`DRIFT_KNOT_SPACING_S`] apart; beyond the training part it holds its last slope, all a
/// drift lets anyone predict).
#[derive(Debug, Clone, Copy)]
pub struct BiasDrift;

impl BalanceCandidate for BalanceResonance {
    fn effect(&self) -> Option<Effect> {
        Some(Effect::BalanceResonance)
    }

    fn separating_experiment(&self) -> &'static str {
        "a wind-off tap test of balance and sting"
    }

    fn shapes(&self, sample_hz: f64, context: &Context<'_>) -> Vec<Shape> {
        let top_hz = (0.35 * sample_hz).min(250.0);
        log_grid(context.resonance_min_hz.min(0.5 * top_hz), top_hz, 60)
            .into_iter()
            .flat_map(|freq_hz| RESONANCE_DAMPING.map(|zeta| Shape::Mode { freq_hz, zeta }))
            .collect()
    }

    fn columns(&self, shape: &Shape, run: &RunStreams, _run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        let Shape::Mode { freq_hz, zeta } = *shape else { return Vec::new() };
        let dt_s = 1.0 / run.sample_hz;
        let load = run.cl_sim();
        let inertial: Vec<f64> = run.phi_ddot_rad_s2.iter().map(|a| a / context.moment_scale_nm).collect();
        vec![
            difference(&resonator(&load, freq_hz, zeta, dt_s), &load),
            difference(&resonator(&inertial, freq_hz, zeta, dt_s), &inertial),
        ]
    }

    fn params(&self, _shape: &Shape, beta: &[f64], _context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        super::gains(&["gain_load", "gain_inertial"], beta)
    }
}

impl BalanceCandidate for BiasDrift {
    fn effect(&self) -> Option<Effect> {
        Some(Effect::BiasDrift)
    }

    fn separating_experiment(&self) -> &'static str {
        "wind-off zero readings before and after each run"
    }

    fn shapes(&self, _sample_hz: f64, _context: &Context<'_>) -> Vec<Shape> {
        let trends = (1..=3).map(|degree| Shape::Trend { degree });
        trends.chain(DRIFT_KNOT_SPACING_S.map(|knot_spacing_s| Shape::Wander { knot_spacing_s })).collect()
    }

    fn columns(&self, shape: &Shape, run: &RunStreams, run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        let duration = run.t_s.last().copied().unwrap_or(1.0).max(f64::MIN_POSITIVE);
        let shapes: Vec<Box<dyn Fn(f64) -> f64>> = match *shape {
            Shape::Wander { knot_spacing_s } => {
                let knots = (duration / knot_spacing_s).floor() as usize;
                std::iter::once(Box::new(move |t: f64| t / duration) as Box<dyn Fn(f64) -> f64>)
                    .chain((1..=knots).map(move |k| {
                        let knot = k as f64 * knot_spacing_s;
                        Box::new(move |t: f64| (t - knot).max(0.0) / duration) as Box<dyn Fn(f64) -> f64>
                    }))
                    .collect()
            }
            Shape::Trend { degree } => (1..=i32::from(degree.max(1)))
                .map(|power| Box::new(move |t: f64| (t / duration).powi(power)) as Box<dyn Fn(f64) -> f64>)
                .collect(),
            _ => return Vec::new(),
        };
        // Every run has its own columns (zero in the other runs).
        let width = drift_width(shape, context);
        let mut out = vec![vec![0.0; run.len()]; width * context.n_runs];
        for (slot, shape) in shapes.iter().enumerate().take(width) {
            let column = &mut out[width * run_idx + slot];
            for (idx, t) in run.t_s.iter().enumerate() {
                column[idx] = shape(*t);
            }
        }
        out
    }

    /// The fitted drift at the end of each run (it starts from the run's tare at zero): the
    /// largest in size.
    fn params(&self, _shape: &Shape, beta: &[f64], _context: &Context<'_>, columns: &[Vec<Vec<f64>>]) -> Params {
        let worst = columns
            .iter()
            .filter_map(|cols| {
                let last = cols.first()?.len().checked_sub(1)?;
                Some(cols.iter().zip(beta).map(|(col, b)| b * col[last]).sum::<f64>())
            })
            .fold(0.0, |acc: f64, v| if v.abs() > acc.abs() { v } else { acc });
        vec![("largest_drift_over_run".into(), worst)]
    }
}

/// Columns per run of a drift: the degree, or one slope and one hinge per knot of the longest
/// run.
fn drift_width(shape: &Shape, context: &Context<'_>) -> usize {
    match *shape {
        Shape::Wander { knot_spacing_s } => 1 + (context.longest_run_s / knot_spacing_s).floor() as usize,
        Shape::Trend { degree } => usize::from(degree.max(1)),
        _ => 0,
    }
}

/// A unit-gain second-order resonator `w^2 / (s^2 + 2 zeta w s + w^2)` (bilinear transform with
/// the natural frequency pre-warped), started at rest at the first input.
#[must_use]
pub fn resonator(values: &[f64], freq_hz: f64, zeta: f64, dt_s: f64) -> Vec<f64> {
    let omega = 2.0 / dt_s * (std::f64::consts::PI * freq_hz * dt_s).tan();
    let k = 2.0 / dt_s;
    let (w2, two_zw) = (omega * omega, 2.0 * zeta * omega);
    let a0 = k * k + two_zw * k + w2;
    let b = [w2 / a0, 2.0 * w2 / a0, w2 / a0];
    let a1 = (2.0 * w2 - 2.0 * k * k) / a0;
    let a2 = (k * k - two_zw * k + w2) / a0;
    let first = values.first().copied().unwrap_or(0.0);
    let (mut x1, mut x2, mut y1, mut y2) = (first, first, first, first);
    values
        .iter()
        .map(|&x| {
            let y = b[0] * x + b[1] * x1 + b[2] * x2 - a1 * y1 - a2 * y2;
            (x2, x1, y2, y1) = (x1, x, y1, y);
            y
        })
        .collect()
}

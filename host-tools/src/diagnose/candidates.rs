//! The candidate effects of the balance stream: each a physical addition to the sim with a few
//! parameters, written as regressors of the balance residual (gap-diagnosis.md section 4.2,
//! groups G0-G9), with a grid over its nonlinear parameters (delays, time constants,
//! frequencies), profiled by least squares.
//!
//! The regressors are built from the recorded inputs and the sim's own blocks, never from the
//! synthetic tunnel's code: the plant is re-run by estimator-core on a delayed or lagged Cmu, the
//! vortex lag filters the eGK moment, the structural mode filters the sim's load.

pub use crate::fit::signals::first_order_lag;
use estimator_core::CoefficientSet;
pub use firmware_sim::effect::Block;
use firmware_sim::effect::Effect;

use super::streams::RunStreams;

/// A candidate effect of the balance stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Candidate {
    /// `actuator_delay`: the plant driven by `Cmu(t - d)`.
    ActuatorDelay,
    /// `actuator_lag`: the plant driven by a first-order lag of Cmu.
    ActuatorLag,
    /// `inertial_tare`: `-I phi_ddot / (q S b)` left in the balance.
    InertialTare,
    /// `gravity_tare`: `m g d sin(phi + phase) / (q S b)` (the weight moment about the roll axis,
    /// with the offset it leaves at `phi = 0`).
    GravityTare,
    /// `roll_damping`: `C_l,p p_hat`.
    RollDamping,
    /// `vortex_lag`: a share of the eGK moment through a slower first-order state.
    VortexLag,
    /// `coupling`: bilinear disturbance-actuation interaction terms.
    Coupling,
    /// `balance_resonance`: a lightly damped mode excited by the load and the motion.
    BalanceResonance,
    /// `bias_drift`: a slow polynomial drift of the zero, per run.
    BiasDrift,
    /// Recalibration of the existing blocks' gains (group G0): competes with every new effect.
    Recalibration,
}

impl Candidate {
    /// Every balance candidate.
    pub const ALL: [Self; 10] = [
        Self::ActuatorDelay,
        Self::ActuatorLag,
        Self::InertialTare,
        Self::GravityTare,
        Self::RollDamping,
        Self::VortexLag,
        Self::Coupling,
        Self::BalanceResonance,
        Self::BiasDrift,
        Self::Recalibration,
    ];

    /// The effect the candidate stands for; `None` for recalibration (G0), which names no new
    /// effect.
    #[must_use]
    pub const fn effect(self) -> Option<Effect> {
        Some(match self {
            Self::ActuatorDelay => Effect::ActuatorDelay,
            Self::ActuatorLag => Effect::ActuatorLag,
            Self::InertialTare => Effect::InertialTare,
            Self::GravityTare => Effect::GravityTare,
            Self::RollDamping => Effect::RollDamping,
            Self::VortexLag => Effect::VortexLag,
            Self::Coupling => Effect::Coupling,
            Self::BalanceResonance => Effect::BalanceResonance,
            Self::BiasDrift => Effect::BiasDrift,
            Self::Recalibration => return None,
        })
    }

    /// The effect's name (the vocabulary of shared/spec/diagnosis.md; `recalibration` for G0).
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self.effect() {
            Some(effect) => effect.name(),
            None => "recalibration",
        }
    }

    /// The block the effect belongs to (recalibration: the disturbance model's gains).
    #[must_use]
    pub const fn block(self) -> Block {
        match self.effect() {
            Some(effect) => effect.block(),
            None => Block::Disturbance,
        }
    }

    /// The experiment that separates this effect from its usual confusers
    /// (gap-diagnosis.md section 2.11, "separator").
    #[must_use]
    pub const fn separating_experiment(self) -> &'static str {
        match self {
            Self::ActuatorDelay | Self::ActuatorLag => {
                "a bench step test of the valve and runs at a second free-stream speed (the pneumatic part is fixed in seconds, the aerodynamic part scales with c/U)"
            }
            Self::InertialTare => {
                "wind-off runs with the same roll motion (the inertial reaction stays, the aerodynamics vanish)"
            }
            Self::GravityTare => {
                "wind-off runs at held roll angles (the weight moment stays) or a second free-stream speed"
            }
            Self::RollDamping | Self::VortexLag => {
                "forced roll at several reduced frequencies and a second free-stream speed (aerodynamic lags scale with c/U, rig lags do not)"
            }
            Self::Coupling => {
                "roll+actuation runs with the blowing scheduled independently of the roll phase, at two roll amplitudes"
            }
            Self::BalanceResonance => "a wind-off tap test of balance and sting",
            Self::BiasDrift => "wind-off zero readings before and after each run",
            Self::Recalibration => "runs at new angles of attack and amplitudes inside the fitted range",
        }
    }

    /// The candidate's family: every grid point is one form with its nonlinear parameters
    /// (delays, time constants, frequencies) and its discrete choices (`per_alpha`: one gain per
    /// angle of attack instead of one for all, for the aerodynamic effects when the recording
    /// has several; `degree`, `knot_spacing_s` of a drift). The vortex lag's time constants
    /// start at `slow_tau_min_s` ([`Context::slow_tau_min_s`]), the balance mode's frequencies
    /// at `resonance_min_hz` ([`Context::resonance_min_hz`]). Within a family the form is
    /// chosen by its complexity-penalised evidence, not by its fit alone.
    #[must_use]
    pub fn grid(self, sample_hz: f64, context: &Context<'_>) -> Vec<Vec<(&'static str, f64)>> {
        let dt_s = 1.0 / sample_hz;
        let scheduled = |points: Vec<Vec<(&'static str, f64)>>| -> Vec<Vec<(&'static str, f64)>> {
            if context.alphas_deg.len() < 2 {
                return points;
            }
            points
                .into_iter()
                .flat_map(|point| {
                    let mut per_alpha = point.clone();
                    per_alpha.push(("per_alpha", 1.0));
                    [point, per_alpha]
                })
                .collect()
        };
        match self {
            Self::ActuatorDelay => log_grid(0.5 * dt_s, 0.25, 40).into_iter().map(|d| vec![("delay_s", d)]).collect(),
            Self::ActuatorLag => log_grid(dt_s, 0.5, 36).into_iter().map(|tau| vec![("tau_s", tau)]).collect(),
            // No per-alpha gains: the sideslip drive already grows with alpha, and a slow state
            // with nine free gains absorbs the sim's own error from recording to recording.
            Self::VortexLag => log_grid(0.03, 5.0, 30)
                .into_iter()
                .filter(|tau| *tau >= context.slow_tau_min_s)
                .flat_map(|tau| [vec![("tau_s", tau), ("drive", 0.0)], vec![("tau_s", tau), ("drive", 1.0)]])
                .collect(),
            // Recalibration stays one gain per block: per-alpha gains on the eGK and the plant
            // absorb the sim's own error in every run and outbid the effect they partly span.
            Self::RollDamping | Self::Coupling => scheduled(vec![Vec::new()]),
            Self::BalanceResonance => {
                let top_hz = (0.35 * sample_hz).min(250.0);
                let mut grid = Vec::new();
                for freq in log_grid(context.resonance_min_hz.min(0.5 * top_hz), top_hz, 60) {
                    for zeta in RESONANCE_DAMPING {
                        grid.push(vec![("freq_hz", freq), ("zeta", zeta)]);
                    }
                }
                grid
            }
            Self::BiasDrift => {
                let mut grid: Vec<Vec<(&'static str, f64)>> =
                    [1.0, 2.0, 3.0].into_iter().map(|degree| vec![("degree", degree)]).collect();
                grid.extend(DRIFT_KNOT_SPACING_S.into_iter().map(|spacing| vec![("knot_spacing_s", spacing)]));
                grid
            }
            _ => vec![Vec::new()],
        }
    }

    /// How many of a grid point's entries are continuous parameters profiled on the grid (they
    /// count in the complexity penalty; discrete choices count through their columns).
    #[must_use]
    pub fn n_profiled(hyper: &[(&'static str, f64)]) -> usize {
        hyper.iter().filter(|(name, _)| !matches!(*name, "per_alpha" | "degree" | "knot_spacing_s" | "drive")).count()
    }
}

/// Damping ratios of the balance-resonance candidate: from 0.005 (a bolted steel sting) to 0.1,
/// the span of "lightly damped" in the contract's definition (gap-diagnosis.md section 2.3); a
/// more damped "mode" is a broad filter that any error of the sim's dynamics can feed.
pub const RESONANCE_DAMPING: [f64; 6] = [0.005, 0.01, 0.02, 0.04, 0.07, 0.1];

/// Knot spacings of the drift's piecewise-linear form, s: a zero that wanders (a random walk)
/// rather than a smooth trend.
pub const DRIFT_KNOT_SPACING_S: [f64; 2] = [4.0, 2.0];

/// `n` points spaced logarithmically from `low` to `high`.
#[must_use]
pub fn log_grid(low: f64, high: f64, n: usize) -> Vec<f64> {
    if n < 2 {
        return vec![low];
    }
    let ratio = (high / low).ln() / (n - 1) as f64;
    (0..n).map(|idx| low * (ratio * idx as f64).exp()).collect()
}

/// What the regressors need besides the run itself.
#[derive(Debug, Clone)]
pub struct Context<'a> {
    /// The sim's coefficient set (the plant is re-run on modified Cmu).
    pub set: &'a CoefficientSet,
    /// `q S b`, N m per unit C_l.
    pub moment_scale_nm: f64,
    /// `b / (2 U)`, s.
    pub half_span_time_s: f64,
    /// Largest recorded Cmu of the dataset (scales the coupling terms).
    pub cmu_ref: f64,
    /// Number of runs (per-run columns).
    pub n_runs: usize,
    /// Shortest time constant of the vortex-lag candidate, s: twice the sim's own eGK lag, so
    /// that the candidate is a slower state, not the eGK's (or a rate damping) again.
    pub slow_tau_min_s: f64,
    /// Lowest natural frequency of the balance-resonance candidate, Hz ([`resonance_min_hz`]).
    pub resonance_min_hz: f64,
    /// The recording's angles of attack, deg, ascending (the groups of a per-alpha gain).
    pub alphas_deg: Vec<f64>,
    /// Duration of the longest run, s (the drift's knots).
    pub longest_run_s: f64,
}

/// Lowest frequency the balance-resonance candidate may take, Hz: an octave above the motion's
/// band, twice the frequency below which 99 % of the roll angle's variance lies (Welch PSD over
/// the training parts of the rolling runs), and at least 2 Hz.
///
/// Why: below its natural frequency a mode driven by the load and the motion responds as their
/// second derivatives scaled, so a "mode" inside or at the edge of the motion's band is an
/// acceleration-like filter of the moment that can absorb an inertial tare or any structural
/// error of the sim; it cannot be told from them. A balance built for dynamic tests has its
/// first mode well above the motion it measures, or it would distort every reading the test is
/// for. A mode that is really inside the band is left to the other candidates, or to
/// `unattributed`.
#[must_use]
pub fn resonance_min_hz(runs: &[RunStreams]) -> f64 {
    const FLOOR_HZ: f64 = 2.0;
    // A missing sample counts as zero: a few of them barely move a spectrum.
    let cleaned: Vec<Vec<f64>> = runs
        .iter()
        .filter(|run| run.rolls())
        .map(|run| run.phi_rad[run.training.clone()].iter().map(|v| if v.is_finite() { *v } else { 0.0 }).collect())
        .collect();
    let segments: Vec<&[f64]> = cleaned.iter().map(Vec::as_slice).collect();
    let Some(sample_hz) = runs.first().map(|run| run.sample_hz) else { return FLOOR_HZ };
    let shortest = segments.iter().map(|segment| segment.len()).min().unwrap_or(0);
    // Windows of about 4 s (0.25 Hz bins), shorter for short runs.
    let window = ((4.0 * sample_hz) as usize).min(shortest / 2).max(4);
    let Some(spectrum) = crate::diagnose::ledger::welch_psd(&segments, sample_hz, window) else { return FLOOR_HZ };
    let total: f64 = spectrum.psd.iter().sum();
    if total.is_nan() || total <= 0.0 {
        return FLOOR_HZ;
    }
    let mut cumulative = 0.0;
    for (freq_hz, power) in spectrum.freq_hz.iter().zip(&spectrum.psd) {
        cumulative += power;
        if cumulative >= 0.99 * total {
            return (2.0 * freq_hz).max(FLOOR_HZ);
        }
    }
    FLOOR_HZ
}

/// The regression columns of `candidate` at grid point `hyper` for run number `run_idx`; every
/// column has the run's length. Columns are zero where the effect cannot act (e.g. no blowing).
#[must_use]
pub fn columns(
    candidate: Candidate,
    hyper: &[(&'static str, f64)],
    run: &RunStreams,
    run_idx: usize,
    context: &Context<'_>,
) -> Vec<Vec<f64>> {
    let base = base_columns(candidate, hyper, run, run_idx, context);
    let per_alpha = hyper.iter().any(|(name, value)| *name == "per_alpha" && *value > 0.5);
    if !per_alpha {
        return base;
    }
    // One gain per angle of attack: each column repeated per alpha, zero at the other alphas.
    let n = run.len();
    let group = context.alphas_deg.iter().position(|a| (a - run.alpha_deg).abs() < 1e-6);
    let mut out = Vec::with_capacity(base.len() * context.alphas_deg.len());
    for column in base {
        for slot in 0..context.alphas_deg.len() {
            out.push(if Some(slot) == group { column.clone() } else { vec![0.0; n] });
        }
    }
    out
}

fn base_columns(
    candidate: Candidate,
    hyper: &[(&'static str, f64)],
    run: &RunStreams,
    run_idx: usize,
    context: &Context<'_>,
) -> Vec<Vec<f64>> {
    let n = run.len();
    let dt_s = 1.0 / run.sample_hz;
    let value = |key: &str| hyper.iter().find(|(name, _)| *name == key).map_or(0.0, |(_, v)| *v);
    match candidate {
        Candidate::ActuatorDelay => {
            if !run.blows() {
                return vec![vec![0.0; n]];
            }
            let delay_samples = value("delay_s") / dt_s;
            let delayed = run.cmu.clone().map(|cmu| fractional_delay(&cmu, delay_samples));
            vec![difference(&run.plant_response(context.set, &delayed), &run.cl_afc())]
        }
        Candidate::ActuatorLag => {
            if !run.blows() {
                return vec![vec![0.0; n]];
            }
            let lagged = run.cmu.clone().map(|cmu| first_order_lag(&cmu, value("tau_s"), dt_s));
            vec![difference(&run.plant_response(context.set, &lagged), &run.cl_afc())]
        }
        Candidate::InertialTare => vec![run.phi_ddot_rad_s2.clone()],
        Candidate::GravityTare => {
            vec![run.phi_rad.iter().map(|phi| phi.sin()).collect(), run.phi_rad.iter().map(|phi| phi.cos()).collect()]
        }
        Candidate::RollDamping => {
            vec![run.phi_dot_rad_s.iter().map(|rate| rate * context.half_span_time_s).collect()]
        }
        Candidate::VortexLag => {
            // A second, slower flow state (gap-diagnosis.md sections 2.9 and 4.2, G9), in the
            // forms a rig can have: a share of the eGK's response through the slower state
            // (LP_tau[C_l,eGK] - C_l,eGK), and a new state driven by one of the disturbance's
            // physical inputs (`drive` 0: the sideslip that rolling at incidence makes, 1: the
            // reduced roll rate), LP_tau[u]. One drive at a time: the lags of the sideslip and
            // of the rate together span the roll angle itself, a static moment, not a lag.
            let tau_s = value("tau_s");
            let drive: Vec<f64> = if value("drive") > 0.5 {
                run.phi_dot_rad_s.iter().map(|rate| rate * context.half_span_time_s).collect()
            } else {
                let alpha = run.alpha_deg.to_radians();
                run.phi_rad.iter().map(|phi| (alpha.sin() * phi.sin()).asin()).collect()
            };
            vec![
                difference(&first_order_lag(&run.cl_egk, tau_s, dt_s), &run.cl_egk),
                first_order_lag(&drive, tau_s, dt_s),
            ]
        }
        Candidate::Coupling => {
            // First-order interaction: the blowing (differential and total, scaled) times the
            // disturbance's own variables (its moment, the roll angle and the reduced roll rate:
            // blowing changes the wing's stiffness and its damping alike).
            let cmu_ref = context.cmu_ref.max(f64::MIN_POSITIVE);
            let differential: Vec<f64> = (0..n).map(|idx| (run.cmu[0][idx] - run.cmu[1][idx]) / cmu_ref).collect();
            let total: Vec<f64> = (0..n).map(|idx| (run.cmu[0][idx] + run.cmu[1][idx]) / cmu_ref).collect();
            let p_hat: Vec<f64> = run.phi_dot_rad_s.iter().map(|rate| rate * context.half_span_time_s).collect();
            // The jets' own moment, with their dynamics (the paper's C_l,Roll x C_l,AFC terms).
            let afc = run.cl_afc();
            let mut columns = Vec::with_capacity(9);
            for variable in [&run.cl_egk, &run.phi_rad, &p_hat] {
                columns.push((0..n).map(|idx| variable[idx] * differential[idx]).collect());
                columns.push((0..n).map(|idx| variable[idx] * total[idx]).collect());
                columns.push((0..n).map(|idx| if run.rolls() { variable[idx] * afc[idx] } else { 0.0 }).collect());
            }
            columns
        }
        Candidate::BalanceResonance => {
            let (freq_hz, zeta) = (value("freq_hz"), value("zeta"));
            let load = run.cl_sim();
            let inertial: Vec<f64> = run.phi_ddot_rad_s2.iter().map(|a| a / context.moment_scale_nm).collect();
            vec![
                difference(&resonator(&load, freq_hz, zeta, dt_s), &load),
                difference(&resonator(&inertial, freq_hz, zeta, dt_s), &inertial),
            ]
        }
        Candidate::BiasDrift => {
            // Per run, from its own tare at its start: a smooth trend (powers of time) or a zero
            // that wanders (piecewise linear between knots; beyond the training part it holds
            // its last slope, all a drift lets anyone predict).
            let duration = run.t_s.last().copied().unwrap_or(1.0).max(f64::MIN_POSITIVE);
            let shapes: Vec<Box<dyn Fn(f64) -> f64>> = if value("knot_spacing_s") > 0.0 {
                let spacing = value("knot_spacing_s");
                let knots = (duration / spacing).floor() as usize;
                std::iter::once(Box::new(move |t: f64| t / duration) as Box<dyn Fn(f64) -> f64>)
                    .chain((1..=knots).map(move |k| {
                        let knot = k as f64 * spacing;
                        Box::new(move |t: f64| (t - knot).max(0.0) / duration) as Box<dyn Fn(f64) -> f64>
                    }))
                    .collect()
            } else {
                (1..=value("degree").round().max(1.0) as i32)
                    .map(|power| Box::new(move |t: f64| (t / duration).powi(power)) as Box<dyn Fn(f64) -> f64>)
                    .collect()
            };
            let width = drift_width(hyper, context);
            let mut out = vec![vec![0.0; n]; width * context.n_runs];
            for (slot, shape) in shapes.iter().enumerate().take(width) {
                let column = &mut out[width * run_idx + slot];
                for (idx, t) in run.t_s.iter().enumerate() {
                    column[idx] = shape(*t);
                }
            }
            out
        }
        Candidate::Recalibration => vec![run.cl_egk.clone(), run.cl_afc()],
    }
}

/// Columns per run of the drift at a grid point: the degree, or one slope and one hinge per knot
/// of the longest run.
fn drift_width(hyper: &[(&'static str, f64)], context: &Context<'_>) -> usize {
    let value = |key: &str| hyper.iter().find(|(name, _)| *name == key).map_or(0.0, |(_, v)| *v);
    let spacing = value("knot_spacing_s");
    if spacing > 0.0 {
        1 + (context.longest_run_s / spacing).floor() as usize
    } else {
        value("degree").round().max(1.0) as usize
    }
}

fn difference(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x - y).collect()
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

    #[test]
    fn lag_and_resonator_have_unit_dc_gain() {
        let step = vec![1.0; 20_000];
        let lagged = first_order_lag(&[vec![0.0], step.clone()].concat(), 0.05, 1e-3);
        assert!((lagged.last().unwrap() - 1.0).abs() < 1e-9);
        let rung = resonator(&[vec![0.0], step].concat(), 25.0, 0.05, 1e-3);
        assert!((rung.last().unwrap() - 1.0).abs() < 1e-6);
        let peak = rung.iter().copied().fold(0.0, f64::max);
        assert!(peak > 1.7, "lightly damped step overshoots: {peak}");
    }
}

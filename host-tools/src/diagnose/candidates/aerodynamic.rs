//! What the disturbance model and the superposition lack (G0, G4, G9 and the coupling): a rate
//! damping, a second slower flow state, the disturbance-actuation interaction, and the
//! recalibration of the existing blocks' gains that competes with every new effect
//! (docs/diagnosis.md, Candidate families).

use firmware_sim::effect::Effect;

use super::{
    BalanceCandidate, Context, DampingLaw, Drive, Params, Shape, SlowLaw, difference, first_order_lag, gains, log_grid,
};
use crate::diagnose::streams::RunStreams;

/// `roll_damping`: a moment that grows with the roll rate, linear `C_l,p p_hat` or quadratic
/// `C_l,p|p| p_hat |p_hat|`, one gain or one per angle of attack.
#[derive(Debug, Clone, Copy)]
pub struct RollDamping;

/// `vortex_lag`: a second, slower flow state, tau from 30 ms to 5 s (no shorter than
/// [`Context::slow_tau_min_s`]).
#[derive(Debug, Clone, Copy)]
pub struct VortexLag;

/// `coupling`: bilinear disturbance-actuation interaction terms, one set or one per angle of
/// attack.
#[derive(Debug, Clone, Copy)]
pub struct Coupling;

/// Recalibration of the existing blocks' gains (group G0): names no new effect.
#[derive(Debug, Clone, Copy)]
pub struct Recalibration;

const AERODYNAMIC_SEPARATOR: &str = "forced roll at several reduced frequencies and a second free-stream speed (aerodynamic lags scale with c/U, rig lags do not)";

impl BalanceCandidate for RollDamping {
    fn regressors(&self) -> &'static str {
        "the reduced roll rate, linear or times its size"
    }

    fn effect(&self) -> Option<Effect> {
        Some(Effect::RollDamping)
    }

    fn separating_experiment(&self) -> &'static str {
        AERODYNAMIC_SEPARATOR
    }

    fn shapes(&self, _sample_hz: f64, _context: &Context<'_>) -> Vec<Shape> {
        [DampingLaw::Linear, DampingLaw::Quadratic].map(|law| Shape::Damping { law }).to_vec()
    }

    fn schedulable(&self) -> bool {
        true
    }

    fn columns(&self, shape: &Shape, run: &RunStreams, _run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        let p_hat = context.p_hat(run);
        match shape {
            Shape::Damping { law: DampingLaw::Quadratic } => vec![p_hat.iter().map(|p| p * p.abs()).collect()],
            _ => vec![p_hat],
        }
    }

    fn params(&self, shape: &Shape, beta: &[f64], _context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        match shape {
            Shape::Damping { law: DampingLaw::Quadratic } => gains(&["clpp"], beta),
            _ => gains(&["clp"], beta),
        }
    }
}

impl BalanceCandidate for VortexLag {
    fn regressors(&self) -> &'static str {
        "a first-order state of the eGK moment and of a physical drive, as the state or its deficit"
    }

    fn effect(&self) -> Option<Effect> {
        Some(Effect::VortexLag)
    }

    fn separating_experiment(&self) -> &'static str {
        AERODYNAMIC_SEPARATOR
    }

    /// No per-alpha gains: the sideslip drive already grows with alpha, and a slow state with
    /// nine free gains absorbs the sim's own error from recording to recording.
    fn shapes(&self, _sample_hz: f64, context: &Context<'_>) -> Vec<Shape> {
        log_grid(0.03, 5.0, 30)
            .into_iter()
            .filter(|tau_s| *tau_s >= context.slow_tau_min_s)
            .flat_map(|tau_s| {
                Drive::ALL.into_iter().flat_map(move |drive| {
                    [SlowLaw::State, SlowLaw::Deficit].map(move |law| Shape::SlowState { tau_s, drive, law })
                })
            })
            .collect()
    }

    /// A second, slower flow state (docs/diagnosis.md, Vortex lag, G9), in the forms a
    /// rig can have: a share of the eGK's response through the slower state
    /// (`LP_tau[C_l,eGK] - C_l,eGK`), and a new state driven by one of the disturbance's physical
    /// inputs, acting as itself, `LP_tau[u]`, or as its deficit, `LP_tau[u] - u`.
    fn columns(&self, shape: &Shape, run: &RunStreams, _run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        let Shape::SlowState { tau_s, drive, law } = *shape else { return Vec::new() };
        let dt_s = 1.0 / run.sample_hz;
        let input: Vec<f64> = match drive {
            Drive::RollRate => context.p_hat(run),
            Drive::RollAngle => run.phi_rad.clone(),
            Drive::Sideslip => {
                let alpha = run.alpha_deg.to_radians();
                run.phi_rad.iter().map(|phi| (alpha.sin() * phi.sin()).asin()).collect()
            }
        };
        let state = first_order_lag(&input, tau_s, dt_s);
        let own = match law {
            SlowLaw::State => state,
            SlowLaw::Deficit => difference(&state, &input),
        };
        vec![difference(&first_order_lag(&run.cl_egk, tau_s, dt_s), &run.cl_egk), own]
    }

    fn params(&self, shape: &Shape, beta: &[f64], _context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        let per_drive = match shape {
            Shape::SlowState { drive: Drive::RollRate, .. } => "per_unit_p_hat",
            Shape::SlowState { drive: Drive::RollAngle, .. } => "per_rad_roll",
            _ => "per_rad_sideslip",
        };
        gains(&["share_of_egk_moment", per_drive], beta)
    }
}

impl BalanceCandidate for Coupling {
    fn regressors(&self) -> &'static str {
        "the eGK moment, the roll angle and the reduced roll rate, each times the differential blowing, the total blowing and the plant's moment"
    }

    fn effect(&self) -> Option<Effect> {
        Some(Effect::Coupling)
    }

    fn separating_experiment(&self) -> &'static str {
        "roll+actuation runs with the blowing scheduled independently of the roll phase, at two roll amplitudes"
    }

    fn shapes(&self, _sample_hz: f64, _context: &Context<'_>) -> Vec<Shape> {
        vec![Shape::Fixed]
    }

    fn schedulable(&self) -> bool {
        true
    }

    /// First-order interaction: the blowing (differential and total, scaled) and the jets' own
    /// moment with their dynamics (the paper's C_l,Roll x C_l,AFC terms), times the
    /// disturbance's own variables (its moment, the roll angle and the reduced roll rate:
    /// blowing changes the wing's stiffness and its damping alike).
    fn columns(&self, _shape: &Shape, run: &RunStreams, _run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        let n = run.len();
        let cmu_ref = context.cmu_ref.max(f64::MIN_POSITIVE);
        let differential: Vec<f64> = (0..n).map(|idx| (run.cmu[0][idx] - run.cmu[1][idx]) / cmu_ref).collect();
        let total: Vec<f64> = (0..n).map(|idx| (run.cmu[0][idx] + run.cmu[1][idx]) / cmu_ref).collect();
        let p_hat = context.p_hat(run);
        let afc = run.cl_afc();
        let mut columns = Vec::with_capacity(9);
        for variable in [&run.cl_egk, &run.phi_rad, &p_hat] {
            columns.push((0..n).map(|idx| variable[idx] * differential[idx]).collect());
            columns.push((0..n).map(|idx| variable[idx] * total[idx]).collect());
            columns.push((0..n).map(|idx| if run.rolls() { variable[idx] * afc[idx] } else { 0.0 }).collect());
        }
        columns
    }

    fn params(&self, _shape: &Shape, beta: &[f64], _context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        gains(
            &[
                "egk_x_differential_cmu",
                "egk_x_total_cmu",
                "egk_x_plant_moment",
                "phi_x_differential_cmu",
                "phi_x_total_cmu",
                "phi_x_plant_moment",
                "p_hat_x_differential_cmu",
                "p_hat_x_total_cmu",
                "p_hat_x_plant_moment",
            ],
            beta,
        )
    }
}

impl BalanceCandidate for Recalibration {
    fn regressors(&self) -> &'static str {
        "the eGK moment and the plant moment (one gain each)"
    }

    fn effect(&self) -> Option<Effect> {
        None
    }

    fn separating_experiment(&self) -> &'static str {
        "runs at new angles of attack and amplitudes inside the fitted range"
    }

    /// One gain per block: per-alpha gains on the eGK and the plant absorb the sim's own error in
    /// every run and outbid the effect they partly span.
    fn shapes(&self, _sample_hz: f64, _context: &Context<'_>) -> Vec<Shape> {
        vec![Shape::Fixed]
    }

    fn columns(&self, _shape: &Shape, run: &RunStreams, _run_idx: usize, _context: &Context<'_>) -> Vec<Vec<f64>> {
        vec![run.cl_egk.clone(), run.cl_afc()]
    }

    fn params(&self, _shape: &Shape, beta: &[f64], _context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        gains(&["disturbance_gain", "plant_gain"], &beta.iter().map(|b| 1.0 + b).collect::<Vec<_>>())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::candidates::{test_context, test_fit};
    use crate::diagnose::streams::{RunStreams, synthetic_run};

    /// A rolling run at 20 deg: a sum of two sines in phi, its rate, and an eGK moment.
    fn rolling_run(n: usize) -> RunStreams {
        let sample_hz = 200.0;
        let mut run = synthetic_run(sample_hz, vec![vec![0.0; n]], vec![vec![0.0; n]]);
        run.alpha_deg = 20.0;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / sample_hz).collect();
        run.phi_rad = t.iter().map(|t| 0.5 * (1.3 * t).sin() + 0.2 * (4.1 * t + 1.0).sin()).collect();
        run.phi_dot_rad_s = t.iter().map(|t| 0.65 * (1.3 * t).cos() + 0.82 * (4.1 * t + 1.0).cos()).collect();
        run.cl_egk = run.phi_rad.iter().map(|phi| -0.01 * phi).collect();
        run
    }

    /// The vortex-lag form that fits `truth` best by least squares: its residual sum of
    /// squares, shape and coefficients.
    fn best_vortex_form(run: &RunStreams, truth: &[f64], context: &Context<'_>) -> (f64, Shape, Vec<f64>) {
        VortexLag
            .shapes(run.sample_hz, context)
            .into_iter()
            .map(|shape| {
                let columns = VortexLag.columns(&shape, run, 0, context);
                let coef = test_fit(&columns, truth);
                let sse: f64 = (0..run.len())
                    .map(|i| (truth[i] - columns.iter().zip(&coef).map(|(c, b)| c[i] * b).sum::<f64>()).powi(2))
                    .sum();
                (sse, shape, coef)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .expect("the family has forms")
    }

    /// Every vortex-lag form is slower than the context's floor and at most 5 s, and each time
    /// constant comes with every drive.
    #[test]
    fn vortex_lag_forms_are_slow_and_cover_every_drive() {
        let context = test_context();
        let shapes = VortexLag.shapes(200.0, &context);
        let taus: Vec<f64> = shapes
            .iter()
            .map(|shape| match shape {
                Shape::SlowState { tau_s, .. } => *tau_s,
                other => panic!("not a slow state: {other:?}"),
            })
            .collect();
        assert!(taus.iter().all(|tau| (context.slow_tau_min_s..=5.0 + 1e-9).contains(tau)));
        assert!(taus.iter().any(|tau| (tau - 5.0).abs() < 1e-9), "reaches 5 s");
        let sideslip = shapes.iter().filter(|s| matches!(s, Shape::SlowState { drive: Drive::Sideslip, .. })).count();
        assert_eq!(Drive::ALL.len() * sideslip, shapes.len());
        for drive in Drive::ALL {
            let count = shapes.iter().filter(|s| matches!(s, Shape::SlowState { drive: d, .. } if *d == drive)).count();
            assert_eq!(count, sideslip, "{drive:?}");
        }
    }

    /// A second state driven by the sideslip, `0.02 LP_0.8s[beta]`, is found by profiling the
    /// family: the sideslip drive, a time constant within one grid step of 0.8 s, the gain.
    #[test]
    fn vortex_lag_profile_finds_drive_and_time_constant() {
        let context = test_context();
        let run = rolling_run(6000);
        let alpha = 20f64.to_radians();
        let beta: Vec<f64> = run.phi_rad.iter().map(|phi| (alpha.sin() * phi.sin()).asin()).collect();
        let truth: Vec<f64> = first_order_lag(&beta, 0.8, 1.0 / run.sample_hz).iter().map(|b| 0.02 * b).collect();
        let best = best_vortex_form(&run, &truth, &context);
        let Shape::SlowState { tau_s, drive, law } = best.1 else { unreachable!() };
        assert_eq!((drive, law), (Drive::Sideslip, SlowLaw::State));
        assert!((tau_s / 0.8).ln().abs() < (5.0f64 / 0.03).ln() / 29.0, "tau {tau_s}");
        let params = VortexLag.params(&best.1, &best.2, &context, &[]);
        assert_eq!(params[1].0, "per_rad_sideslip");
        assert!((params[1].1 - 0.02).abs() < 0.004, "{params:?}");
    }

    /// A state driven by the rate that acts as its deficit, `0.5 (LP_0.6s[p_hat] - p_hat)`, is
    /// found in the deficit law with the rate drive (the state law would need the rate itself,
    /// which is roll damping's column, not this family's).
    #[test]
    fn vortex_lag_profile_tells_a_deficit_from_a_state() {
        let context = test_context();
        let run = rolling_run(6000);
        let p_hat = context.p_hat(&run);
        let lagged = first_order_lag(&p_hat, 0.6, 1.0 / run.sample_hz);
        let truth: Vec<f64> = lagged.iter().zip(&p_hat).map(|(x, u)| 0.5 * (x - u)).collect();
        let best = best_vortex_form(&run, &truth, &context);
        let Shape::SlowState { drive, law, .. } = best.1 else { unreachable!() };
        assert_eq!((drive, law), (Drive::RollRate, SlowLaw::Deficit));
    }

    /// Without blowing every coupling column is zero (the interaction needs both); with a
    /// constant differential blowing of the reference level, the first column is the eGK
    /// moment itself.
    #[test]
    fn coupling_needs_both_motion_and_blowing() {
        let context = test_context();
        let mut run = rolling_run(400);
        let columns = Coupling.columns(&Shape::Fixed, &run, 0, &context);
        assert_eq!(columns.len(), 9);
        assert!(columns.iter().flatten().all(|v| *v == 0.0));
        run.cmu = [vec![context.cmu_ref; 400], vec![0.0; 400]];
        let columns = Coupling.columns(&Shape::Fixed, &run, 0, &context);
        assert!(columns[0].iter().zip(&run.cl_egk).all(|(c, e)| (c - e).abs() < 1e-15));
        assert!(columns[1].iter().zip(&run.cl_egk).all(|(c, e)| (c - e).abs() < 1e-15));
    }

    /// Roll damping's column is the reduced rate, and its gain is `C_l,p` as fitted.
    #[test]
    fn roll_damping_recovers_clp() {
        let context = test_context();
        let run = rolling_run(2000);
        let residual: Vec<f64> = run.phi_dot_rad_s.iter().map(|p| -0.05 * p * context.half_span_time_s).collect();
        let columns = RollDamping.columns(&Shape::Fixed, &run, 0, &context);
        let beta = test_fit(&columns, &residual);
        let params = RollDamping.params(&Shape::Fixed, &beta, &context, &[]);
        assert!((params[0].1 + 0.05).abs() < 1e-9, "{params:?}");
    }

    /// A damping that grows with the rate squared is told from a linear one: of the two laws,
    /// the quadratic leaves no residual and gives back its `C_l,p|p|`.
    #[test]
    fn roll_damping_family_tells_a_quadratic_law() {
        let context = test_context();
        let run = rolling_run(2000);
        let residual: Vec<f64> = context.p_hat(&run).iter().map(|p| -0.8 * p * p.abs()).collect();
        let fits: Vec<(f64, Shape, Vec<f64>)> = RollDamping
            .shapes(run.sample_hz, &context)
            .into_iter()
            .map(|shape| {
                let columns = RollDamping.columns(&shape, &run, 0, &context);
                let beta = test_fit(&columns, &residual);
                let sse: f64 = (0..run.len()).map(|i| (residual[i] - columns[0][i] * beta[0]).powi(2)).sum();
                (sse, shape, beta)
            })
            .collect();
        let best = fits.iter().min_by(|a, b| a.0.total_cmp(&b.0)).unwrap();
        assert_eq!(best.1, Shape::Damping { law: DampingLaw::Quadratic });
        let params = RollDamping.params(&best.1, &best.2, &context, &[]);
        assert_eq!(params[0].0, "clpp");
        assert!((params[0].1 + 0.8).abs() < 1e-9, "{params:?}");
        let linear = fits.iter().find(|f| f.1 == Shape::Damping { law: DampingLaw::Linear }).unwrap();
        assert!(linear.0 > 1e3 * best.0.max(1e-30), "the linear law leaves a residual");
    }

    /// Recalibration reports gains relative to one: a zero coefficient is the sim unchanged.
    #[test]
    fn recalibration_gains_are_relative_to_one() {
        let params = Recalibration.params(&Shape::Fixed, &[0.0, -0.25], &test_context(), &[]);
        assert_eq!(params, vec![("disturbance_gain".to_owned(), 1.0), ("plant_gain".to_owned(), 0.75)]);
    }
}

//! What the disturbance model and the superposition lack (G0, G4, G9 and the coupling): a rate
//! damping, a second slower flow state, the disturbance-actuation interaction, and the
//! recalibration of the existing blocks' gains that competes with every new effect
//! (docs/diagnosis.md, Candidate families).

use firmware_sim::effect::Effect;

use super::{
    AngleSet, BalanceCandidate, CmuLaw, Context, DampingLaw, Drive, Params, Shape, SlowLaw, difference,
    first_order_lag, gains, log_grid,
};
use crate::diagnose::streams::RunStreams;

/// `roll_damping`: a moment that grows with the roll rate, linear `C_l,p p_hat`, quadratic
/// `C_l,p|p| p_hat |p_hat|` or cubic `C_l,p3 p_hat^3`, one gain or one per angle of attack.
#[derive(Debug, Clone, Copy)]
pub struct RollDamping;

/// `vortex_lag`: a second, slower flow state, tau from 30 ms (no shorter than
/// [`Context::slow_tau_min_s`], twice the eGK's lag where it acts) to 50 times the eGK's lag
/// (at least 5 s), driven by a motion variable or by the vortex state itself, at every angle of
/// attack or at some of them only (a breakdown that sets in above an angle). The time
/// constants are profiled up to a factor `SLOW_SEARCH_MARGIN` beyond that range, and a best
/// form at the longest is no slow state ([`BalanceCandidate::beyond_its_range`]).
#[derive(Debug, Clone, Copy)]
pub struct VortexLag;

/// `coupling`: disturbance-actuation interaction terms, linear in Cmu or in its square root,
/// instantaneous or through a first-order lag, one set or one per angle of attack.
#[derive(Debug, Clone, Copy)]
pub struct Coupling;

/// Lags of the coupling's coarse grid, s: instantaneous, then 0.1 and 0.4 s (refined to a
/// factor of two either side; 0.02 to 0.8 s spans a jet's effect building up over a few to
/// some hundred convective times at tunnel speeds).
const COUPLING_LAGS_COARSE_S: [f64; 3] = [0.0, 0.1, 0.4];

/// Recalibration of the existing blocks' gains (group G0): names no new effect.
#[derive(Debug, Clone, Copy)]
pub struct Recalibration;

const AERODYNAMIC_SEPARATOR: &str = "forced roll at several reduced frequencies and a second free-stream speed (aerodynamic lags scale with c/U, rig lags do not)";

impl BalanceCandidate for RollDamping {
    fn regressors(&self) -> &'static str {
        "the reduced roll rate, linear, times its size, or cubed"
    }

    fn effect(&self) -> Option<Effect> {
        Some(Effect::RollDamping)
    }

    fn separating_experiment(&self) -> &'static str {
        AERODYNAMIC_SEPARATOR
    }

    fn shapes(&self, _sample_hz: f64, _context: &Context<'_>) -> Vec<Shape> {
        [DampingLaw::Linear, DampingLaw::Quadratic, DampingLaw::Cubic].map(|law| Shape::Damping { law }).to_vec()
    }

    fn schedulable(&self) -> bool {
        true
    }

    fn columns(&self, shape: &Shape, run: &RunStreams, _run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        let p_hat = context.p_hat(run);
        match shape {
            Shape::Damping { law: DampingLaw::Quadratic } => vec![p_hat.iter().map(|p| p * p.abs()).collect()],
            Shape::Damping { law: DampingLaw::Cubic } => vec![p_hat.iter().map(|p| p * p * p).collect()],
            _ => vec![p_hat],
        }
    }

    fn params(&self, shape: &Shape, beta: &[f64], _context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        match shape {
            Shape::Damping { law: DampingLaw::Quadratic } => gains(&["clpp"], beta),
            Shape::Damping { law: DampingLaw::Cubic } => gains(&["clp3"], beta),
            _ => gains(&["clp"], beta),
        }
    }
}

/// How far beyond the longest time constant of the contract's range the vortex lag's time
/// constants are profiled, as a factor. A best form at the longest searched is no slow state:
/// the state no longer moves with the motion, and its deficit `LP_tau[u] - u` is the drive's
/// own static term, `-u` (of the roll rate, a linear roll damping; of the eGK's moment, a change
/// of its gain). Two: an octave, so that a state at the contract's longest has its best fit
/// inside the search. The shortest has no such rule: it is twice the sim's eGK lag, and a rig's
/// own lift lag can be shorter, so a state of the contract's range can have its best fit there.
pub const SLOW_SEARCH_MARGIN: f64 = 2.0;

/// The time constant of a slow state's slow limit, s: far beyond any run, so that the state
/// holds its first value and its deficit is the drive's static term (`-u`; of the roll rate, a
/// linear roll damping; of the eGK's moment, a change of its gain).
const SLOW_LIMIT_S: f64 = 1e6;

impl VortexLag {
    /// Points of the coarse grid of time constants: 19 over the search's factor of 50 or more,
    /// the spacing that 16 gave over the contract's factor of 25.
    const COARSE: usize = 19;

    /// Up to this many angles of attack, a state is profiled at every set of them; beyond it,
    /// at every band of neighbouring angles, so that the forms grow with the square of the
    /// angles and not as a power of two (three angles: 6 sets; nine: 44 bands).
    const EVERY_SET_UP_TO: usize = 3;

    /// The contract's range of time constants, s: from 30 ms and twice the eGK's lag to 50
    /// times the eGK's lag ("2 to 50 times slower"), at least 5 s.
    fn tau_range(context: &Context<'_>) -> (f64, f64) {
        let low = 0.03f64.max(context.slow_tau_min_s);
        (low, 5.0f64.max(25.0 * context.slow_tau_min_s))
    }

    /// The time constants profiled, s: the contract's range, its longest widened by
    /// `SLOW_SEARCH_MARGIN`.
    fn search_range(context: &Context<'_>) -> (f64, f64) {
        let (low, high) = Self::tau_range(context);
        (low, high * SLOW_SEARCH_MARGIN)
    }

    fn taus(context: &Context<'_>, n: usize) -> Vec<f64> {
        let (low, high) = Self::search_range(context);
        log_grid(low, high, n)
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
    /// nine free gains absorbs the sim's own error from recording to recording. A state that acts
    /// at some angles of attack only (the contract's "at every alpha or only at some"; vortex
    /// breakdown sets in above an angle, Nelson & Pelletier 2003, and a burst vortex can also
    /// leave the flow at the highest) keeps one gain and profiles the set of angles where it
    /// acts ([`AngleSet::proper_sets`]). The vortex state's own deficit is the first column
    /// already, so that drive acts as the state only.
    fn shapes(&self, _sample_hz: f64, context: &Context<'_>) -> Vec<Shape> {
        let sets: Vec<Option<AngleSet>> = std::iter::once(None)
            .chain(AngleSet::proper_sets(context.alphas_deg.len(), Self::EVERY_SET_UP_TO).into_iter().map(Some))
            .collect();
        let sets = sets.as_slice();
        Self::taus(context, Self::COARSE)
            .into_iter()
            .flat_map(|tau_s| {
                Drive::ALL.into_iter().flat_map(move |drive| {
                    let laws: &'static [SlowLaw] = if drive == Drive::VortexState {
                        &[SlowLaw::State]
                    } else {
                        &[SlowLaw::State, SlowLaw::Deficit]
                    };
                    laws.iter().copied().flat_map(move |law| {
                        sets.iter().map(move |&at_alphas| Shape::SlowState { tau_s, drive, law, at_alphas })
                    })
                })
            })
            .collect()
    }

    fn refine(&self, best: &Shape, _sample_hz: f64, context: &Context<'_>) -> Vec<Shape> {
        let Shape::SlowState { tau_s, drive, law, at_alphas } = *best else { return Vec::new() };
        let (low, high) = Self::search_range(context);
        super::around(tau_s, super::grid_ratio(low, high, Self::COARSE), 7, low, high)
            .into_iter()
            .map(|tau_s| Shape::SlowState { tau_s, drive, law, at_alphas })
            .collect()
    }

    /// The state one sample fast (it is its drive, `u`, and its deficit the drive's rate: of the
    /// roll angle, a linear roll damping) and `SLOW_LIMIT_S` slow (its deficit is the drive's
    /// static term): a slower flow state is one whose time constant the data resolve between
    /// the two ("2 to 50 times slower than the eGK's lag", docs/spec/diagnosis.md). Where the
    /// recording's motion is too fast or too short to resolve it, a static term or a damping
    /// (outside the vocabulary, or another name) explains the gap as well, and naming a
    /// "slower state" would be a guess between them.
    fn limits(&self, shape: &Shape, sample_hz: f64) -> Vec<Shape> {
        let Shape::SlowState { drive, law, at_alphas, .. } = *shape else { return Vec::new() };
        [1.0 / sample_hz, SLOW_LIMIT_S].map(|tau_s| Shape::SlowState { tau_s, drive, law, at_alphas }).to_vec()
    }

    /// At the longest time constant searched (`SLOW_SEARCH_MARGIN`): a static term of the
    /// drive, not a slower state.
    fn beyond_its_range(&self, shape: &Shape, context: &Context<'_>) -> bool {
        let Shape::SlowState { tau_s, .. } = *shape else { return false };
        tau_s >= Self::search_range(context).1 * (1.0 - 1e-9)
    }

    /// A second, slower flow state (docs/diagnosis.md, Vortex lag, G9), in the forms a
    /// rig can have: a share of the eGK's response through the slower state
    /// (`LP_tau[C_l,eGK] - C_l,eGK`), and a new state driven by one of the disturbance's physical
    /// inputs, acting as itself, `LP_tau[u]`, or as its deficit, `LP_tau[u] - u`.
    fn columns(&self, shape: &Shape, run: &RunStreams, _run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        let Shape::SlowState { tau_s, drive, law, at_alphas } = *shape else { return Vec::new() };
        if at_alphas.is_some_and(|set| !set.holds(run.alpha_deg, &context.alphas_deg)) {
            return vec![vec![0.0; run.len()]; 2];
        }
        let dt_s = 1.0 / run.sample_hz;
        let input: Vec<f64> = match drive {
            Drive::RollRate => context.p_hat(run),
            Drive::RollAngle => run.phi_rad.clone(),
            Drive::Sideslip => {
                let alpha = run.alpha_deg.to_radians();
                run.phi_rad.iter().map(|phi| (alpha.sin() * phi.sin()).asin()).collect()
            }
            Drive::VortexState => run.cl_egk.clone(),
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
            Shape::SlowState { drive: Drive::VortexState, .. } => "per_unit_egk_moment",
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
        [CmuLaw::Linear, CmuLaw::SquareRoot]
            .into_iter()
            .flat_map(|law| COUPLING_LAGS_COARSE_S.map(|lag_s| Shape::Interaction { law, lag_s }))
            .collect()
    }

    fn refine(&self, best: &Shape, _sample_hz: f64, _context: &Context<'_>) -> Vec<Shape> {
        let Shape::Interaction { law, lag_s } = *best else { return Vec::new() };
        if lag_s <= 0.0 {
            return [0.5, 0.7]
                .map(|share| Shape::Interaction { law, lag_s: share * COUPLING_LAGS_COARSE_S[1] })
                .to_vec();
        }
        log_grid(lag_s / 2.0, lag_s * 2.0, 5).into_iter().map(|lag_s| Shape::Interaction { law, lag_s }).collect()
    }

    fn schedulable(&self) -> bool {
        true
    }

    /// The interaction: the blowing (differential and total, scaled; in Cmu or its square root)
    /// and the jets' own moment with their dynamics (the paper's C_l,Roll x C_l,AFC terms),
    /// times the disturbance's own variables (its moment, the roll angle and the reduced roll
    /// rate: blowing changes the wing's stiffness and its damping alike), each through the
    /// form's lag (a jet whose effect on the vortex builds up over convective times).
    fn columns(&self, shape: &Shape, run: &RunStreams, _run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        let Shape::Interaction { law, lag_s } = *shape else { return Vec::new() };
        let n = run.len();
        let cmu_ref = context.cmu_ref.max(f64::MIN_POSITIVE);
        let level = |cmu: f64| match law {
            CmuLaw::Linear => cmu / cmu_ref,
            CmuLaw::SquareRoot => (cmu.max(0.0) / cmu_ref).sqrt(),
        };
        let differential: Vec<f64> = (0..n).map(|idx| level(run.cmu[0][idx]) - level(run.cmu[1][idx])).collect();
        let total: Vec<f64> = (0..n).map(|idx| level(run.cmu[0][idx]) + level(run.cmu[1][idx])).collect();
        let p_hat = context.p_hat(run);
        let afc = run.cl_afc();
        let dt_s = 1.0 / run.sample_hz;
        let lagged = |column: Vec<f64>| if lag_s > 0.0 { first_order_lag(&column, lag_s, dt_s) } else { column };
        let mut columns = Vec::with_capacity(9);
        for variable in [&run.cl_egk, &run.phi_rad, &p_hat] {
            columns.push(lagged((0..n).map(|idx| variable[idx] * differential[idx]).collect()));
            columns.push(lagged((0..n).map(|idx| variable[idx] * total[idx]).collect()));
            columns.push(lagged((0..n).map(|idx| if run.rolls() { variable[idx] * afc[idx] } else { 0.0 }).collect()));
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
    use crate::diagnose::candidates::{test_context, test_fit, test_fit_runs, test_left};
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
        best_vortex_form_among(run, truth, context, |_| true)
    }

    /// [`best_vortex_form`] among the coarse forms `keep` keeps.
    fn best_vortex_form_among(
        run: &RunStreams,
        truth: &[f64],
        context: &Context<'_>,
        keep: impl Fn(&Shape) -> bool,
    ) -> (f64, Shape, Vec<f64>) {
        let fit = |shape: Shape| {
            let columns = VortexLag.columns(&shape, run, 0, context);
            let coef = test_fit(&columns, truth);
            (test_left(&columns, &coef, truth), shape, coef)
        };
        let best = |fits: Vec<(f64, Shape, Vec<f64>)>| fits.into_iter().min_by(|a, b| a.0.total_cmp(&b.0));
        let coarse =
            best(VortexLag.shapes(run.sample_hz, context).into_iter().filter(keep).map(fit).collect()).expect("forms");
        let finer: Vec<_> = VortexLag.refine(&coarse.1, run.sample_hz, context).into_iter().map(fit).collect();
        best(finer).filter(|fine| fine.0 <= coarse.0).unwrap_or(coarse)
    }

    /// The vortex-lag forms reach from the context's floor to an octave beyond the contract's
    /// longest (twice 5 s), and each time constant comes with every drive; the vortex state
    /// drives only the state law (its deficit is the family's first column).
    #[test]
    fn vortex_lag_forms_reach_beyond_the_range_and_cover_every_drive() {
        let context = test_context();
        let shapes = VortexLag.shapes(200.0, &context);
        let taus: Vec<f64> = shapes
            .iter()
            .map(|shape| match shape {
                Shape::SlowState { tau_s, .. } => *tau_s,
                other => panic!("not a slow state: {other:?}"),
            })
            .collect();
        let (low, high) = (context.slow_tau_min_s, 10.0);
        assert!(taus.iter().all(|tau| (low - 1e-9..=high + 1e-9).contains(tau)));
        assert!(taus.iter().any(|tau| (tau - low).abs() < 1e-9), "reaches the floor");
        assert!(taus.iter().any(|tau| (tau - high).abs() < 1e-9), "reaches 10 s");
        let count = |drive: Drive, law: SlowLaw| {
            shapes
                .iter()
                .filter(|s| matches!(s, Shape::SlowState { drive: d, law: l, .. } if *d == drive && *l == law))
                .count()
        };
        let per_law = count(Drive::Sideslip, SlowLaw::State);
        assert!(per_law > 0);
        for drive in [Drive::Sideslip, Drive::RollRate, Drive::RollAngle] {
            assert_eq!((count(drive, SlowLaw::State), count(drive, SlowLaw::Deficit)), (per_law, per_law), "{drive:?}");
        }
        assert_eq!(
            (count(Drive::VortexState, SlowLaw::State), count(Drive::VortexState, SlowLaw::Deficit)),
            (per_law, 0)
        );
        assert_eq!(shapes.len(), 7 * per_law);
    }

    /// A slow state driven by the vortex state itself, `0.3 LP_1s[C_l,eGK]`, is found with that
    /// drive, as the state.
    #[test]
    fn vortex_lag_profile_finds_a_state_of_the_vortex_state() {
        let context = test_context();
        let mut run = rolling_run(6000);
        // The eGK moment with a lag of its own, so that it is no multiple of the roll angle.
        run.cl_egk = first_order_lag(&run.phi_rad, 0.05, 1.0 / run.sample_hz).iter().map(|phi| -0.01 * phi).collect();
        let truth: Vec<f64> = first_order_lag(&run.cl_egk, 1.0, 1.0 / run.sample_hz).iter().map(|x| 0.3 * x).collect();
        let best = best_vortex_form(&run, &truth, &context);
        let Shape::SlowState { drive, law, .. } = best.1 else { unreachable!() };
        assert_eq!((drive, law), (Drive::VortexState, SlowLaw::State));
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
        let Shape::SlowState { tau_s, drive, law, at_alphas } = best.1 else { unreachable!() };
        assert_eq!((drive, law, at_alphas), (Drive::Sideslip, SlowLaw::State, None));
        // Within one step of the refined grid (a coarse cell either side in six steps).
        let (low, high) = VortexLag::search_range(&context);
        let fine_step = 2.0 * (high / low).ln() / (VortexLag::COARSE - 1) as f64 / 6.0;
        assert!((tau_s / 0.8).ln().abs() < fine_step, "tau {tau_s}");
        let params = VortexLag.params(&best.1, &best.2, &context, &[]);
        assert_eq!(params[1].0, "per_rad_sideslip");
        assert!((params[1].1 - 0.02).abs() < 0.004, "{params:?}");
    }

    /// A sideslip state at the middle of three angles only, `0.02 LP_0.8s[beta]` there and
    /// nothing at the others, is found with that one angle, and its gain is the gain where it
    /// acts (a form at every angle would share it with the two runs without it).
    #[test]
    fn vortex_lag_profile_finds_a_state_at_one_inner_angle_only() {
        let mut context = test_context();
        context.alphas_deg = vec![4.0, 12.0, 20.0];
        let runs: Vec<RunStreams> = context
            .alphas_deg
            .iter()
            .map(|alpha_deg| RunStreams { alpha_deg: *alpha_deg, ..rolling_run(4000) })
            .collect();
        let truth: Vec<f64> = runs
            .iter()
            .flat_map(|run| {
                let alpha = run.alpha_deg.to_radians();
                let beta: Vec<f64> = run.phi_rad.iter().map(|phi| (alpha.sin() * phi.sin()).asin()).collect();
                let acts = (run.alpha_deg - 12.0).abs() < 1e-9;
                first_order_lag(&beta, 0.8, 1.0 / run.sample_hz)
                    .into_iter()
                    .map(move |b| if acts { 0.02 * b } else { 0.0 })
            })
            .collect();
        let fit = |shape: &Shape| {
            let per_run: Vec<Vec<Vec<f64>>> =
                runs.iter().enumerate().map(|(idx, run)| VortexLag.columns(shape, run, idx, &context)).collect();
            test_fit_runs(&per_run, &truth)
        };
        let sideslip_states = VortexLag
            .shapes(200.0, &context)
            .into_iter()
            .filter(|shape| matches!(shape, Shape::SlowState { drive: Drive::Sideslip, law: SlowLaw::State, .. }));
        let (sse, best, coef) = sideslip_states
            .map(|shape| {
                let (sse, coef) = fit(&shape);
                (sse, shape, coef)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .expect("forms");
        let Shape::SlowState { at_alphas, .. } = best else { unreachable!() };
        assert_eq!(at_alphas.map(|set| set.angles_deg(&context.alphas_deg)), Some(vec![12.0]), "sse {sse}");
        let params = VortexLag.params(&best, &coef, &context, &[]);
        assert!((params[1].1 - 0.02).abs() < 0.004, "{params:?}");
    }

    /// A linear roll damping, `-0.05 p_hat`, is the static term the rate's deficit tends to as
    /// its state stops following the motion: that law's best fit lies at the longest time
    /// constant searched, beyond the family's range. A rate state of the contract's range,
    /// `0.5 (LP_0.6s[p_hat] - p_hat)`, has its best fit inside it.
    #[test]
    fn a_static_rate_term_is_beyond_the_slow_states_range() {
        let context = test_context();
        let mut run = rolling_run(6000);
        // A motion that starts at rest (no start-up transient of a long state), and an eGK
        // moment of its own motion (what its deficit column takes is no rate term).
        let t_s: Vec<f64> = (0..run.len()).map(|i| i as f64 / run.sample_hz).collect();
        run.phi_rad = t_s.iter().map(|t| -0.5 * (1.3 * t).cos() - 0.2 * (4.1 * t).cos()).collect();
        run.phi_dot_rad_s = t_s.iter().map(|t| 0.65 * (1.3 * t).sin() + 0.82 * (4.1 * t).sin()).collect();
        run.cl_egk = t_s.iter().map(|t| 0.01 * (2.3 * t).sin()).collect();
        let p_hat = context.p_hat(&run);
        let rate_deficit =
            |shape: &Shape| matches!(shape, Shape::SlowState { drive: Drive::RollRate, law: SlowLaw::Deficit, .. });
        let damping: Vec<f64> = p_hat.iter().map(|p| -0.05 * p).collect();
        let best = best_vortex_form_among(&run, &damping, &context, rate_deficit);
        assert!(VortexLag.beyond_its_range(&best.1, &context), "{:?}", best.1);
        let lagged = first_order_lag(&p_hat, 0.6, 1.0 / run.sample_hz);
        let state: Vec<f64> = lagged.iter().zip(&p_hat).map(|(l, p)| 0.5 * (l - p)).collect();
        let best = best_vortex_form_among(&run, &state, &context, rate_deficit);
        assert!(!VortexLag.beyond_its_range(&best.1, &context), "{:?}", best.1);
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
        let shape = Shape::Interaction { law: CmuLaw::Linear, lag_s: 0.0 };
        let columns = Coupling.columns(&shape, &run, 0, &context);
        assert_eq!(columns.len(), 9);
        assert!(columns.iter().flatten().all(|v| *v == 0.0));
        run.cmu = [vec![context.cmu_ref; 400], vec![0.0; 400]];
        let columns = Coupling.columns(&shape, &run, 0, &context);
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

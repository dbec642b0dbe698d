//! Controller blocks of the paper's Fig. 4 (King et al.; Williams et al.): a feedforward that
//! cancels the estimated disturbance moment through the inverted plant model with a causality
//! filter, `K_d = -F G_p^-1 G_d`, and a PI feedback on the measured roll moment
//! (Kerstens et al., AIAA J. 49(8), 2011; docs/equations.md, Controller design).
//!
//! The plant is the nonlinear SINDy difference equation, so it is inverted numerically at each
//! step: the jet's Cmu in `[0, Cmu_max]` whose next-step moment meets the demand, by bisection
//! with a fixed number of iterations (bounded time, no panic). Blowing is one-signed per jet, so
//! a signed moment demand goes to the jet whose effect has its sign; the other jet is off.

use crate::coeffs::{CoefficientSet, ControllerParams};
use crate::health::Health;
use crate::plant::Plant;
use crate::sparse::{Interpreted, ModelId, SparseEval};

/// Inputs of one controller step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControllerInput {
    /// Disturbance moment to cancel (the estimator's `C_l,roll`, with or without the coupling
    /// correction, as the caller chooses).
    pub disturbance_cl: f32,
    /// Measured roll moment for the feedback (NaN when not measured this step).
    pub measured_cl: f32,
    /// Angle of attack, rad.
    pub alpha_rad: f32,
}

/// Output of one controller step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Demand {
    /// Cmu demand of the port and starboard jets.
    pub cmu: [f32; 2],
    /// Total actuation moment demanded for the next step.
    pub moment: f32,
}

/// The controller's state: the causality filter and the feedback integrator.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Controller {
    filtered_target: f32,
    integral: f32,
}

impl Controller {
    /// At rest.
    #[must_use]
    pub const fn new() -> Self {
        Self { filtered_target: 0.0, integral: 0.0 }
    }

    /// One step with the plants' current states. `feedforward` and `feedback` switch the two
    /// blocks (the SIL harness compares them).
    pub fn step(
        &mut self,
        set: &CoefficientSet,
        plants: &[Plant; 2],
        input: &ControllerInput,
        blocks: Blocks,
        health: &mut Health,
    ) -> Demand {
        self.step_with(Interpreted, set, plants, input, blocks, health)
    }

    /// [`Controller::step`] with the plant models evaluated by `eval` (the estimator's
    /// [`crate::Estimator::evaluator`]).
    pub fn step_with<E: SparseEval>(
        &mut self,
        eval: E,
        set: &CoefficientSet,
        plants: &[Plant; 2],
        input: &ControllerInput,
        blocks: Blocks,
        health: &mut Health,
    ) -> Demand {
        let params = &set.controller;
        let target = if blocks.feedforward && input.disturbance_cl.is_finite() { -input.disturbance_cl } else { 0.0 };
        self.filtered_target = params.causality_pole * self.filtered_target + (1.0 - params.causality_pole) * target;
        let error = if blocks.feedback { -input.measured_cl } else { 0.0 };
        if blocks.feedback && !error.is_finite() {
            health.set(Health::FEEDBACK_HELD);
        }
        let error = if error.is_finite() { error } else { 0.0 };
        let moment = self.filtered_target + params.feedback_kp * error + params.feedback_ki * self.integral;
        let (cmu, saturated) = allocate(eval, set, plants, moment, input.alpha_rad);
        if saturated {
            health.set(Health::CMU_SATURATED);
        } else {
            // Conditional integration: the integrator stops while the jets saturate.
            self.integral += error * set.dt_s;
        }
        if !(self.filtered_target.is_finite() && self.integral.is_finite()) {
            *self = Self::new();
            health.set(Health::STATE_RESET);
        }
        Demand { cmu, moment }
    }
}

/// Which controller blocks are on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Blocks {
    /// Feedforward from the disturbance estimate.
    pub feedforward: bool,
    /// Feedback on the measured roll moment.
    pub feedback: bool,
}

/// Chooses the jet and its Cmu for a total next-step moment `demand`; returns the demands and
/// whether the chosen jet saturated.
fn allocate<E: SparseEval>(
    eval: E,
    set: &CoefficientSet,
    plants: &[Plant; 2],
    demand: f32,
    alpha_rad: f32,
) -> ([f32; 2], bool) {
    let params = &set.controller;
    let next = |side: usize, cmu: f32| {
        eval.eval(ModelId::plant(side), &set.plant[side].model, &plants[side].variables(cmu, alpha_rad))
    };
    let coasting = [next(0, 0.0), next(1, 0.0)];
    let full = [next(0, params.cmu_max), next(1, params.cmu_max)];
    let wanted = demand - coasting[0] - coasting[1];
    let mut best: Option<(usize, f32)> = None;
    for side in 0..2 {
        let authority = full[side] - coasting[side];
        if authority * wanted > 0.0 && best.is_none_or(|(_, best_authority)| authority.abs() > best_authority.abs()) {
            best = Some((side, authority));
        }
    }
    let Some((side, _)) = best else { return ([0.0; 2], false) };
    let target = demand - coasting[1 - side];
    let ends = Bracket { low: coasting[side] - target, high: full[side] - target };
    let (cmu, saturated) = invert(params, |cmu| next(side, cmu) - target, ends);
    let mut cmu_pair = [0.0; 2];
    cmu_pair[side] = cmu;
    (cmu_pair, saturated)
}

/// The residual `f(cmu) - target` at both ends of `[0, Cmu_max]`.
#[derive(Debug, Clone, Copy)]
struct Bracket {
    low: f32,
    high: f32,
}

/// Largest residual moment the inversion accepts, far below any balance's noise.
const INVERSION_TOLERANCE: f32 = 1e-9;

/// Solves `residual(cmu) = 0` on `[0, Cmu_max]` by the Illinois variant of regula falsi
/// (Dowell & Jarratt, BIT 11, 1971): superlinear on the smooth plant polynomial, bracketed
/// like bisection, at most `inversion_iterations` evaluations. A target out of reach gives the
/// nearer end of the range, reported as saturated.
fn invert(params: &ControllerParams, residual: impl Fn(f32) -> f32, ends: Bracket) -> (f32, bool) {
    let (mut a, mut b) = (0.0f32, crate::max_num(params.cmu_max, 0.0));
    let (mut fa, mut fb) = (ends.low, ends.high);
    if !(fa.is_finite() && fb.is_finite()) {
        return (0.0, true);
    }
    if fa * fb > 0.0 {
        return if fa.abs() <= fb.abs() { (a, true) } else { (b, true) };
    }
    for _ in 0..params.inversion_iterations {
        if fb.abs() <= INVERSION_TOLERANCE {
            break;
        }
        let secant = b - fb * (b - a) / (fb - fa);
        // Fall back to bisection where the secant step is not usable.
        let c = if secant.is_finite() && secant >= crate::min_num(a, b) && secant <= crate::max_num(a, b) {
            secant
        } else {
            0.5 * (a + b)
        };
        let fc = residual(c);
        if !fc.is_finite() {
            break;
        }
        if fc * fb < 0.0 {
            (a, fa) = (b, fb);
        } else {
            fa *= 0.5;
        }
        (b, fb) = (c, fc);
    }
    (b, false)
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // Index loops read like the matrix formulas they check.
mod tests {
    use super::*;
    use crate::prior::PRIOR;

    const FEEDFORWARD: Blocks = Blocks { feedforward: true, feedback: false };

    fn next_moment(plants: &[Plant; 2], cmu: [f32; 2]) -> f32 {
        (0..2).map(|side| PRIOR.plant[side].model.eval(&plants[side].variables(cmu[side], 0.0))).sum()
    }

    #[test]
    fn demand_within_reach_is_met_by_the_jet_of_its_sign() {
        let plants = [Plant::new(); 2];
        for (demand, side) in [(1e-4f32, 0usize), (-1e-4, 1)] {
            let (cmu, saturated) = allocate(Interpreted, &PRIOR, &plants, demand, 0.0);
            assert!(!saturated);
            assert_eq!(cmu[1 - side], 0.0, "blowing is one-signed per jet: the other jet is off");
            assert!(cmu[side] > 0.0 && cmu[side] <= PRIOR.controller.cmu_max);
            // 16 bisection steps resolve Cmu to 0.009 / 2^16, far below the demand's scale.
            assert!((next_moment(&plants, cmu) - demand).abs() < 1e-8, "{cmu:?}");
        }
    }

    #[test]
    fn demand_out_of_reach_saturates_at_the_largest_cmu() {
        let plants = [Plant::new(); 2];
        let (cmu, saturated) = allocate(Interpreted, &PRIOR, &plants, 0.5, 0.0);
        assert!(saturated);
        assert_eq!(cmu, [PRIOR.controller.cmu_max, 0.0]);
        assert_eq!(allocate(Interpreted, &PRIOR, &plants, 0.0, 0.0), ([0.0; 2], false));
    }

    #[test]
    fn feedforward_cancels_a_steady_disturbance_through_the_causality_filter() {
        let mut controller = Controller::new();
        let mut plants = [Plant::new(); 2];
        let input = ControllerInput { disturbance_cl: -0.004, measured_cl: f32::NAN, alpha_rad: 0.0 };
        let mut cl_afc = 0.0;
        for _ in 0..3000 {
            let demand = controller.step(&PRIOR, &plants, &input, FEEDFORWARD, &mut Health::default());
            cl_afc = 0.0;
            for side in 0..2 {
                cl_afc += plants[side].step(&PRIOR.plant[side], demand.cmu[side], 0.0).0;
            }
        }
        assert!((cl_afc - 0.004).abs() < 1e-5, "the jets cancel the disturbance: {cl_afc}");
    }

    #[test]
    fn feedback_integrates_and_holds_without_a_measurement() {
        let mut controller = Controller::new();
        let plants = [Plant::new(); 2];
        let blocks = Blocks { feedforward: false, feedback: true };
        let measured = ControllerInput { disturbance_cl: 0.0, measured_cl: -1e-4, alpha_rad: 0.0 };
        let first = controller.step(&PRIOR, &plants, &measured, blocks, &mut Health::default());
        let second = controller.step(&PRIOR, &plants, &measured, blocks, &mut Health::default());
        assert!(second.moment > first.moment && first.moment > 0.0, "{first:?} {second:?}");
        let mut health = Health::default();
        let missing = ControllerInput { measured_cl: f32::NAN, ..measured };
        let held = controller.step(&PRIOR, &plants, &missing, blocks, &mut health);
        assert!(health.has(Health::FEEDBACK_HELD));
        assert!((held.moment - PRIOR.controller.feedback_ki * 2.0 * 1e-4 * PRIOR.dt_s).abs() < 1e-9);
    }
}

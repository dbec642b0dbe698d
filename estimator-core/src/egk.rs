//! The extended Goman-Khrabrov (eGK) disturbance model: the roll moment of the rolling wing
//! from its roll angle, rate and acceleration at the given angle of attack.
//!
//! Two flow states, one per half-wing (the vortex-breakdown form of GK for delta wings,
//! Goman & Khrabrov, J. Aircraft 31(5), 1994; docs/equations.md, Extended Goman-Khrabrov model):
//!
//! - effective incidence of each half-wing under body-axis roll,
//!   `a_L,R = atan(tan alpha cos phi) -+ kb asin(sin alpha sin phi)`;
//! - state equation `tau1 x' + x = x0(a - tau2 a')` with the Fischenberg breakdown curve
//!   `x0(a) = (1 - tanh(k (a - a*))) / 2` (Jategaonkar, Flight Vehicle System Identification,
//!   ch. 12), updated exactly for an input held over the step (zero-order hold):
//!   `x[k] = x0 + (x[k-1] - x0) exp(-dt / tau1)`, then clamped to `[0, 1]`;
//! - output map `C_l = C_l,beta beta + C_l,p p_hat + C_l,pdot p_hat_dot +
//!   C_l,p|p| p_hat |p_hat| + K_v (x_L - x_R) + C_l,0`, where the rate-damping and acceleration terms are the
//!   "extension" for a rolling motion, and the quadratic damping is the `|phi_dot| phi_dot` term
//!   of the slender-wing roll models (Elzebda, Nayfeh & Mook, J. Aircraft 26(8), 1989;
//!   docs/equations.md, Slender-wing roll moment forms).
//!
//! The input is held over the step that ends at `k` (the sample of step `k`), so the state of
//! step `k` already responds to the input of step `k`.
//!
//! The equations are generic over the scalar ([`crate::real`]): the estimator's [`Egk`] runs
//! them in f32 on the coefficient set's schedule; the host's fit runs [`EgkState`] in f64 at
//! each angle of attack.

use crate::coeffs::{CoefficientSet, EgkParams, N_ALPHA};
use crate::real::Real;
use crate::schedule::SchedulePosition;

/// Exact zero-order-hold update of `tau x' + x = x0` over one step: `x0 + (x - x0) decay`
/// with `decay = exp(-dt / tau)`.
#[must_use]
pub fn gk_update<R: Real>(state: R, target: R, decay: R) -> R {
    target + (state - target) * decay
}

/// Fischenberg breakdown curve `x0(a) = (1 - tanh(k (a - a*))) / 2`, `a` in deg, computed as
/// the identical logistic `1 / (1 + e^(2 k (a - a*)))` with the scalar's exponential (in f32
/// [`crate::exp`]: one exponential and a division instead of libm's `tanhf`).
#[must_use]
pub fn breakdown_curve<R: Real>(params: &EgkParams<R>, incidence_deg: R) -> R {
    let two = R::ONE + R::ONE;
    R::ONE / (R::ONE + (two * params.steepness_per_deg * (incidence_deg - params.breakdown_deg)).exp())
}

/// The eGK parameters at `alpha_deg`: linear interpolation between the schedule's breakpoints,
/// held constant outside them.
#[must_use]
pub fn params_at(set: &CoefficientSet, alpha_deg: f32) -> EgkParams {
    params_from(set, crate::schedule::position(set, alpha_deg))
}

/// The eGK parameters at a position in the schedule.
fn params_from(set: &CoefficientSet, at: SchedulePosition) -> EgkParams {
    let low = &set.egk[at.lower.min(N_ALPHA - 1)];
    if at.weight == 0.0 {
        return *low;
    }
    interpolate(low, &set.egk[at.upper.min(N_ALPHA - 1)], at.weight)
}

fn interpolate(low: &EgkParams, high: &EgkParams, weight: f32) -> EgkParams {
    let mix = |a: f32, b: f32| a + weight * (b - a);
    EgkParams {
        tau1_s: mix(low.tau1_s, high.tau1_s),
        tau2_s: mix(low.tau2_s, high.tau2_s),
        breakdown_deg: mix(low.breakdown_deg, high.breakdown_deg),
        steepness_per_deg: mix(low.steepness_per_deg, high.steepness_per_deg),
        sideslip_gain: mix(low.sideslip_gain, high.sideslip_gain),
        clbeta_per_rad: mix(low.clbeta_per_rad, high.clbeta_per_rad),
        clp: mix(low.clp, high.clp),
        clpdot: mix(low.clpdot, high.clpdot),
        clpp: mix(low.clpp, high.clpp),
        vortex_gain: mix(low.vortex_gain, high.vortex_gain),
        bias: mix(low.bias, high.bias),
        half_span_time_s: mix(low.half_span_time_s, high.half_span_time_s),
    }
}

/// Geometry of body-axis roll at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RollGeometry<R = f32> {
    /// Sideslip `beta = asin(sin alpha sin phi)`, rad.
    pub beta_rad: R,
    /// Effective incidence of the port and starboard half-wings, deg.
    pub incidence_deg: [R; 2],
    /// Their rates, deg/s.
    pub incidence_rate_deg_s: [R; 2],
}

/// Sideslip and half-wing incidences under body-axis roll (docs/equations.md, Kinematics):
/// `beta = asin(sin alpha sin phi)`, `alpha_b = atan(tan alpha cos phi)`, and the windward
/// half-wing sees `alpha_b + kb beta`.
#[must_use]
pub fn roll_geometry<R: Real>(
    sin_alpha: R,
    tan_alpha: R,
    sideslip_gain: R,
    phi_rad: R,
    phi_dot_rad_s: R,
) -> RollGeometry<R> {
    let (sin_phi, cos_phi) = phi_rad.sin_cos();
    let sin_beta = (sin_alpha * sin_phi).clamp(-R::ONE, R::ONE);
    let beta_rad = sin_beta.asin();
    let tan_cos = tan_alpha * cos_phi;
    let alpha_b = tan_cos.atan();
    // cos(asin(s)) = sqrt(1 - s^2): a square root instead of a cosine.
    let cos_beta = crate::max_num((R::ONE - sin_beta * sin_beta).sqrt(), R::from_f64(1e-6));
    let dbeta_dphi = sin_alpha * cos_phi / cos_beta;
    let dalpha_b_dphi = -tan_alpha * sin_phi / (R::ONE + tan_cos * tan_cos);
    let to_deg = R::DEG_PER_RAD;
    let kb = sideslip_gain;
    RollGeometry {
        beta_rad,
        incidence_deg: [(alpha_b - kb * beta_rad) * to_deg, (alpha_b + kb * beta_rad) * to_deg],
        incidence_rate_deg_s: [
            (dalpha_b_dphi - kb * dbeta_dphi) * phi_dot_rad_s * to_deg,
            (dalpha_b_dphi + kb * dbeta_dphi) * phi_dot_rad_s * to_deg,
        ],
    }
}

/// The eGK at one angle of attack: its parameters there and the constants they give.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgkConstants<R = f32> {
    /// The parameters.
    pub params: EgkParams<R>,
    /// `exp(-dt / tau1)`.
    decay: R,
    sin_alpha: R,
    /// `tan alpha`, alpha limited to +-1.5 rad.
    tan_alpha: R,
}

impl<R: Real> EgkConstants<R> {
    /// The constants of `params` at `alpha_deg` for the step `dt_s`, in the scalar's own
    /// functions (f32: [`crate::exp`], [`crate::trig`]; libm's `expf`, `sinf` and `tanf`
    /// compute in f64, which the M4F emulates in software at thousands of instructions, and
    /// in flight alpha changes every step). The estimator holds alpha within +-60 deg, inside
    /// the +-90 deg of `sin_cos`; `tan` is limited to `+-1.5` rad.
    #[must_use]
    pub fn new(params: EgkParams<R>, alpha_deg: R, dt_s: R) -> Self {
        let tau1_s = crate::max_num(params.tau1_s, R::from_f64(1e-6));
        let decay = (-dt_s / tau1_s).exp();
        let alpha_rad = alpha_deg * R::RAD_PER_DEG;
        let sin_alpha = alpha_rad.sin_cos().0;
        let limit = R::from_f64(1.5);
        let (sin_limited, cos_limited) = alpha_rad.clamp(-limit, limit).sin_cos();
        Self { params, decay, sin_alpha, tan_alpha: sin_limited / cos_limited }
    }
}

/// The regressors of the eGK's output map at one step, in the order of its weights
/// `[C_l,beta, C_l,p, C_l,pdot, C_l,p|p|, K_v, C_l,0]`:
/// `[beta, p_hat, p_hat_dot, p_hat |p_hat|, x_L - x_R, 1]`. The map is linear in the weights
/// once the states are known (the host's fit solves for them).
pub type EgkRegressors<R> = [R; 6];

/// The eGK's two flow states.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgkState<R = f32> {
    vortex: [R; 2],
    primed: bool,
}

/// Kinematic inputs of one eGK step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgkInput<R = f32> {
    /// Roll angle, rad.
    pub phi_rad: R,
    /// Roll rate, rad/s.
    pub phi_dot_rad_s: R,
    /// Roll acceleration, rad/s^2.
    pub phi_ddot_rad_s2: R,
    /// Angle of attack, deg.
    pub alpha_deg: R,
}

impl<R: Real> EgkState<R> {
    /// Before its first step: the states are set to their quasi-steady values then.
    #[must_use]
    pub const fn new() -> Self {
        Self { vortex: [R::ONE; 2], primed: false }
    }

    /// The flow states (port, starboard).
    #[must_use]
    pub const fn vortex(&self) -> [R; 2] {
        self.vortex
    }

    /// One step at `constants` (the input's alpha is theirs); returns the output map's
    /// regressors and whether a state had to be reset.
    pub fn advance(&mut self, constants: &EgkConstants<R>, input: &EgkInput<R>) -> (EgkRegressors<R>, bool) {
        let params = &constants.params;
        let geometry = roll_geometry(
            constants.sin_alpha,
            constants.tan_alpha,
            params.sideslip_gain,
            input.phi_rad,
            input.phi_dot_rad_s,
        );
        let mut reset = false;
        for side in 0..2 {
            let lagged = geometry.incidence_deg[side] - params.tau2_s * geometry.incidence_rate_deg_s[side];
            let target = breakdown_curve(params, lagged);
            let next = if self.primed { gk_update(self.vortex[side], target, constants.decay) } else { target };
            reset |= !next.is_finite();
            self.vortex[side] = if next.is_finite() { next.clamp(R::ZERO, R::ONE) } else { R::ONE };
        }
        self.primed = true;
        let p_hat = input.phi_dot_rad_s * params.half_span_time_s;
        let p_hat_dot = input.phi_ddot_rad_s2 * params.half_span_time_s * params.half_span_time_s;
        let regressors =
            [geometry.beta_rad, p_hat, p_hat_dot, p_hat * p_hat.abs(), self.vortex[0] - self.vortex[1], R::ONE];
        (regressors, reset)
    }
}

impl<R: Real> Default for EgkState<R> {
    fn default() -> Self {
        Self::new()
    }
}

/// The output map: `C_l = w . regressors`, summed in the weights' order.
#[must_use]
pub fn output_map<R: Real>(params: &EgkParams<R>, regressors: &EgkRegressors<R>) -> R {
    let weights = [params.clbeta_per_rad, params.clp, params.clpdot, params.clpp, params.vortex_gain, params.bias];
    weights.iter().zip(regressors).fold(R::NEG_ZERO, |sum, (&w, &x)| sum + w * x)
}

/// The estimator's eGK stage: its two flow states and the constants cached for the current
/// alpha, from the coefficient set's schedule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Egk {
    state: EgkState,
    cached_alpha_deg: f32,
    /// Where the cached alpha lies in the schedule (the pressure path's map uses it too).
    at: SchedulePosition,
    constants: EgkConstants,
}

impl Egk {
    /// Before its first step: the states are set to their quasi-steady values then.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            state: EgkState::new(),
            cached_alpha_deg: f32::NAN,
            at: SchedulePosition::FIRST,
            constants: EgkConstants {
                params: EgkParams {
                    tau1_s: 1.0,
                    tau2_s: 0.0,
                    breakdown_deg: 0.0,
                    steepness_per_deg: 0.0,
                    sideslip_gain: 0.0,
                    clbeta_per_rad: 0.0,
                    clp: 0.0,
                    clpdot: 0.0,
                    clpp: 0.0,
                    vortex_gain: 0.0,
                    bias: 0.0,
                    half_span_time_s: 0.0,
                },
                decay: 0.0,
                sin_alpha: 0.0,
                tan_alpha: 0.0,
            },
        }
    }

    /// Where the alpha of the last step lies in the schedule: computed when alpha changes, so
    /// the estimator's other scheduled stage does not search the schedule every step.
    #[must_use]
    pub const fn schedule_position(&self) -> SchedulePosition {
        self.at
    }

    /// The flow states (port, starboard).
    #[must_use]
    pub const fn vortex(&self) -> [f32; 2] {
        self.state.vortex
    }

    /// One step; returns `C_l,roll,eGK` and whether a state had to be reset.
    pub fn step(&mut self, set: &CoefficientSet, input: &EgkInput) -> (f32, bool) {
        self.refresh_alpha(set, input.alpha_deg);
        let (regressors, reset) = self.state.advance(&self.constants, input);
        (output_map(&self.constants.params, &regressors), reset)
    }

    /// Recomputes the alpha-dependent constants when alpha changes (bitwise).
    fn refresh_alpha(&mut self, set: &CoefficientSet, alpha_deg: f32) {
        if alpha_deg.to_bits() == self.cached_alpha_deg.to_bits() {
            return;
        }
        self.cached_alpha_deg = alpha_deg;
        self.at = crate::schedule::position(set, alpha_deg);
        self.constants = EgkConstants::new(params_from(set, self.at), alpha_deg, set.dt_s);
    }
}

impl Default for Egk {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // Index loops read like the matrix formulas they check.
mod tests {
    use super::*;
    use crate::prior::PRIOR;

    /// The f64 reference: the same continuous-time model, written independently.
    struct Reference {
        params: EgkParams,
        alpha_rad: f64,
    }

    impl Reference {
        fn target(&self, phi: f64, phi_dot: f64, side: usize) -> f64 {
            let p = &self.params;
            let (sin_a, tan_a) = (self.alpha_rad.sin(), self.alpha_rad.tan());
            let beta = (sin_a * phi.sin()).asin();
            let alpha_b = (tan_a * phi.cos()).atan();
            let dbeta = sin_a * phi.cos() / beta.cos() * phi_dot;
            let dalpha_b = -tan_a * phi.sin() / (1.0 + (tan_a * phi.cos()).powi(2)) * phi_dot;
            let sign = if side == 0 { -1.0 } else { 1.0 };
            let kb = f64::from(p.sideslip_gain);
            let incidence = (alpha_b + sign * kb * beta).to_degrees();
            let rate = (dalpha_b + sign * kb * dbeta).to_degrees();
            let lagged = incidence - f64::from(p.tau2_s) * rate;
            0.5 * (1.0 - (f64::from(p.steepness_per_deg) * (lagged - f64::from(p.breakdown_deg))).tanh())
        }

        /// RK4 with `n_sub` substeps over `[t0, t0 + dt]` of `tau1 x' + x = x0(input(t))`.
        fn integrate(&self, state: [f64; 2], t0: f64, dt: f64, input: &dyn Fn(f64) -> (f64, f64)) -> [f64; 2] {
            let n_sub = 20;
            let tau1 = f64::from(self.params.tau1_s);
            let h = dt / n_sub as f64;
            let mut x = state;
            for sub in 0..n_sub {
                let t = t0 + sub as f64 * h;
                for side in 0..2 {
                    let rate = |time: f64, value: f64| {
                        let (phi, phi_dot) = input(time);
                        (self.target(phi, phi_dot, side) - value) / tau1
                    };
                    let k1 = rate(t, x[side]);
                    let k2 = rate(t + h / 2.0, x[side] + h / 2.0 * k1);
                    let k3 = rate(t + h / 2.0, x[side] + h / 2.0 * k2);
                    let k4 = rate(t + h, x[side] + h * k3);
                    x[side] += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
                }
            }
            x
        }
    }

    fn roll(t: f64) -> (f64, f64) {
        let omega = core::f64::consts::TAU * 1.5;
        (25f64.to_radians() * (omega * t).sin(), 25f64.to_radians() * omega * (omega * t).cos())
    }

    /// Largest difference between the core's states and the reference's over 2 s of roll at
    /// alpha = 20 deg, where the breakdown curve is steepest, at step `dt`.
    fn max_error_against_rk4(held_input: bool, dt: f64) -> f64 {
        let alpha_deg = 20.0f32;
        let set = CoefficientSet { dt_s: dt as f32, ..PRIOR };
        let mut egk = Egk::new();
        let reference = Reference { params: params_at(&set, alpha_deg), alpha_rad: f64::from(alpha_deg).to_radians() };
        let mut x_ref = [0.0; 2];
        let mut worst = 0.0f64;
        for k in 0..(2.0 / dt).round() as usize {
            let t = k as f64 * dt;
            let (phi, phi_dot) = roll(t);
            let input =
                EgkInput { phi_rad: phi as f32, phi_dot_rad_s: phi_dot as f32, phi_ddot_rad_s2: 0.0, alpha_deg };
            let _ = egk.step(&set, &input);
            if k == 0 {
                x_ref = [reference.target(phi, phi_dot, 0), reference.target(phi, phi_dot, 1)];
            } else if held_input {
                // The core holds the input of step k over the step ending at k.
                x_ref = reference.integrate(x_ref, t - dt, dt, &|_| (phi, phi_dot));
            } else {
                x_ref = reference.integrate(x_ref, t - dt, dt, &roll);
            }
            for side in 0..2 {
                worst = worst.max((f64::from(egk.vortex()[side]) - x_ref[side]).abs());
            }
        }
        worst
    }

    #[test]
    fn update_matches_the_exact_solution_for_a_held_input() {
        let (tau1_s, target) = (0.15f64, 0.2f64);
        let dt = 1e-3;
        let decay = (-dt / tau1_s).exp() as f32;
        let mut state = 1.0f32;
        for k in 1..=3000 {
            state = gk_update(state, target as f32, decay);
            let exact = target + (1.0 - target) * (-(k as f64) * dt / tau1_s).exp();
            // f32 round-off accumulates to a few ulps of the state over 3000 steps.
            assert!((f64::from(state) - exact).abs() < 2e-6, "step {k}: {state} vs {exact}");
        }
    }

    #[test]
    fn states_match_rk4_for_a_held_moving_input_to_round_off() {
        let error = max_error_against_rk4(true, 1e-3);
        assert!(error < 2e-5, "{error}");
    }

    #[test]
    fn states_match_rk4_for_a_continuous_input_to_first_order_in_the_step() {
        // Holding the input over a step shifts it by half a step on average; as |x'| <= 1 / tau1
        // (x and x0 lie in [0, 1]), the state error stays below dt / (2 tau1) and halves with dt.
        let tau1_s = f64::from(PRIOR.egk[2].tau1_s);
        let coarse = max_error_against_rk4(false, 1e-3);
        let fine = max_error_against_rk4(false, 0.5e-3);
        assert!(coarse < 1e-3 / (2.0 * tau1_s), "{coarse}");
        let order = coarse / fine;
        assert!((1.7..2.3).contains(&order), "first order in dt: {coarse} / {fine} = {order}");
    }

    #[test]
    fn states_stay_in_their_range_and_start_quasi_steady() {
        let mut egk = Egk::new();
        let input = EgkInput { phi_rad: 0.4, phi_dot_rad_s: 0.0, phi_ddot_rad_s2: 0.0, alpha_deg: 20.0 };
        let _ = egk.step(&PRIOR, &input);
        let first = egk.vortex();
        let _ = egk.step(&PRIOR, &input);
        assert_eq!(first, egk.vortex(), "a quasi-steady start does not move under a held input");
        let wild = EgkInput { phi_rad: 1.5, phi_dot_rad_s: 1e6, phi_ddot_rad_s2: -1e6, alpha_deg: 20.0 };
        for _ in 0..100 {
            let (cl, reset) = egk.step(&PRIOR, &wild);
            assert!(cl.is_finite() && !reset);
            assert!(egk.vortex().iter().all(|x| (0.0..=1.0).contains(x)));
        }
    }

    #[test]
    fn schedule_interpolates_and_holds_outside() {
        assert_eq!(params_at(&PRIOR, -5.0), PRIOR.egk[0]);
        assert_eq!(params_at(&PRIOR, 35.0), PRIOR.egk[2]);
        let middle = params_at(&PRIOR, 15.0);
        let expected = 0.5 * (PRIOR.egk[1].clbeta_per_rad + PRIOR.egk[2].clbeta_per_rad);
        assert!((middle.clbeta_per_rad - expected).abs() < 1e-7);
    }
}

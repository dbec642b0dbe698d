//! The fixed-step estimator: one call per sample runs every stage in order.
//!
//! 1. inputs: validate, hold the last valid value of a missing one, clamp to physical ranges;
//! 2. roll rate and acceleration from the encoder ([`crate::rate`]);
//! 3. eGK ([`crate::egk`]);
//! 4. pressure model and Kalman filter ([`crate::pressure`]);
//! 5. fusion into `C_l,roll` ([`crate::fusion`]);
//! 6. plant of each jet, `C_l,AFC` ([`crate::plant`]);
//! 7. linear superposition and the coupling operator ([`crate::coupling`]);
//! 8. the envelope: `C_l,roll`, `C_l,linear` and `C_l` kept within the fitted range of roll
//!    moments with its margin ([`crate::coeffs::Envelope`]).
//!
//! Between steps the caller notes the controller's demand ([`Estimator::note_demand`]): a
//! missing blowing measurement is then predicted from it ([`crate::actuator`]) instead of held.

use crate::actuator::DemandHistory;
use crate::coeffs::{CoefficientSet, CompiledDefault, Envelope, N_PRESSURE_INPUTS, N_TAPS};
use crate::coupling::{CouplingInput, correction_with};
use crate::egk::{Egk, EgkInput};
use crate::fusion::Fusion;
use crate::health::Health;
use crate::plant::Plant;
use crate::pressure::PressureFilter;
use crate::rate::{RateEstimator, RollRates};
use crate::sparse::{Interpreted, ModelId, SparseEval};

/// Largest |roll angle| accepted, deg (beyond it the input is clamped and flagged).
const PHI_LIMIT_DEG: f32 = 90.0;
/// Largest |angle of attack| accepted, deg.
const ALPHA_LIMIT_DEG: f32 = 60.0;
/// Largest Cmu accepted (far beyond any trailing-edge jet).
const CMU_LIMIT: f32 = 0.1;
/// Largest |roll rate| passed on, rad/s (about 4 times the largest of the paper's campaign,
/// 8 rad/s): an encoder that jumps (a spike, a stuck value released) makes the differentiated
/// angle spike far beyond what the rig can do, and the eGK's damping term would turn that into
/// a roll moment of several units.
const PHI_DOT_LIMIT_RAD_S: f32 = 30.0;
/// Largest |roll acceleration| passed on, rad/s^2 (about 8 times the largest of the paper's
/// campaign, 380 rad/s^2, most of which is differentiated encoder noise), for the same reason.
const PHI_DDOT_LIMIT_RAD_S2: f32 = 3000.0;
/// Steps over which a missing roll angle is extrapolated with the filtered roll rate before it
/// is held (50 ms at 1 kHz): a dropped encoder sample then does not show up as a step of the
/// angle (a spike of the rate) when the next one arrives, and a dead encoder does not make the
/// angle run away.
const PHI_COAST_STEPS: u16 = 50;
/// Largest |coupling correction| passed on; beyond it the correction is limited and flagged.
/// The correction is a fraction of the roll moment (at most about 0.005 on the paper's
/// campaign, whose |C_l| stays below 0.06); far outside the fitted inputs (clamped garbage, a
/// Cmu ten times the largest jet) the cubic terms would otherwise reach C_l of several hundred.
const COUPLING_LIMIT: f32 = 0.05;

/// The measurements of one step. Any value may be NaN (not measured this step).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Input {
    /// Roll angle, deg (positive starboard wing down).
    pub phi_deg: f32,
    /// Angle of attack, deg.
    pub alpha_deg: f32,
    /// Momentum coefficient of the port jet.
    pub cmu_port: f32,
    /// Momentum coefficient of the starboard jet.
    pub cmu_stbd: f32,
    /// Pressure coefficients `cp01`..`cp12`.
    pub cp: [f32; N_TAPS],
}

/// The estimates of one step.
///
/// `repr(C)`: the C interface writes it straight into C's `rollest_output`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Output {
    /// `C_l,roll` of the eGK alone.
    pub cl_egk: f32,
    /// `C_l,roll` of the pressure path alone.
    pub cl_pressure: f32,
    /// `C_l,roll`: the fused disturbance estimate, within the envelope's disturbance range
    /// with its margin (limited and flagged [`Health::ESTIMATE_LIMITED`] otherwise).
    pub cl_roll: f32,
    /// `C_l,AFC` of the port jet.
    pub cl_afc_port: f32,
    /// `C_l,AFC` of the starboard jet.
    pub cl_afc_stbd: f32,
    /// `C_l,AFC = port + starboard`.
    pub cl_afc: f32,
    /// Linear superposition `C_l,roll + C_l,AFC`, within the envelope's total range with its
    /// margin (limited and flagged otherwise).
    pub cl_linear: f32,
    /// The coupling operator's correction.
    pub coupling: f32,
    /// `C_l` with the coupling operator: `C_l,linear + coupling`, within the envelope's total
    /// range with its margin (limited and flagged otherwise; the sum then no longer holds).
    pub cl: f32,
    /// Filtered roll rate, rad/s.
    pub phi_dot_rad_s: f32,
    /// What was missing, rejected, held or reset.
    pub health: Health,
}

impl Output {
    /// Names of [`Output::estimates`], in order.
    pub const ESTIMATE_NAMES: [&'static str; 10] = [
        "cl_egk",
        "cl_pressure",
        "cl_roll",
        "cl_afc_port",
        "cl_afc_stbd",
        "cl_afc",
        "cl_linear",
        "coupling",
        "cl",
        "phi_dot_rad_s",
    ];

    /// Every estimate of the step, in the order of [`Output::ESTIMATE_NAMES`] (the order of
    /// replay files and firmware output records).
    #[must_use]
    pub const fn estimates(&self) -> [f32; 10] {
        [
            self.cl_egk,
            self.cl_pressure,
            self.cl_roll,
            self.cl_afc_port,
            self.cl_afc_stbd,
            self.cl_afc,
            self.cl_linear,
            self.coupling,
            self.cl,
            self.phi_dot_rad_s,
        ]
    }
}

/// Inputs after validation: finite and in range.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Held {
    phi_deg: f32,
    alpha_deg: f32,
    cmu: [f32; 2],
}

/// The estimator: its coefficient tables (borrowed, so that const tables stay in flash), how it
/// evaluates their sparse models (`E`: from the tables, or the built-in set's generated code)
/// and the state of every stage. It lives in a `static` on the target: its constructors are
/// `const`, and the size is fixed at compile time.
#[derive(Debug, Clone)]
pub struct Estimator<'a, E: SparseEval = Interpreted> {
    set: &'a CoefficientSet,
    eval: E,
    held: Held,
    rates: RateEstimator,
    egk: Egk,
    pressure: PressureFilter,
    fusion: Fusion,
    plants: [Plant; 2],
    last_cmu_total: f32,
    /// `1 / dt`, Hz.
    rate_hz: f32,
    /// Consecutive steps without a roll angle (saturating).
    phi_missing_steps: u16,
    /// The controller's demands noted after each step.
    demands: DemandHistory,
    /// The envelope with its margin, `[low, high]`: of `C_l,roll`, and of `C_l,linear` and `C_l`.
    bounds: [[f32; 2]; 2],
}

impl<'a> Estimator<'a> {
    /// A fresh estimator over the given tables (validate a loaded set with
    /// [`crate::blob::validate`] first; the step stays panic-free with any tables).
    #[must_use]
    pub const fn new(set: &'a CoefficientSet) -> Self {
        Self::with(set, Interpreted)
    }
}

impl Estimator<'static, CompiledDefault> {
    /// A fresh estimator over the built-in tables ([`crate::coeffs::BUILT_IN`]) whose sparse
    /// models run as generated code: the same outputs, bit for bit, as
    /// `Estimator::new(&BUILT_IN)`, in fewer instructions.
    #[must_use]
    pub const fn built_in() -> Self {
        Self::with(&crate::coeffs::BUILT_IN, CompiledDefault::NEW)
    }
}

impl<'a, E: SparseEval> Estimator<'a, E> {
    const fn with(set: &'a CoefficientSet, eval: E) -> Self {
        Self {
            set,
            eval,
            held: Held { phi_deg: 0.0, alpha_deg: set.alpha_schedule_deg[0], cmu: [0.0; 2] },
            rates: RateEstimator::new(),
            egk: Egk::new(),
            pressure: PressureFilter::new(&set.pressure),
            fusion: Fusion::new(),
            plants: [Plant::new(); 2],
            last_cmu_total: 0.0,
            rate_hz: 1.0 / set.dt_s,
            phi_missing_steps: 0,
            demands: DemandHistory::new(),
            bounds: [Envelope::with_margin(set.envelope.cl_roll), Envelope::with_margin(set.envelope.cl)],
        }
    }

    /// The coefficient tables.
    #[must_use]
    pub const fn coefficients(&self) -> &'a CoefficientSet {
        self.set
    }

    /// How the sparse models are evaluated (pass it to [`crate::controller::Controller::step_with`]).
    #[must_use]
    pub const fn evaluator(&self) -> E {
        self.eval
    }

    /// The plants' states (for the controller blocks).
    #[must_use]
    pub const fn plants(&self) -> &[Plant; 2] {
        &self.plants
    }

    /// Returns to the state of a fresh estimator over the same tables (no demand noted).
    pub fn reset(&mut self) {
        *self = Self::with(self.set, self.eval);
    }

    /// Notes the controller's Cmu demand `[port, starboard]` of this step: call it once per
    /// step, after [`Estimator::step`] and the controller, with what goes to the valves (a host
    /// replay passes the recorded command). From the first call on, a step whose measured Cmu is
    /// missing runs the plant on the jet's Cmu predicted from the demands through the fitted
    /// [`crate::coeffs::ActuatorResponse`] (flag [`Health::CMU_FROM_DEMAND`]); without any
    /// call, the last measured Cmu is held ([`Health::CMU_HELD`]). The demand is limited to the
    /// accepted Cmu range; a non-finite one repeats the jet's previous demand. It changes no
    /// output while the Cmu is measured. Constant time (two stores); never panics.
    pub fn note_demand(&mut self, cmu_demand: [f32; 2]) {
        self.demands.note(cmu_demand, CMU_LIMIT);
    }

    /// One fixed step. Never panics; a missing or non-finite input is held and flagged, and no
    /// NaN or infinity reaches the state.
    pub fn step(&mut self, input: &Input) -> Output {
        let set = self.set;
        let mut health = Health::default();
        self.validate(input, &mut health);
        let phi_rad = self.held.phi_deg.to_radians();
        let alpha_rad = self.held.alpha_deg.to_radians();
        let rates = limit_rates(self.rates.step(&set.rate_filter, self.rate_hz, phi_rad), &mut health);
        let (cl_egk, egk_reset) = self.egk.step(set, &self.egk_input(phi_rad, &rates));
        let pressure_inputs = self.pressure_inputs(phi_rad, &rates);
        let at = self.egk.schedule_position();
        let pressure = self.pressure.step(&set.pressure, at, &pressure_inputs, &input.cp, &mut health);
        if !pressure.measured {
            health.set(Health::PRESSURE_UNUSED);
        }
        let (cl_roll, fusion_reset) = self.fusion.step(&set.fusion, cl_egk, pressure.measured.then_some(pressure.cl));
        let (cl_afc_port, port_reset) =
            self.plants[0].step_with(self.eval, ModelId::PlantPort, &set.plant[0], self.held.cmu[0], alpha_rad);
        let (cl_afc_stbd, stbd_reset) =
            self.plants[1].step_with(self.eval, ModelId::PlantStarboard, &set.plant[1], self.held.cmu[1], alpha_rad);
        if egk_reset || fusion_reset || port_reset || stbd_reset {
            health.set(Health::STATE_RESET);
        }
        let cl_afc = cl_afc_port + cl_afc_stbd;
        let cmu_total = self.held.cmu[0] + self.held.cmu[1];
        let coupling_input = CouplingInput {
            cl_roll,
            cl_afc,
            alpha_rad,
            cmu: cmu_total,
            dcmu: cmu_total - self.last_cmu_total,
            phi_rad,
            phi_dot_rad_s: rates.phi_dot_rad_s,
        };
        self.last_cmu_total = cmu_total;
        let coupling = match correction_with(self.eval, &set.coupling, &coupling_input) {
            Some(value) if value.abs() <= COUPLING_LIMIT => value,
            Some(value) => {
                health.set(Health::ESTIMATE_LIMITED);
                value.clamp(-COUPLING_LIMIT, COUPLING_LIMIT)
            }
            None => {
                health.set(Health::STATE_RESET);
                0.0
            }
        };
        let [roll_bounds, total_bounds] = self.bounds;
        let cl_roll = limit_to(cl_roll, roll_bounds, &mut health);
        let cl_linear = limit_to(cl_roll + cl_afc, total_bounds, &mut health);
        Output {
            cl_egk,
            cl_pressure: pressure.cl,
            cl_roll,
            cl_afc_port,
            cl_afc_stbd,
            cl_afc,
            cl_linear,
            coupling,
            cl: limit_to(cl_linear + coupling, total_bounds, &mut health),
            phi_dot_rad_s: rates.phi_dot_rad_s,
            health,
        }
    }

    /// Holds the last valid value of a missing input (a missing roll angle is first extrapolated
    /// for [`PHI_COAST_STEPS`] steps) and clamps out-of-range ones.
    fn validate(&mut self, input: &Input, health: &mut Health) {
        if input.phi_deg.is_finite() {
            self.phi_missing_steps = 0;
        } else {
            self.phi_missing_steps = self.phi_missing_steps.saturating_add(1);
            if self.phi_missing_steps <= PHI_COAST_STEPS {
                let step_deg = self.rates.phi_dot_rad_s().to_degrees() * self.set.dt_s;
                let coasted = self.held.phi_deg + step_deg;
                if coasted.is_finite() {
                    self.held.phi_deg = coasted.clamp(-PHI_LIMIT_DEG, PHI_LIMIT_DEG);
                }
            }
        }
        let mut take = |value: f32, limit: f32, low: f32, held: &mut f32, missing_flag: u16| {
            if !value.is_finite() {
                health.set(missing_flag);
            } else if value < low || value > limit {
                health.set(Health::INPUT_CLAMPED);
                *held = value.clamp(low, limit);
            } else {
                *held = value;
            }
        };
        take(input.phi_deg, PHI_LIMIT_DEG, -PHI_LIMIT_DEG, &mut self.held.phi_deg, Health::PHI_HELD);
        take(input.alpha_deg, ALPHA_LIMIT_DEG, -ALPHA_LIMIT_DEG, &mut self.held.alpha_deg, Health::ALPHA_HELD);
        take(input.cmu_port, CMU_LIMIT, 0.0, &mut self.held.cmu[0], Health::CMU_HELD);
        take(input.cmu_stbd, CMU_LIMIT, 0.0, &mut self.held.cmu[1], Health::CMU_HELD);
        self.cmu_from_demand([input.cmu_port, input.cmu_stbd], health);
    }

    /// A missing Cmu, once a demand was noted: the jet's Cmu predicted from its previous one
    /// (measured or predicted) and the demands, limited to the accepted range, in place of the
    /// held value, flagged [`Health::CMU_FROM_DEMAND`]; [`Health::CMU_HELD`] stays only for a
    /// jet whose prediction is not finite (tables no validation would pass), which keeps its
    /// held value.
    fn cmu_from_demand(&mut self, measured: [f32; 2], health: &mut Health) {
        if !self.demands.noted() || measured.iter().all(|cmu| cmu.is_finite()) {
            return;
        }
        let (mut any_predicted, mut any_held) = (false, false);
        for (side, (held, response)) in self.held.cmu.iter_mut().zip(&self.set.actuator).enumerate() {
            if measured.get(side).is_some_and(|cmu| cmu.is_finite()) {
                continue;
            }
            let predicted = self.demands.predict(response, side, *held);
            if predicted.is_finite() {
                *held = crate::min_num(crate::max_num(predicted, 0.0), CMU_LIMIT);
                any_predicted = true;
            } else {
                any_held = true;
            }
        }
        if any_predicted {
            health.set(Health::CMU_FROM_DEMAND);
        }
        if !any_held {
            health.flags &= !Health::CMU_HELD;
        }
    }

    fn egk_input(&self, phi_rad: f32, rates: &RollRates) -> EgkInput {
        EgkInput {
            phi_rad,
            phi_dot_rad_s: rates.phi_dot_rad_s,
            phi_ddot_rad_s2: rates.phi_ddot_rad_s2,
            alpha_deg: self.held.alpha_deg,
        }
    }

    /// `[phi_rad, phi_dot_rad_s, cmu_port, cmu_stbd, 1]`.
    fn pressure_inputs(&self, phi_rad: f32, rates: &RollRates) -> [f32; N_PRESSURE_INPUTS] {
        [phi_rad, rates.phi_dot_rad_s, self.held.cmu[0], self.held.cmu[1], 1.0]
    }
}

/// `value` within `bounds` (`[low, high]`); outside them (or NaN) it is limited to the nearer
/// bound and [`Health::ESTIMATE_LIMITED`] is set. A value within them passes bit for bit.
fn limit_to(value: f32, bounds: [f32; 2], health: &mut Health) -> f32 {
    let [low, high] = bounds;
    if value >= low && value <= high {
        return value;
    }
    health.set(Health::ESTIMATE_LIMITED);
    crate::min_num(crate::max_num(value, low), high)
}

/// Limits the roll rate and acceleration passed on to [`PHI_DOT_LIMIT_RAD_S`] and
/// [`PHI_DDOT_LIMIT_RAD_S2`] (the filters' own states are not touched, so they decay from the
/// spike as they would).
fn limit_rates(rates: RollRates, health: &mut Health) -> RollRates {
    if rates.phi_dot_rad_s.abs() <= PHI_DOT_LIMIT_RAD_S && rates.phi_ddot_rad_s2.abs() <= PHI_DDOT_LIMIT_RAD_S2 {
        return rates;
    }
    health.set(Health::INPUT_CLAMPED);
    RollRates {
        phi_dot_rad_s: rates.phi_dot_rad_s.clamp(-PHI_DOT_LIMIT_RAD_S, PHI_DOT_LIMIT_RAD_S),
        phi_ddot_rad_s2: rates.phi_ddot_rad_s2.clamp(-PHI_DDOT_LIMIT_RAD_S2, PHI_DDOT_LIMIT_RAD_S2),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coeffs::ActuatorResponse;
    use crate::prior::full_size_fixture;
    use proptest::prelude::*;

    /// Steps after which an estimator that saw garbage agrees with a fresh one fed the same
    /// normal input: the slowest mode is the eGK lag (tau1 = 0.15 s, 20 time constants).
    const RECOVERY_STEPS: usize = 3000;

    fn normal_input(step: usize) -> Input {
        let t = step as f32 * 1e-3;
        let phi_deg = 20.0 * libm::sinf(core::f32::consts::TAU * 0.8 * t);
        let cmu_port = if (step / 700).is_multiple_of(2) { 0.0 } else { 0.006 };
        let cp = core::array::from_fn(|tap| -0.3 + 0.02 * tap as f32 + 0.01 * libm::sinf(t * (tap as f32 + 1.0)));
        Input { phi_deg, alpha_deg: 10.0, cmu_port, cmu_stbd: 0.0, cp }
    }

    fn wild_value() -> impl Strategy<Value = f32> {
        prop_oneof![
            Just(f32::NAN),
            Just(f32::INFINITY),
            Just(f32::NEG_INFINITY),
            Just(1e30f32),
            Just(-1e30f32),
            Just(f32::MAX),
            Just(f32::MIN_POSITIVE),
            -100.0f32..100.0,
            any::<f32>(),
        ]
    }

    fn wild_input() -> impl Strategy<Value = Input> {
        (wild_value(), wild_value(), wild_value(), wild_value(), proptest::array::uniform12(wild_value())).prop_map(
            |(phi_deg, alpha_deg, cmu_port, cmu_stbd, cp)| Input { phi_deg, alpha_deg, cmu_port, cmu_stbd, cp },
        )
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Arbitrary input never panics and never leaves a non-finite output; normal input
        /// afterwards brings every estimate back to a fresh estimator's within
        /// `RECOVERY_STEPS` steps (3 s at 1 kHz), to 1e-4 in C_l.
        #[test]
        fn garbage_never_panics_and_the_estimate_recovers(garbage in proptest::collection::vec(wild_input(), 1..200)) {
            let set = full_size_fixture();
            let mut battered = Estimator::new(&set);
            for input in &garbage {
                let output = battered.step(input);
                prop_assert!(output.estimates().iter().all(|value| value.is_finite()), "{output:?}");
            }
            let mut fresh = Estimator::new(&set);
            for step in 0..RECOVERY_STEPS {
                let input = normal_input(step);
                let (a, b) = (battered.step(&input), fresh.step(&input));
                prop_assert!(a.estimates().iter().all(|value| value.is_finite()));
                if step + 1 == RECOVERY_STEPS {
                    for (x, y) in a.estimates().iter().zip(b.estimates()) {
                        prop_assert!((x - y).abs() < 1e-4, "{a:?}\nvs\n{b:?}");
                    }
                }
            }
        }
    }

    /// The built-in estimator (generated sparse code) and an interpreting one over the same
    /// tables agree bit for bit, step by step, with alpha moving, both jets blowing in turn,
    /// dropouts and a garbage sample in between.
    #[test]
    fn built_in_code_and_interpreted_tables_agree_bit_for_bit() {
        let mut compiled = Estimator::built_in();
        let mut interpreted = Estimator::new(&crate::coeffs::BUILT_IN);
        for step in 0..6000 {
            let mut input = normal_input(step);
            input.alpha_deg = 12.0 + 9.0 * libm::sinf(step as f32 * 1e-3);
            input.cmu_stbd = if (step / 1100).is_multiple_of(3) { 0.004 } else { 0.0 };
            if step % 997 == 0 {
                input.cp[step % N_TAPS] = f32::NAN;
            }
            if step == 4321 {
                input.phi_deg = f32::INFINITY;
                input.cmu_port = 1e30;
            }
            let (a, b) = (compiled.step(&input), interpreted.step(&input));
            let bits = |output: &Output| output.estimates().map(f32::to_bits);
            assert_eq!(bits(&a), bits(&b), "step {step}");
            assert_eq!(a.health, b.health, "step {step}");
        }
    }

    #[test]
    fn missing_inputs_are_held_and_flagged() {
        let set = full_size_fixture();
        let mut estimator = Estimator::new(&set);
        let _ = estimator.step(&normal_input(0));
        let mut input = normal_input(1);
        input.phi_deg = f32::NAN;
        input.alpha_deg = f32::INFINITY;
        input.cmu_port = f32::NAN;
        input.cp[4] = f32::NAN;
        let output = estimator.step(&input);
        assert!(output.health.has(Health::PHI_HELD));
        assert!(output.health.has(Health::ALPHA_HELD));
        assert!(output.health.has(Health::CMU_HELD));
        assert_eq!(output.health.cp_missing, 1 << 4);
        let mut clamped = normal_input(2);
        clamped.phi_deg = 500.0;
        assert!(estimator.step(&clamped).health.has(Health::INPUT_CLAMPED));
    }

    #[test]
    fn coupling_is_zero_without_blowing_or_without_roll() {
        let set = full_size_fixture();
        let mut estimator = Estimator::new(&set);
        for step in 0..200 {
            let mut input = normal_input(step);
            input.cmu_port = 0.0;
            assert_eq!(estimator.step(&input).coupling, 0.0, "no blowing: the gated operator is exactly zero");
        }
        let mut estimator = Estimator::new(&set);
        for step in 0..200 {
            let mut input = normal_input(step + 700);
            input.phi_deg = 0.0;
            assert_eq!(estimator.step(&input).coupling, 0.0, "no roll: the gated operator is exactly zero");
        }
    }

    /// The fixture with an envelope of +-`half_width` for both ranges.
    fn fixture_with_envelope(half_width: f32) -> CoefficientSet {
        let mut set = full_size_fixture();
        set.envelope = Envelope { cl_roll: [-half_width, half_width], cl: [-half_width, half_width] };
        set
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Under garbage every final estimate stays within the envelope with its margin, every
        /// step at which an unbounded estimator (same state, an envelope far wider) leaves it is
        /// flagged, and an unflagged step passes every estimate bit for bit.
        #[test]
        fn garbage_never_leaves_the_envelope_and_every_limited_step_is_flagged(
            garbage in proptest::collection::vec(wild_input(), 1..300),
        ) {
            let (narrow_set, wide_set) = (fixture_with_envelope(0.02), fixture_with_envelope(1.0));
            let (mut narrow, mut wide) = (Estimator::new(&narrow_set), Estimator::new(&wide_set));
            let [low, high] = Envelope::with_margin(narrow_set.envelope.cl);
            for (step, input) in (0..400).map(normal_input).chain(garbage.iter().copied()).enumerate() {
                let (bounded, free) = (narrow.step(&input), wide.step(&input));
                let flagged = bounded.health.has(Health::ESTIMATE_LIMITED);
                for (value, unbounded) in
                    [(bounded.cl_roll, free.cl_roll), (bounded.cl_linear, free.cl_linear), (bounded.cl, free.cl)]
                {
                    prop_assert!((low..=high).contains(&value), "step {step}: {value} beyond [{low}, {high}]");
                    prop_assert!(flagged || (low..=high).contains(&unbounded), "step {step}: {unbounded} not flagged");
                    prop_assert!(flagged || value.to_bits() == unbounded.to_bits(), "step {step}: changed unflagged");
                }
            }
        }
    }

    /// The tables' actuator response as the "true" valve: a demand sequence of holds, and the
    /// Cmu it makes (exactly the response, so the prediction can match it).
    fn valve_run(set: &CoefficientSet, steps: usize) -> (Vec<f32>, Vec<f32>) {
        let response = set.actuator[0];
        let demands: Vec<f32> = (0..steps).map(|step| [0.0, 0.006, 0.002, 0.009][(step / 150) % 4]).collect();
        let mut cmu = vec![0.0f32; steps];
        for step in 1..steps {
            let delayed = step.checked_sub(1 + usize::from(response.delay_steps)).map_or(0.0, |idx| demands[idx]);
            cmu[step] = response.pole * cmu[step - 1] + (1.0 - response.pole) * response.gain * delayed;
        }
        (demands, cmu)
    }

    /// With the blowing measurement lost after 1 s, the plant runs on the Cmu predicted from the
    /// demands and follows the plant of an estimator that still measures it; holding the last Cmu
    /// (no demand noted) does not.
    #[test]
    fn a_missing_cmu_with_demands_tracks_the_true_cmu_path() {
        let mut set = full_size_fixture();
        // The prior's plant: a moment of 0.01 at the largest Cmu (the fixture's is tiny).
        set.plant = crate::prior::PRIOR.plant;
        set.actuator[0] = ActuatorResponse { delay_steps: 5, pole: 0.72, gain: 1.0 };
        let (demands, cmu) = valve_run(&set, 4000);
        let (mut measured, mut predicted, mut held) =
            (Estimator::new(&set), Estimator::new(&set), Estimator::new(&set));
        let (mut worst_predicted, mut worst_held) = (0.0f32, 0.0f32);
        for step in 0..demands.len() {
            let mut input = normal_input(step);
            input.cmu_port = cmu[step];
            let truth = measured.step(&input);
            if step >= 1000 {
                input.cmu_port = f32::NAN;
            }
            let (with_demand, without) = (predicted.step(&input), held.step(&input));
            predicted.note_demand([demands[step], 0.0]);
            measured.note_demand([demands[step], 0.0]);
            if step >= 1000 {
                assert!(with_demand.health.has(Health::CMU_FROM_DEMAND) && !with_demand.health.has(Health::CMU_HELD));
                assert!(without.health.has(Health::CMU_HELD) && !without.health.has(Health::CMU_FROM_DEMAND));
                worst_predicted = worst_predicted.max((with_demand.cl_afc_port - truth.cl_afc_port).abs());
                worst_held = worst_held.max((without.cl_afc_port - truth.cl_afc_port).abs());
            }
        }
        assert!(worst_predicted < 1e-6, "predicted: {worst_predicted:e}");
        assert!(worst_held > 1e-3, "held: {worst_held:e}");
    }

    /// The demand changes nothing while the Cmu is measured, and without any demand a missing
    /// Cmu is held exactly as before the actuator response existed.
    #[test]
    fn demands_change_nothing_while_cmu_is_measured_and_without_them_cmu_is_held() {
        let mut set = full_size_fixture();
        set.actuator[0] = ActuatorResponse { delay_steps: 3, pole: 0.5, gain: 1.2 };
        let (mut noting, mut plain) = (Estimator::new(&set), Estimator::new(&set));
        for step in 0..3000 {
            let input = normal_input(step);
            let (a, b) = (noting.step(&input), plain.step(&input));
            noting.note_demand([0.001 * (step % 9) as f32, f32::NAN]);
            assert_eq!(a.estimates().map(f32::to_bits), b.estimates().map(f32::to_bits), "step {step}");
            assert_eq!(a.health, b.health);
        }
        // No demand: the held Cmu is the last measured one, as if it were still measured.
        let (mut plain, mut last_measured) = (Estimator::new(&set), Estimator::new(&set));
        for step in 0..2000 {
            let mut input = normal_input(step);
            let mut reference = input;
            if step >= 800 {
                input.cmu_port = f32::NAN;
                reference.cmu_port = normal_input(799).cmu_port;
            }
            let (a, b) = (plain.step(&input), last_measured.step(&reference));
            assert_eq!(a.estimates().map(f32::to_bits), b.estimates().map(f32::to_bits), "step {step}");
        }
    }

    #[test]
    fn estimator_fits_in_a_static() {
        static SET: CoefficientSet = crate::prior::PRIOR;
        static ESTIMATOR: Estimator<'static> = Estimator::new(&SET);
        assert_eq!(ESTIMATOR.coefficients().dt_s, 1e-3);
    }
}

//! What makes a coefficient set usable by the estimator, whether compiled in, loaded from a
//! blob or fitted: the checks [`validate`] makes, each failure naming its field.

use core::fmt;

use crate::coeffs::{
    ActuatorResponse, CoefficientSet, ControllerParams, DEMAND_SLOTS, EgkParams, Envelope, FusionParams, MAX_TERMS,
    MAX_VARS, N_ALPHA, PRESSURE_RANK, PlantParams, PressureModel, RateFilter, SCHEMA_VERSION,
};
use crate::sparse::{Monomial, SparseModel, Term};

/// A coefficient set the estimator cannot use; the text names the first offending field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct InvalidSet(pub &'static str);

impl fmt::Display for InvalidSet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "invalid coefficient set: {}", self.0)
    }
}

impl core::error::Error for InvalidSet {}

/// Checks that a coefficient set is usable by the estimator.
///
/// The set must have this build's `schema_version`; every f32 in it (used or not, including the
/// sparse coefficients and thresholds) must be finite; `dt_s > 0`; `1 <= n_alpha <= N_ALPHA`
/// with the used breakpoints strictly ascending; the used eGK entries need `tau1_s > 0` and
/// `tau2_s >= 0`; `pressure.rank <= PRESSURE_RANK`, `pressure.gate_sigma > 0` and the
/// constants the pressure filter derives from its tables are finite; every sparse model has
/// `n_terms <= MAX_TERMS`; `controller.cmu_max > 0`; each actuator response has
/// `delay_steps < DEMAND_SLOTS`, `pole` in `[0, 1)` and `gain` in `(0, 10]`; each range of the
/// envelope is ordered (`low <= high`) within `[-ENVELOPE_LIMIT, ENVELOPE_LIMIT]`.
///
/// # Errors
///
/// [`InvalidSet`] naming the first offending field.
pub fn validate(set: &CoefficientSet) -> Result<(), InvalidSet> {
    ensure(set.schema_version == SCHEMA_VERSION, "schema_version differs from this build's SCHEMA_VERSION")?;
    check_all_finite(set)?;
    ensure(set.dt_s > 0.0, "dt_s must be > 0")?;

    let n_alpha = usize::from(set.n_alpha);
    ensure((1..=N_ALPHA).contains(&n_alpha), "n_alpha must be in 1..=N_ALPHA")?;
    let used_alpha = set.alpha_schedule_deg.get(..n_alpha).unwrap_or(&[]);
    ensure(
        used_alpha.windows(2).all(|pair| matches!(pair, [lower, upper] if lower < upper)),
        "alpha_schedule_deg must be strictly ascending over the n_alpha used breakpoints",
    )?;
    for params in set.egk.iter().take(n_alpha) {
        ensure(params.tau1_s > 0.0, "egk.tau1_s must be > 0")?;
        ensure(params.tau2_s >= 0.0, "egk.tau2_s must be >= 0")?;
    }

    ensure(usize::from(set.pressure.rank) <= PRESSURE_RANK, "pressure.rank must be <= PRESSURE_RANK")?;
    ensure(modes_beyond_rank_are_zero(&set.pressure), "pressure modes beyond rank must be zero")?;
    ensure(set.pressure.gate_sigma > 0.0, "pressure.gate_sigma must be > 0")?;
    // Finite tables can still overflow in the constants the filter derives from them (found by
    // `cargo xtask fuzz --target blob`: a weight of 1e30 times a mode shape of 1e23).
    ensure(
        crate::pressure::PressureFilter::new(&set.pressure).derived_constants_are_finite(),
        "pressure tables overflow: the roll-moment map, its constant or a gate is not finite",
    )?;

    let [port, starboard] = &set.plant;
    ensure((0.0..1.0).contains(&port.slow_pole), "plant[0].slow_pole must be in [0, 1)")?;
    ensure((0.0..1.0).contains(&starboard.slow_pole), "plant[1].slow_pole must be in [0, 1)")?;
    ensure(port.cmu_max > 0.0, "plant[0].cmu_max must be > 0")?;
    ensure(starboard.cmu_max > 0.0, "plant[1].cmu_max must be > 0")?;
    let [port, starboard] = [&port.model, &starboard.model];
    ensure(usize::from(port.n_terms) <= MAX_TERMS, "plant[0].n_terms must be <= MAX_TERMS")?;
    ensure(usize::from(starboard.n_terms) <= MAX_TERMS, "plant[1].n_terms must be <= MAX_TERMS")?;
    ensure(usize::from(set.coupling.n_terms) <= MAX_TERMS, "coupling.n_terms must be <= MAX_TERMS")?;
    ensure(factors_in_table(port), "plant[0] factors must be variables or ONE_FACTOR, ascending")?;
    ensure(factors_in_table(starboard), "plant[1] factors must be variables or ONE_FACTOR, ascending")?;
    ensure(factors_in_table(&set.coupling), "coupling factors must be variables or ONE_FACTOR, ascending")?;

    ensure(set.controller.cmu_max > 0.0, "controller.cmu_max must be > 0")?;

    for (response, delay_what, pole_what, gain_what) in [
        (
            &set.actuator[0],
            "actuator[0].delay_steps must be < DEMAND_SLOTS",
            "actuator[0].pole must be in [0, 1)",
            "actuator[0].gain must be in (0, 10]",
        ),
        (
            &set.actuator[1],
            "actuator[1].delay_steps must be < DEMAND_SLOTS",
            "actuator[1].pole must be in [0, 1)",
            "actuator[1].gain must be in (0, 10]",
        ),
    ] {
        ensure(usize::from(response.delay_steps) < DEMAND_SLOTS, delay_what)?;
        ensure((0.0..1.0).contains(&response.pole), pole_what)?;
        ensure(response.gain > 0.0 && response.gain <= ACTUATOR_GAIN_LIMIT, gain_what)?;
    }
    ensure(envelope_range_ok(set.envelope.cl_roll), "envelope.cl_roll must be ordered within +-ENVELOPE_LIMIT")?;
    ensure(envelope_range_ok(set.envelope.cl), "envelope.cl must be ordered within +-ENVELOPE_LIMIT")
}

/// Largest actuator gain accepted: a jet that blows ten times its demand is a broken fit, not a
/// valve.
const ACTUATOR_GAIN_LIMIT: f32 = 10.0;

/// Largest |bound| of an envelope range: a roll moment coefficient of 1 is a hundred times the
/// authority of a trailing-edge jet and about 17 times the largest moment of the paper's wing
/// (0.06), and keeps the margin's arithmetic far from overflow.
pub const ENVELOPE_LIMIT: f32 = 1.0;

/// An envelope range `[low, high]` is ordered and within [`ENVELOPE_LIMIT`].
fn envelope_range_ok(range: [f32; 2]) -> bool {
    let [low, high] = range;
    -ENVELOPE_LIMIT <= low && low <= high && high <= ENVELOPE_LIMIT
}

/// The estimator runs its pressure loops over the full size, so modes past `rank` must be zero
/// rows and columns of `A`, `B`, `C` and `K`.
fn modes_beyond_rank_are_zero(model: &PressureModel) -> bool {
    let rank = usize::from(model.rank);
    let unused = |row: &[f32]| row.get(rank..).unwrap_or(&[]).iter().all(|&value| value == 0.0);
    model.a.iter().all(|row| unused(row))
        && model.a.iter().skip(rank).all(|row| row.iter().all(|&value| value == 0.0))
        && model.b.iter().skip(rank).all(|row| row.iter().all(|&value| value == 0.0))
        && model.c.iter().all(|row| unused(row))
        && model.gain.iter().skip(rank).all(|row| row.iter().all(|&value| value == 0.0))
}

/// Every factor of every term (used or not) is a variable or the padding
/// [`crate::sparse::ONE_FACTOR`], in the canonical ascending order: the estimator's factor
/// table has no other entries, and equal monomials must compare equal.
fn factors_in_table(model: &SparseModel) -> bool {
    model.terms.iter().all(|term| term.monomial.is_canonical(MAX_VARS))
}

/// `Ok` when `ok`, else [`InvalidSet`] with `what`.
fn ensure(ok: bool, what: &'static str) -> Result<(), InvalidSet> {
    if ok { Ok(()) } else { Err(InvalidSet(what)) }
}

/// [`InvalidSet`] with `what` unless every value is finite.
fn all_finite(values: &[f32], what: &'static str) -> Result<(), InvalidSet> {
    ensure(values.iter().all(|value| value.is_finite()), what)
}

/// Walks every f32 of the set. The destructuring is exhaustive on purpose: a new field does not
/// compile until it is checked here (and described in [`SCHEMA`]).
fn check_all_finite(set: &CoefficientSet) -> Result<(), InvalidSet> {
    let CoefficientSet {
        schema_version: _,
        dt_s,
        rate_filter,
        alpha_schedule_deg,
        n_alpha: _,
        egk,
        pressure,
        fusion,
        plant,
        coupling,
        controller,
        actuator,
        envelope,
    } = set;
    all_finite(&[*dt_s], "dt_s is not finite")?;

    let RateFilter { rate_pole, accel_pole } = rate_filter;
    all_finite(&[*rate_pole], "rate_filter.rate_pole is not finite")?;
    all_finite(&[*accel_pole], "rate_filter.accel_pole is not finite")?;

    all_finite(alpha_schedule_deg, "alpha_schedule_deg is not finite")?;

    for params in egk {
        let EgkParams {
            tau1_s,
            tau2_s,
            breakdown_deg,
            steepness_per_deg,
            sideslip_gain,
            clbeta_per_rad,
            clp,
            clpdot,
            clpp,
            vortex_gain,
            bias,
            half_span_time_s,
        } = params;
        all_finite(&[*tau1_s], "egk.tau1_s is not finite")?;
        all_finite(&[*tau2_s], "egk.tau2_s is not finite")?;
        all_finite(&[*breakdown_deg], "egk.breakdown_deg is not finite")?;
        all_finite(&[*steepness_per_deg], "egk.steepness_per_deg is not finite")?;
        all_finite(&[*sideslip_gain], "egk.sideslip_gain is not finite")?;
        all_finite(&[*clbeta_per_rad], "egk.clbeta_per_rad is not finite")?;
        all_finite(&[*clp], "egk.clp is not finite")?;
        all_finite(&[*clpdot], "egk.clpdot is not finite")?;
        all_finite(&[*clpp], "egk.clpp is not finite")?;
        all_finite(&[*vortex_gain], "egk.vortex_gain is not finite")?;
        all_finite(&[*bias], "egk.bias is not finite")?;
        all_finite(&[*half_span_time_s], "egk.half_span_time_s is not finite")?;
    }

    let PressureModel {
        rank: _,
        a,
        b,
        c,
        cp_mean,
        gain,
        innovation_std,
        gate_sigma,
        isolate_after: _,
        settle_steps: _,
        cl_weights,
        cl_offset,
    } = pressure;
    all_finite(a.as_flattened(), "pressure.a is not finite")?;
    all_finite(b.as_flattened(), "pressure.b is not finite")?;
    all_finite(c.as_flattened(), "pressure.c is not finite")?;
    all_finite(cp_mean, "pressure.cp_mean is not finite")?;
    all_finite(gain.as_flattened(), "pressure.gain is not finite")?;
    all_finite(innovation_std, "pressure.innovation_std is not finite")?;
    all_finite(&[*gate_sigma], "pressure.gate_sigma is not finite")?;
    all_finite(cl_weights.as_flattened(), "pressure.cl_weights is not finite")?;
    all_finite(cl_offset, "pressure.cl_offset is not finite")?;

    let FusionParams { rho, gain } = fusion;
    all_finite(&[*rho], "fusion.rho is not finite")?;
    all_finite(&[*gain], "fusion.gain is not finite")?;

    let [port, starboard] = plant;
    let PlantParams { slow_pole: port_pole, cmu_max: port_cmu_max, model: port } = port;
    let PlantParams { slow_pole: starboard_pole, cmu_max: starboard_cmu_max, model: starboard } = starboard;
    all_finite(&[*port_pole], "plant[0].slow_pole is not finite")?;
    all_finite(&[*starboard_pole], "plant[1].slow_pole is not finite")?;
    all_finite(&[*port_cmu_max], "plant[0].cmu_max is not finite")?;
    all_finite(&[*starboard_cmu_max], "plant[1].cmu_max is not finite")?;
    sparse_finite(port, "plant[0].terms.coeff is not finite", "plant[0].gate_threshold is not finite")?;
    sparse_finite(starboard, "plant[1].terms.coeff is not finite", "plant[1].gate_threshold is not finite")?;
    sparse_finite(coupling, "coupling.terms.coeff is not finite", "coupling.gate_threshold is not finite")?;

    let ControllerParams { causality_pole, feedback_kp, feedback_ki, cmu_max, inversion_iterations: _ } = controller;
    all_finite(&[*causality_pole], "controller.causality_pole is not finite")?;
    all_finite(&[*feedback_kp], "controller.feedback_kp is not finite")?;
    all_finite(&[*feedback_ki], "controller.feedback_ki is not finite")?;
    all_finite(&[*cmu_max], "controller.cmu_max is not finite")?;

    for response in actuator {
        let ActuatorResponse { delay_steps: _, pole, gain } = response;
        all_finite(&[*pole], "actuator.pole is not finite")?;
        all_finite(&[*gain], "actuator.gain is not finite")?;
    }
    let Envelope { cl_roll, cl } = envelope;
    all_finite(cl_roll, "envelope.cl_roll is not finite")?;
    all_finite(cl, "envelope.cl is not finite")
}

/// Every f32 of a sparse model: all term coefficients (used or not) and the gate thresholds.
fn sparse_finite(
    model: &SparseModel,
    coeff_what: &'static str,
    threshold_what: &'static str,
) -> Result<(), InvalidSet> {
    let SparseModel { terms, n_terms: _, gate_threshold } = model;
    for term in terms {
        let Term { coeff, monomial } = term;
        let Monomial { factors: _, gate_mask: _ } = monomial;
        all_finite(&[*coeff], coeff_what)?;
    }
    all_finite(gate_threshold, threshold_what)
}

//! The physical prior at the paper's geometry: the fit's prior (`host_tools::fit::prior`, built
//! from physics and the literature and scaled by each dataset's own chord, span and speed)
//! evaluated for the paper's wing at 6.5 m/s, as a complete, valid coefficient set.
//!
//! It is a fixture for tests and the skeleton of a fitted set (whose controller settings are
//! these); the host's fit builds its own prior from the dataset, and a host test keeps the two
//! equal at the paper's geometry. The tables that fly are fitted (`host-tools fit`) and
//! generated (`host-tools codegen`). None of its values is a default of the synthetic tunnel:
//! a prior equal to the tunnel starts a fit on it at its truth.

use crate::coeffs::{
    ActuatorResponse, CoefficientSet, ControllerParams, EgkParams, Envelope, FusionParams, MAX_VARS, N_ALPHA,
    N_PLANT_VARS, N_PRESSURE_INPUTS, N_TAPS, PRESSURE_RANK, PlantParams, PressureModel, RateFilter, SCHEMA_VERSION,
    coupling_var, plant_var,
};
use crate::sparse::{Factor, Monomial, ONE_FACTOR, SparseModel, Term};

/// `b / (2 U)` of the paper's wing (b = 0.287 m) at 6.5 m/s, s.
const HALF_SPAN_TIME_S: f32 = 0.287 / (2.0 * 6.5);

/// The eGK prior at one angle of attack on the paper's wing (c = 0.330 m, b = 0.287 m,
/// S = 0.0474 m^2, U = 6.5 m/s; `host_tools::fit::prior` says where each value comes from):
/// GK time constants at the geometric middles of the published ranges (tau1 = 4.74 c/U,
/// tau2 = 1.58 c/U), the breakdown at mid-chord 25.5 deg with Jategaonkar's 20 per rad, the
/// finite-aspect-ratio roll damping `-K_p / 16` and the slender-wing added inertia
/// `-pi b c / (80 S)`; the sideslip gain, sideslip derivative and vortex gain depend on alpha.
const fn egk_prior(sideslip_gain: f32, clbeta_per_rad: f32, vortex_gain: f32) -> EgkParams {
    EgkParams {
        tau1_s: 0.240_82,
        tau2_s: 0.080_273,
        breakdown_deg: 25.508,
        steepness_per_deg: 0.349_07,
        sideslip_gain,
        clbeta_per_rad,
        clp: -0.146_77,
        clpdot: -0.078_465,
        clpp: 0.0,
        vortex_gain,
        bias: 0.0,
        half_span_time_s: HALF_SPAN_TIME_S,
    }
}

/// The eGK prior at alpha = 0: no sideslip, no lift and no vortex asymmetry by symmetry.
const EGK_PRIOR_0: EgkParams = egk_prior(0.0, 0.0, 0.0);
/// The eGK prior at alpha = 10 deg.
const EGK_PRIOR_10: EgkParams = egk_prior(0.393_26, -0.106_273, 0.004_679_1);
/// The eGK prior at alpha = 20 deg.
const EGK_PRIOR_20: EgkParams = egk_prior(0.739_09, -0.229_29, 0.017_320_5);

/// A first-order plant `C[k+1] = a C[k] + g Cmu[k]` for one jet: a lag of 88 ms, the geometric
/// middle of the 1 to 3 c/U the circulation of a trailing-edge jet takes to build up
/// (docs/equations.md, Actuator and plant magnitudes \[INF\]), to a roll moment of `sign * 0.01` at
/// the paper's largest Cmu, 0.009 (the middle of the 0.005 to 0.02 given there \[INF\]). It has no
/// slow terms
/// (the paper's first-order form).
///
/// A placeholder for tests: no fit starts from it. The plant fit is a sparse regression on the
/// actuation runs with no prior, and a dataset without them is refused, so this plant never
/// reaches a fitted model (the moment coincides with the tunnel's at alpha = 0 for that reason
/// alone).
const fn plant_prior(sign: f32) -> PlantParams {
    // exp(-dt / 88 ms) at 1 kHz.
    let pole = 0.988_69;
    let mut model = SparseModel::ZERO;
    model.terms[0] = Term { coeff: pole, monomial: single(plant_var::CL_AFC) };
    model.terms[1] = Term { coeff: sign * (1.0 - pole) * 0.01 / 0.009, monomial: single(plant_var::CMU) };
    model.n_terms = 2;
    PlantParams { slow_pole: 0.0, cmu_max: 0.009, model }
}

const _: () = assert!(Factor::var(plant_var::CL_AFC).is_some() && Factor::var(plant_var::CMU).is_some());

/// The monomial of one variable (degree 1).
const fn single(var_idx: usize) -> Monomial {
    // The callers name a model variable (checked below), so the fallback is never taken.
    let factor = match Factor::var(var_idx) {
        Some(factor) => factor,
        None => ONE_FACTOR,
    };
    Monomial { factors: [factor, ONE_FACTOR, ONE_FACTOR], gate_mask: 0 }
}

/// The physical prior at the paper's geometry and 1 kHz. The pressure path has no modes yet
/// (its estimate is the offset, and the fusion gain is zero, so `C_l,roll` is the eGK's), and
/// the coupling operator is zero (the linear superposition).
pub const PRIOR: CoefficientSet = CoefficientSet {
    schema_version: SCHEMA_VERSION,
    dt_s: 1.0e-3,
    // Poles of 30 Hz and 20 Hz first-order differentiators at 1 kHz: exp(-2 pi f dt).
    rate_filter: RateFilter { rate_pole: 0.828_2, accel_pole: 0.881_9 },
    alpha_schedule_deg: [0.0, 10.0, 20.0, 20.0, 20.0, 20.0, 20.0, 20.0],
    n_alpha: 3,
    egk: [
        EGK_PRIOR_0,
        EGK_PRIOR_10,
        EGK_PRIOR_20,
        EGK_PRIOR_20,
        EGK_PRIOR_20,
        EGK_PRIOR_20,
        EGK_PRIOR_20,
        EGK_PRIOR_20,
    ],
    pressure: PressureModel {
        rank: 0,
        a: [[0.0; PRESSURE_RANK]; PRESSURE_RANK],
        b: [[0.0; N_PRESSURE_INPUTS]; PRESSURE_RANK],
        c: [[0.0; PRESSURE_RANK]; N_TAPS],
        cp_mean: [0.0; N_TAPS],
        gain: [[0.0; N_TAPS]; PRESSURE_RANK],
        innovation_std: [1.0; N_TAPS],
        gate_sigma: 6.0,
        isolate_after: 20,
        settle_steps: 0,
        cl_weights: [[0.0; N_TAPS]; N_ALPHA],
        cl_offset: [0.0; N_ALPHA],
    },
    fusion: FusionParams { rho: 0.999, gain: 0.0 },
    plant: [plant_prior(1.0), plant_prior(-1.0)],
    coupling: SparseModel::ZERO,
    controller: ControllerParams {
        causality_pole: 0.98,
        feedback_kp: 0.5,
        feedback_ki: 5.0,
        cmu_max: 0.009,
        inversion_iterations: 16,
    },
    // No actuator dynamics known before a fit: the jet's Cmu is the last demand.
    actuator: [ActuatorResponse::IDENTITY; 2],
    // The paper's wing rolls with |C_l| below about 0.06 (the default campaign's balance, the
    // roll runs at alpha 20 deg); before a fit the envelope is wider than that, +-0.1.
    envelope: Envelope { cl_roll: [-0.1, 0.1], cl: [-0.1, 0.1] },
};

const _: () = assert!(N_ALPHA >= 3, "the prior schedules three angles of attack");

/// A set with every table at its full size (rank-10 pressure model, 16-term plants and coupling
/// operator) and stable, deterministic values: the fixture for tests and for the benchmark of
/// one full step, whose cost depends on the sizes, not on the values.
#[must_use]
pub fn full_size_fixture() -> CoefficientSet {
    let mut set = PRIOR;
    let pressure = &mut set.pressure;
    pressure.rank = PRESSURE_RANK as u8;
    for row in 0..PRESSURE_RANK {
        for col in 0..PRESSURE_RANK {
            let coupling = 0.01 * fixture_value(row * 31 + col);
            pressure.a[row][col] = if row == col { 0.95 - 0.02 * row as f32 } else { coupling };
        }
        for input in 0..N_PRESSURE_INPUTS {
            pressure.b[row][input] = 0.01 * fixture_value(700 + row * 7 + input);
        }
        for tap in 0..N_TAPS {
            pressure.c[tap][row] = 0.3 * fixture_value(1000 + tap * 17 + row);
            pressure.gain[row][tap] = 0.05 * fixture_value(2000 + row * 13 + tap);
        }
    }
    for tap in 0..N_TAPS {
        pressure.cp_mean[tap] = -0.3 + 0.02 * tap as f32;
        pressure.innovation_std[tap] = 0.02;
        for (breakpoint, weights) in pressure.cl_weights.iter_mut().enumerate() {
            weights[tap] = 0.01 * fixture_value(3000 + 100 * breakpoint + tap);
        }
    }
    set.fusion = FusionParams { rho: 0.999, gain: 0.05 };
    for side in 0..2 {
        set.plant[side].slow_pole = 0.95;
        fill_sparse(&mut set.plant[side].model, 4000 + 100 * side, N_PLANT_VARS, 0.001, 0);
        // Keep the plant a stable lag: the self term dominates.
        set.plant[side].model.terms[0] = Term { coeff: 0.987, monomial: single(plant_var::CL_AFC) };
    }
    // Every coupling term is gated on blowing and roll, as the paper's admissibility rules ask.
    let gates = (1 << coupling_var::CMU) | (1 << coupling_var::PHI);
    fill_sparse(&mut set.coupling, 5000, MAX_VARS, 0.01, gates);
    set
}

/// Fills every term slot with a distinct monomial of degree up to 3 over `n_vars` variables,
/// small coefficients, and the given gates on every term.
fn fill_sparse(model: &mut SparseModel, seed: usize, n_vars: usize, scale: f32, gate_mask: u8) {
    for (term_idx, term) in model.terms.iter_mut().enumerate() {
        let mut powers = [0u8; MAX_VARS];
        powers[term_idx % n_vars] += 1;
        powers[(term_idx / n_vars + 1) % n_vars] += (term_idx % 3) as u8;
        let monomial = Monomial::from_powers(&powers, gate_mask).unwrap_or(Monomial::ONE);
        *term = Term { coeff: scale * fixture_value(seed + term_idx), monomial };
    }
    model.n_terms = model.terms.len() as u8;
    model.gate_threshold = [1e-4; MAX_VARS];
}

/// A deterministic value in [-1, 1) (a 32-bit integer hash).
fn fixture_value(index: usize) -> f32 {
    let mut hash = (index as u32).wrapping_mul(0x9E37_79B9) ^ 0x85EB_CA6B;
    hash ^= hash >> 15;
    hash = hash.wrapping_mul(0x2C1B_3C6D);
    hash ^= hash >> 12;
    (hash as f32 / u32::MAX as f32) * 2.0 - 1.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::blob::validate;

    #[test]
    fn prior_and_fixture_are_valid_sets() {
        assert_eq!(validate(&PRIOR), Ok(()));
        assert_eq!(validate(&full_size_fixture()), Ok(()));
    }
}

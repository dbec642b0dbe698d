//! Sparse models (SINDy, Brunton, Proctor & Kutz, PNAS 2016): a sum of terms, each a
//! coefficient times a product of integer powers of the variables, optionally multiplied by
//! anti-Dirac indicators `delta_bar(v) = 1 if |v| > eps else 0` (paper section V).
//!
//! The plant (paper eq. 5) and the coupling operator (paper eqs. 9-11) share this
//! representation, and the host evaluates the same tables in f64 with [`SparseModel::eval_f64`].

use serde::{Deserialize, Serialize};

use crate::coeffs::{MAX_POWER, MAX_TERMS, MAX_VARS};

/// One term: `coeff * prod_v x_v^powers[v] * prod_{v in gates} delta_bar(x_v)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Monomial {
    /// Power of each variable (0 = absent).
    pub powers: [u8; MAX_VARS],
    /// Bit `v` set: the term is multiplied by the indicator of variable `v`.
    pub gate_mask: u8,
}

impl Monomial {
    /// The constant term `1`.
    pub const ONE: Self = Self { powers: [0; MAX_VARS], gate_mask: 0 };

    /// Product of the variables' powers and gates in f32.
    #[must_use]
    pub fn eval(&self, vars: &[f32; MAX_VARS], gate_threshold: &[f32; MAX_VARS]) -> f32 {
        let mut product = 1.0f32;
        for var_idx in 0..MAX_VARS {
            if self.gate_mask & (1 << var_idx) != 0 && !indicator(vars[var_idx], gate_threshold[var_idx]) {
                return 0.0;
            }
            for _ in 0..usize::from(self.powers[var_idx]).min(MAX_POWER) {
                product *= vars[var_idx];
            }
        }
        product
    }

    /// Product of the variables' powers and gates in f64 (the host's reference evaluation).
    #[must_use]
    pub fn eval_f64(&self, vars: &[f64; MAX_VARS], gate_threshold: &[f32; MAX_VARS]) -> f64 {
        let mut product = 1.0f64;
        for var_idx in 0..MAX_VARS {
            if self.gate_mask & (1 << var_idx) != 0 && !indicator_f64(vars[var_idx], gate_threshold[var_idx]) {
                return 0.0;
            }
            for _ in 0..usize::from(self.powers[var_idx]).min(MAX_POWER) {
                product *= vars[var_idx];
            }
        }
        product
    }

    /// Total degree of the term.
    #[must_use]
    pub fn degree(&self) -> u32 {
        self.powers.iter().map(|&power| u32::from(power)).sum()
    }
}

/// One coefficient and its monomial.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Term {
    /// Coefficient.
    pub coeff: f32,
    /// Variables, powers and gates.
    pub monomial: Monomial,
}

impl Term {
    /// A zero term (unused slot).
    pub const ZERO: Self = Self { coeff: 0.0, monomial: Monomial::ONE };
}

/// A sparse model of at most [`MAX_TERMS`] terms over at most [`MAX_VARS`] variables.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SparseModel {
    /// Terms; only the first `n_terms` are evaluated.
    pub terms: [Term; MAX_TERMS],
    /// Number of used terms.
    pub n_terms: u8,
    /// Indicator threshold of each variable: `delta_bar(v) = 1` when `|v| > threshold`.
    pub gate_threshold: [f32; MAX_VARS],
}

impl SparseModel {
    /// The model that is zero everywhere.
    pub const ZERO: Self = Self { terms: [Term::ZERO; MAX_TERMS], n_terms: 0, gate_threshold: [0.0; MAX_VARS] };

    /// The used terms.
    #[must_use]
    pub fn active_terms(&self) -> &[Term] {
        let n_terms = usize::from(self.n_terms).min(MAX_TERMS);
        &self.terms[..n_terms]
    }

    /// Evaluates the model in f32 (the core's arithmetic).
    ///
    /// The powers of every variable up to [`MAX_POWER`] are computed once, so each term costs
    /// one multiplication per variable (a larger power, which validation rejects, is clamped).
    #[must_use]
    pub fn eval(&self, vars: &[f32; MAX_VARS]) -> f32 {
        let mut powers = [[1.0f32; MAX_POWER + 1]; MAX_VARS];
        let mut active = 0u8;
        for var_idx in 0..MAX_VARS {
            for power in 1..=MAX_POWER {
                powers[var_idx][power] = powers[var_idx][power - 1] * vars[var_idx];
            }
            if indicator(vars[var_idx], self.gate_threshold[var_idx]) {
                active |= 1 << var_idx;
            }
        }
        let mut sum = 0.0f32;
        for term in self.active_terms() {
            if term.monomial.gate_mask & !active != 0 {
                continue;
            }
            // Only the variables present in the term are multiplied in (most terms have one to
            // three); validated sets have no power above MAX_POWER, a larger one is clamped.
            let mut product = term.coeff;
            for (table, &power) in powers.iter().zip(&term.monomial.powers) {
                if power != 0 {
                    product *= table[usize::from(power).min(MAX_POWER)];
                }
            }
            sum += product;
        }
        sum
    }

    /// Evaluates the model in f64 with the same coefficients (the host's reference).
    #[must_use]
    pub fn eval_f64(&self, vars: &[f64; MAX_VARS]) -> f64 {
        self.active_terms()
            .iter()
            .map(|term| f64::from(term.coeff) * term.monomial.eval_f64(vars, &self.gate_threshold))
            .sum()
    }
}

/// Anti-Dirac indicator `delta_bar(v) = 1 - delta(v)`: true when `|v|` exceeds the threshold.
/// A NaN is not "active".
#[must_use]
pub fn indicator(value: f32, threshold: f32) -> bool {
    value.abs() > threshold
}

/// The same indicator for f64 values, with the f32 threshold widened exactly.
#[must_use]
pub fn indicator_f64(value: f64, threshold: f32) -> bool {
    value.abs() > f64::from(threshold)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The direct f64 formula of one term, written without the model's loops.
    fn direct(
        coeff: f32,
        powers: [u8; MAX_VARS],
        gate_mask: u8,
        threshold: &[f32; MAX_VARS],
        vars: &[f64; MAX_VARS],
    ) -> f64 {
        let gated_off = (0..MAX_VARS).any(|v| gate_mask & (1 << v) != 0 && vars[v].abs() <= f64::from(threshold[v]));
        if gated_off {
            return 0.0;
        }
        f64::from(coeff) * (0..MAX_VARS).map(|v| vars[v].powi(i32::from(powers[v]))).product::<f64>()
    }

    fn term_strategy() -> impl Strategy<Value = (f32, [u8; MAX_VARS], u8)> {
        (-100.0f32..100.0, proptest::array::uniform6(0u8..=3), 0u8..64)
    }

    proptest! {
        /// f32 evaluation against the direct f64 formula: relative error below 1e-5 of the sum
        /// of the terms' magnitudes (f32 has a 6e-8 unit round-off; a term of degree up to 18
        /// and 16 terms accumulate at most a few hundred of them).
        #[test]
        fn f32_and_f64_evaluations_match_the_direct_formula(
            terms in proptest::collection::vec(term_strategy(), 0..=MAX_TERMS),
            vars in proptest::array::uniform6(-2.0f32..2.0),
            threshold in proptest::array::uniform6(0.0f32..0.5),
        ) {
            let mut model = SparseModel { gate_threshold: threshold, ..SparseModel::ZERO };
            for (slot, &(coeff, powers, gate_mask)) in terms.iter().enumerate() {
                model.terms[slot] = Term { coeff, monomial: Monomial { powers, gate_mask } };
            }
            model.n_terms = terms.len() as u8;
            let vars64 = vars.map(f64::from);
            let expected: f64 = terms.iter().map(|&(c, p, g)| direct(c, p, g, &threshold, &vars64)).sum();
            let magnitude: f64 = terms.iter().map(|&(c, p, g)| direct(c, p, g, &threshold, &vars64).abs()).sum();
            let tolerance = 1e-5 * magnitude.max(1e-12);
            prop_assert!((model.eval_f64(&vars64) - expected).abs() <= 1e-12 * magnitude.max(1.0));
            prop_assert!((f64::from(model.eval(&vars)) - expected).abs() <= tolerance);
        }
    }

    #[test]
    fn indicator_gates_are_exact() {
        let mut model = SparseModel::ZERO;
        let mut powers = [0; MAX_VARS];
        powers[0] = 1;
        model.terms[0] = Term { coeff: 2.0, monomial: Monomial { powers, gate_mask: 1 << 3 } };
        model.n_terms = 1;
        model.gate_threshold[3] = 1e-4;
        let mut vars = [0.0f32; MAX_VARS];
        vars[0] = 0.5;
        for (gate_value, expected) in [(0.0, 0.0), (1e-4, 0.0), (-1e-4, 0.0), (1.0001e-4, 1.0), (-0.3, 1.0)] {
            vars[3] = gate_value;
            assert_eq!(model.eval(&vars), expected, "gate value {gate_value}");
            assert_eq!(model.eval_f64(&vars.map(f64::from)), f64::from(expected));
        }
        vars[3] = f32::NAN;
        assert_eq!(model.eval(&vars), 0.0, "a NaN gate variable is not active");
    }

    #[test]
    fn terms_past_n_terms_are_not_evaluated() {
        let mut model = SparseModel::ZERO;
        model.terms[0] = Term { coeff: 1.0, monomial: Monomial::ONE };
        model.terms[1] = Term { coeff: 5.0, monomial: Monomial::ONE };
        model.n_terms = 1;
        assert_eq!(model.eval(&[0.0; MAX_VARS]), 1.0);
        model.n_terms = 200;
        assert_eq!(model.eval(&[0.0; MAX_VARS]), 6.0, "n_terms beyond the capacity is clamped");
    }
}

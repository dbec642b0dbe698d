//! Sparse models (SINDy, Brunton, Proctor & Kutz, PNAS 2016): a sum of terms, each a
//! coefficient times a product of integer powers of the variables, optionally multiplied by
//! anti-Dirac indicators `delta_bar(v) = 1 if |v| > eps else 0` (paper section V).
//!
//! The plant (paper eq. 5) and the coupling operator (paper eqs. 9-11) share this
//! representation, and the host evaluates the same tables in f64 with [`SparseModel::eval_in`].

use serde::{Deserialize, Serialize};

use crate::coeffs::{MAX_DEGREE, MAX_TERMS, MAX_VARS};
use crate::real::Real;

/// One factor of a monomial: a variable of the model, or the constant `1` that pads a term of
/// degree below [`MAX_DEGREE`].
///
/// An enum, not a `u8`: the compiler then knows every factor indexes the evaluation table, so
/// an interpreted term reads each factor with no mask and no bounds check (three instructions
/// per term on the M4F, which put a loaded set's worst step within its instruction budget).
/// `postcard` writes a unit variant as its index, one byte, as it wrote the `u8`: blobs are
/// unchanged, and one that names no factor fails to decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[repr(u8)]
pub enum Factor {
    /// Variable 0.
    Var0,
    /// Variable 1.
    Var1,
    /// Variable 2.
    Var2,
    /// Variable 3.
    Var3,
    /// Variable 4.
    Var4,
    /// Variable 5.
    Var5,
    /// Variable 6.
    Var6,
    /// The constant `1`.
    One,
}

const _: () = assert!(Factor::One as usize == MAX_VARS, "one Factor variant per variable, then One");

impl Factor {
    /// The factor of variable `var_idx`, or `None` past the [`MAX_VARS`] variables.
    #[must_use]
    pub const fn var(var_idx: usize) -> Option<Self> {
        const VARS: [Factor; MAX_VARS] =
            [Factor::Var0, Factor::Var1, Factor::Var2, Factor::Var3, Factor::Var4, Factor::Var5, Factor::Var6];
        if var_idx < MAX_VARS { Some(VARS[var_idx]) } else { None }
    }

    /// The variable's index, or [`MAX_VARS`] for [`Factor::One`]: the factor's entry in the
    /// evaluation table.
    #[must_use]
    pub const fn index(self) -> usize {
        self as usize
    }
}

/// The padding factor (the constant `1`).
pub const ONE_FACTOR: Factor = Factor::One;

/// One term: `coeff * prod_{f in factors} x_f * prod_{v in gates} delta_bar(x_v)`.
///
/// The term is stored as its factors (a variable index per degree, [`ONE_FACTOR`] for none),
/// not as a power per variable: the core then multiplies exactly [`MAX_DEGREE`] table entries
/// per term without scanning the variables, which more than halves the cost of a term on the
/// M4F. Factors are kept in ascending order with the padding last, so that equal
/// monomials compare equal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Monomial {
    /// Variable index of each factor, ascending; [`ONE_FACTOR`] pads terms of lower degree.
    pub factors: [Factor; MAX_DEGREE],
    /// Bit `v` set: the term is multiplied by the indicator of variable `v`.
    pub gate_mask: u8,
}

impl Monomial {
    /// The constant term `1`.
    pub const ONE: Self = Self { factors: [ONE_FACTOR; MAX_DEGREE], gate_mask: 0 };

    /// The monomial with the given power of each variable, or `None` when its degree exceeds
    /// [`MAX_DEGREE`].
    #[must_use]
    pub fn from_powers(powers: &[u8; MAX_VARS], gate_mask: u8) -> Option<Self> {
        let mut factors = [ONE_FACTOR; MAX_DEGREE];
        let mut slot = 0;
        for (var_idx, &power) in powers.iter().enumerate() {
            for _ in 0..power {
                *factors.get_mut(slot)? = Factor::var(var_idx)?;
                slot += 1;
            }
        }
        Some(Self { factors, gate_mask })
    }

    /// The power of each variable (factors outside the variables, which validation rejects,
    /// are not counted).
    #[must_use]
    pub fn powers(&self) -> [u8; MAX_VARS] {
        let mut powers = [0u8; MAX_VARS];
        for &factor in &self.factors {
            if let Some(power) = powers.get_mut(factor.index()) {
                *power += 1;
            }
        }
        powers
    }

    /// This monomial times `var^power`, or `None` when the degree would exceed [`MAX_DEGREE`].
    #[must_use]
    pub fn times(&self, var_idx: usize, power: u8) -> Option<Self> {
        let mut powers = self.powers();
        *powers.get_mut(var_idx)? += power;
        Self::from_powers(&powers, self.gate_mask)
    }

    /// True when every factor is a variable below `n_vars` or the padding, and the padding
    /// comes last in ascending order (the form [`Monomial::from_powers`] builds).
    #[must_use]
    pub fn is_canonical(&self, n_vars: usize) -> bool {
        let in_range = self.factors.iter().all(|&factor| factor.index() < n_vars || factor == ONE_FACTOR);
        in_range && self.factors.windows(2).all(|pair| pair[0] <= pair[1])
    }

    /// Product of the factors, zero when a gate is shut, in any scalar (the host builds the
    /// SINDy library's columns with it in f64): the factors multiplied in order, as
    /// [`SparseModel::eval`] multiplies them after the coefficient.
    #[must_use]
    pub fn eval_in<R: Real>(&self, vars: &[R; MAX_VARS], gate_threshold: &[f32; MAX_VARS]) -> R {
        let gated_off = (0..MAX_VARS)
            .any(|var_idx| self.gate_mask & (1 << var_idx) != 0 && !indicator(vars[var_idx], gate_threshold[var_idx]));
        if gated_off {
            return R::ZERO;
        }
        let table = factor_table(vars);
        self.factors.iter().fold(R::ONE, |product, &factor| product * table[factor.index()])
    }

    /// Total degree of the term.
    #[must_use]
    pub fn degree(&self) -> u32 {
        self.factors.iter().filter(|&&factor| factor != ONE_FACTOR).count() as u32
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

/// Entries of the evaluation table: the variables, then the constant 1 for [`ONE_FACTOR`]
/// (and, while the variables are fewer, more 1s that keep the length a power of two).
const FACTOR_TABLE_LEN: usize = 8;
const _: () = assert!(MAX_VARS < FACTOR_TABLE_LEN && FACTOR_TABLE_LEN.is_power_of_two());

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
    /// Each term multiplies its coefficient by exactly [`MAX_DEGREE`] entries of the variables
    /// extended by the constant 1 (the padding factor), in factor order, and the terms are
    /// summed in order. A [`Factor`] always indexes the table, so the loop has no bounds check.
    ///
    /// The indicators are computed only when a term has a gate: the plant models have none,
    /// and their indicators cost about a fifth of an interpreted model (a loaded set's worst step:
    /// 3,095 instructions on the M4F, 3,327 with every indicator computed first). The sum is the
    /// same, bit for bit, as evaluating every indicator first: the terms and their order do not
    /// change.
    #[must_use]
    pub fn eval(&self, vars: &[f32; MAX_VARS]) -> f32 {
        self.eval_in(vars)
    }

    /// [`SparseModel::eval`] in any scalar, the table's f32 coefficients and thresholds widened
    /// exactly (the host's fits evaluate the tables in f64 with it).
    #[must_use]
    #[inline]
    pub fn eval_in<R: Real>(&self, vars: &[R; MAX_VARS]) -> R {
        let table = factor_table(vars);
        // `-0.0` is the identity of addition, so the first term is not added to a zero.
        let mut sum = R::NEG_ZERO;
        let mut rest = self.active_terms();
        // Two terms per turn while neither has a gate: half the loop's overhead.
        while let [first, second, tail @ ..] = rest {
            if first.monomial.gate_mask | second.monomial.gate_mask != 0 {
                break;
            }
            sum += term_value(first, &table);
            sum += term_value(second, &table);
            rest = tail;
        }
        while let [term, tail @ ..] = rest {
            if term.monomial.gate_mask != 0 {
                return self.eval_gated(&table, rest, sum);
            }
            sum += term_value(term, &table);
            rest = tail;
        }
        sum
    }

    /// The rest of [`SparseModel::eval`] from the first gated term on: the indicators, then
    /// the remaining `terms` added to `sum` in order, a gated-off term skipped.
    #[inline(never)]
    fn eval_gated<R: Real>(&self, table: &[R; FACTOR_TABLE_LEN], terms: &[Term], mut sum: R) -> R {
        let mut active = 0u8;
        for (var_idx, (&value, &threshold)) in table.iter().zip(&self.gate_threshold).enumerate() {
            if indicator(value, threshold) {
                active |= 1 << var_idx;
            }
        }
        for term in terms {
            if term.monomial.gate_mask & !active == 0 {
                sum += term_value(term, table);
            }
        }
        sum
    }
}

/// The variables extended by the constant 1 (the padding factor's entry), so that a
/// [`Factor`] always indexes it.
#[inline(always)]
fn factor_table<R: Real>(vars: &[R; MAX_VARS]) -> [R; FACTOR_TABLE_LEN] {
    let mut table = [R::ONE; FACTOR_TABLE_LEN];
    for (slot, &value) in table.iter_mut().zip(vars) {
        *slot = value;
    }
    table
}

/// A term's coefficient times its [`MAX_DEGREE`] factors from `table`, in factor order.
#[inline(always)]
fn term_value<R: Real>(term: &Term, table: &[R; FACTOR_TABLE_LEN]) -> R {
    let mut product = R::from_f32(term.coeff);
    for &factor in &term.monomial.factors {
        product *= table[factor.index()];
    }
    product
}

/// Which of a coefficient set's sparse models.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelId {
    /// `plant[0].model`.
    PlantPort,
    /// `plant[1].model`.
    PlantStarboard,
    /// `coupling`.
    Coupling,
}

impl ModelId {
    /// The plant model of a side (0 port, 1 starboard).
    #[must_use]
    pub const fn plant(side: usize) -> Self {
        if side == 0 { Self::PlantPort } else { Self::PlantStarboard }
    }
}

/// How the estimator and the controller evaluate the coefficient set's sparse models.
///
/// [`Interpreted`] reads the tables, so it serves any set (a loaded blob); the built-in set
/// also has its models generated as straight-line code (`coeffs::CompiledDefault`), which
/// gives the same bits at a fraction of the instructions on the M4F.
pub trait SparseEval: Copy {
    /// The value of `model`, which is the set's model `id`, at `vars`.
    fn eval(self, id: ModelId, model: &SparseModel, vars: &[f32; MAX_VARS]) -> f32;
}

/// Evaluates a sparse model from its tables ([`SparseModel::eval`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Interpreted;

impl SparseEval for Interpreted {
    #[inline]
    fn eval(self, _id: ModelId, model: &SparseModel, vars: &[f32; MAX_VARS]) -> f32 {
        model.eval(vars)
    }
}

/// Anti-Dirac indicator `delta_bar(v) = 1 - delta(v)`: true when `|v|` exceeds the threshold.
/// A NaN is not "active".
#[must_use]
pub fn indicator<R: Real>(value: R, threshold: f32) -> bool {
    value.abs() > R::from_f32(threshold)
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

    /// A coefficient, the powers of a monomial of degree up to [`MAX_DEGREE`] and a gate mask.
    fn term_strategy() -> impl Strategy<Value = (f32, [u8; MAX_VARS], u8)> {
        let factors = proptest::array::uniform3(0..=MAX_VARS);
        (-100.0f32..100.0, factors, 0u8..64).prop_map(|(coeff, factors, gate_mask)| {
            let mut powers = [0u8; MAX_VARS];
            for var_idx in factors.into_iter().filter(|&var_idx| var_idx < MAX_VARS) {
                powers[var_idx] += 1;
            }
            (coeff, powers, gate_mask)
        })
    }

    /// The evaluation as it was before the indicators became lazy: every indicator first, then
    /// every term in order, a gated-off one skipped.
    fn eager(model: &SparseModel, vars: &[f32; MAX_VARS]) -> f32 {
        let mut table = [1.0f32; FACTOR_TABLE_LEN];
        table[..MAX_VARS].copy_from_slice(vars);
        let active =
            (0..MAX_VARS).filter(|&v| indicator(vars[v], model.gate_threshold[v])).fold(0u8, |mask, v| mask | 1 << v);
        model.active_terms().iter().filter(|t| t.monomial.gate_mask & !active == 0).fold(-0.0f32, |sum, term| {
            sum + term.monomial.factors.iter().fold(term.coeff, |p, &f| p * table[f.index()])
        })
    }

    proptest! {
        /// The lazy indicators give the eager evaluation's sum bit for bit, wherever the first
        /// gated term sits and whether its gate is open or shut.
        #[test]
        fn lazy_indicators_sum_bit_for_bit_like_eager_ones(
            terms in proptest::collection::vec(term_strategy(), 0..=MAX_TERMS),
            vars in proptest::array::uniform7(prop_oneof![Just(0.0f32), -2.0f32..2.0]),
            threshold in proptest::array::uniform7(0.0f32..0.5),
        ) {
            let mut model = SparseModel { gate_threshold: threshold, ..SparseModel::ZERO };
            for (slot, &(coeff, powers, gate_mask)) in model.terms.iter_mut().zip(&terms) {
                let monomial = Monomial::from_powers(&powers, gate_mask).expect("degree within the limit");
                *slot = Term { coeff, monomial };
            }
            model.n_terms = terms.len() as u8;
            prop_assert_eq!(model.eval(&vars).to_bits(), eager(&model, &vars).to_bits());
        }
    }

    proptest! {
        /// f32 evaluation against the direct f64 formula: relative error below 1e-5 of the sum
        /// of the terms' magnitudes (f32 has a 6e-8 unit round-off; a term of degree up to 3
        /// and 16 terms accumulate at most a few dozen of them).
        #[test]
        fn f32_and_f64_evaluations_match_the_direct_formula(
            terms in proptest::collection::vec(term_strategy(), 0..=MAX_TERMS),
            vars in proptest::array::uniform7(-2.0f32..2.0),
            threshold in proptest::array::uniform7(0.0f32..0.5),
        ) {
            let mut model = SparseModel { gate_threshold: threshold, ..SparseModel::ZERO };
            for (slot, &(coeff, powers, gate_mask)) in terms.iter().enumerate() {
                let monomial = Monomial::from_powers(&powers, gate_mask).unwrap();
                prop_assert_eq!(monomial.powers(), powers);
                prop_assert!(monomial.is_canonical(MAX_VARS));
                model.terms[slot] = Term { coeff, monomial };
            }
            model.n_terms = terms.len() as u8;
            let vars64 = vars.map(f64::from);
            let expected: f64 = terms.iter().map(|&(c, p, g)| direct(c, p, g, &threshold, &vars64)).sum();
            let magnitude: f64 = terms.iter().map(|&(c, p, g)| direct(c, p, g, &threshold, &vars64).abs()).sum();
            let tolerance = 1e-5 * magnitude.max(1e-12);
            prop_assert!((model.eval_in(&vars64) - expected).abs() <= 1e-12 * magnitude.max(1.0));
            prop_assert!((f64::from(model.eval(&vars)) - expected).abs() <= tolerance);
        }
    }

    #[test]
    fn indicator_gates_are_exact() {
        let mut model = SparseModel::ZERO;
        let mut powers = [0; MAX_VARS];
        powers[0] = 1;
        model.terms[0] = Term { coeff: 2.0, monomial: Monomial::from_powers(&powers, 1 << 3).unwrap() };
        model.n_terms = 1;
        model.gate_threshold[3] = 1e-4;
        let mut vars = [0.0f32; MAX_VARS];
        vars[0] = 0.5;
        for (gate_value, expected) in [(0.0, 0.0), (1e-4, 0.0), (-1e-4, 0.0), (1.0001e-4, 1.0), (-0.3, 1.0)] {
            vars[3] = gate_value;
            assert_eq!(model.eval(&vars), expected, "gate value {gate_value}");
            assert_eq!(model.eval_in(&vars.map(f64::from)), f64::from(expected));
        }
        vars[3] = f32::NAN;
        assert_eq!(model.eval(&vars), 0.0, "a NaN gate variable is not active");
    }

    #[test]
    fn degree_above_the_limit_has_no_monomial() {
        assert_eq!(
            Monomial::from_powers(&[2, 0, 1, 0, 0, 0, 0], 0).map(|m| m.factors),
            Some([Factor::Var0, Factor::Var0, Factor::Var2])
        );
        assert_eq!(Monomial::from_powers(&[2, 0, 2, 0, 0, 0, 0], 0), None);
        assert_eq!(Monomial::from_powers(&[0; MAX_VARS], 0), Some(Monomial::ONE));
        let x0 = Monomial::from_powers(&[1, 0, 0, 0, 0, 0, 0], 0).unwrap();
        assert_eq!(x0.times(5, 2).map(|m| m.factors), Some([Factor::Var0, Factor::Var5, Factor::Var5]));
        assert_eq!(x0.times(5, 3), None);
        assert!(!Monomial { factors: [Factor::Var3, Factor::Var1, ONE_FACTOR], gate_mask: 0 }.is_canonical(MAX_VARS));
        assert!(!Monomial { factors: [Factor::Var1, ONE_FACTOR, Factor::Var2], gate_mask: 0 }.is_canonical(MAX_VARS));
        assert!(!Monomial { factors: [Factor::Var1, Factor::Var4, ONE_FACTOR], gate_mask: 0 }.is_canonical(4));
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

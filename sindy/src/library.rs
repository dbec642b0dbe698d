//! Candidate libraries: ordered lists of the core's monomials over named variables.
//!
//! Every column of the library matrix Theta is computed with [`Monomial::eval_in`], the
//! host's reference evaluation of the core's sparse terms, so the model the host fits is the
//! model the core evaluates (up to the f32 rounding of the coefficients).

use estimator_core::coeffs::{MAX_DEGREE, MAX_TERMS, MAX_VARS};
use estimator_core::sparse::{Monomial, SparseModel, Term};
use nalgebra::DMatrix;

use super::error::SindyError;

/// An ordered list of candidate terms over at most [`MAX_VARS`] named variables, with the
/// per-variable thresholds of the anti-Dirac gates (`delta_bar(v) = 1` when `|v| > threshold`).
#[derive(Debug, Clone, PartialEq)]
pub struct Library {
    /// Variable names; variable `v` is slot `v` of a sample.
    names: Vec<String>,
    /// Gate threshold of each variable, as in [`SparseModel::gate_threshold`].
    gate_threshold: [f32; MAX_VARS],
    /// The candidate terms, one column of Theta each.
    terms: Vec<Monomial>,
}

impl Library {
    /// An empty library over the given variables (at most [`MAX_VARS`], distinct, non-empty).
    pub fn new(names: &[&str]) -> Result<Self, SindyError> {
        if names.is_empty() {
            return Err(SindyError::EmptyData { what: "variable names" });
        }
        if names.len() > MAX_VARS {
            return Err(SindyError::TooManyVariables { found: names.len() });
        }
        for (idx, name) in names.iter().enumerate() {
            if name.is_empty() || names[..idx].contains(name) {
                return Err(SindyError::InvalidVariableName((*name).to_owned()));
            }
        }
        let names = names.iter().map(|&name| name.to_owned()).collect();
        Ok(Self { names, gate_threshold: [0.0; MAX_VARS], terms: Vec::new() })
    }

    /// All monomials of total degree at most `max_degree`, in PySINDy's `PolynomialLibrary`
    /// order: by degree, then lexicographically by variable index (`1, x0, x1, x0^2, x0*x1,
    /// x1^2, ...`, i.e. `itertools.combinations_with_replacement`). The degree is at most
    /// [`MAX_DEGREE`], the largest the core evaluates.
    pub fn polynomial(names: &[&str], max_degree: u8, include_constant: bool) -> Result<Self, SindyError> {
        if usize::from(max_degree) > MAX_DEGREE {
            return Err(SindyError::DegreeTooHigh { found: max_degree });
        }
        let mut library = Self::new(names)?;
        let first_degree = if include_constant { 0 } else { 1 };
        for degree in first_degree..=max_degree {
            let mut powers = [0u8; MAX_VARS];
            push_combinations(library.names.len(), degree, 0, &mut powers, &mut library.terms);
        }
        Ok(library)
    }

    /// A library of the given terms, in the given order.
    pub fn from_terms(names: &[&str], terms: &[Monomial]) -> Result<Self, SindyError> {
        let mut library = Self::new(names)?;
        for &term in terms {
            library.push(term)?;
        }
        Ok(library)
    }

    /// Appends a term; rejects unknown variables, non-canonical factors and duplicates.
    pub fn push(&mut self, term: Monomial) -> Result<(), SindyError> {
        self.validate(&term)?;
        if self.terms.contains(&term) {
            return Err(self.invalid(&term, "duplicate term"));
        }
        self.terms.push(term);
        Ok(())
    }

    /// The monomial `prod x_name^power * prod [gate]`, from variable names.
    pub fn monomial(&self, factors: &[(&str, u8)], gates: &[&str]) -> Result<Monomial, SindyError> {
        let mut powers = [0u8; MAX_VARS];
        let mut gate_mask = 0u8;
        for &(name, power) in factors {
            let var = self.var_index(name)?;
            powers[var] = powers[var].saturating_add(power);
        }
        for &name in gates {
            gate_mask |= 1 << self.var_index(name)?;
        }
        let term = Monomial::from_powers(&powers, gate_mask).ok_or_else(|| SindyError::InvalidTerm {
            term: factors.iter().map(|(name, power)| format!("{name}^{power}")).collect::<Vec<_>>().join("*"),
            reason: "degree above the core's limit",
        })?;
        self.validate(&term)?;
        Ok(term)
    }

    /// Removes the given term; returns whether it was present.
    pub fn exclude_term(&mut self, term: &Monomial) -> bool {
        let before = self.terms.len();
        self.terms.retain(|candidate| candidate != term);
        self.terms.len() != before
    }

    /// Removes every term for which `predicate` is true; returns how many were removed.
    pub fn exclude_where(&mut self, mut predicate: impl FnMut(&Monomial) -> bool) -> usize {
        let before = self.terms.len();
        self.terms.retain(|term| !predicate(term));
        before - self.terms.len()
    }

    /// Multiplies every term by the indicator of variable `gate`.
    pub fn gate_all(&mut self, gate: &str) -> Result<(), SindyError> {
        self.gate_where(gate, |_| true).map(|_| ())
    }

    /// Multiplies the terms for which `predicate` is true by the indicator of variable `gate`;
    /// returns how many terms were gated. Fails (and leaves the library unchanged) when two
    /// terms would become equal.
    pub fn gate_where(
        &mut self,
        gate: &str,
        mut predicate: impl FnMut(&Monomial) -> bool,
    ) -> Result<usize, SindyError> {
        let bit = 1u8 << self.var_index(gate)?;
        let mut gated = self.terms.clone();
        let mut count = 0;
        for term in gated.iter_mut().filter(|term| predicate(term)) {
            term.gate_mask |= bit;
            count += 1;
        }
        for (idx, term) in gated.iter().enumerate() {
            if gated[..idx].contains(term) {
                return Err(self.invalid(term, "gating makes two terms equal"));
            }
        }
        self.terms = gated;
        Ok(count)
    }

    /// Sets the gate threshold of a variable (finite and non-negative).
    pub fn set_gate_threshold(&mut self, name: &str, threshold: f32) -> Result<(), SindyError> {
        if !(threshold.is_finite() && threshold >= 0.0) {
            return Err(SindyError::InvalidConfig("gate thresholds must be finite and non-negative"));
        }
        let var = self.var_index(name)?;
        self.gate_threshold[var] = threshold;
        Ok(())
    }

    /// The gate thresholds of all [`MAX_VARS`] slots.
    #[must_use]
    pub fn gate_thresholds(&self) -> &[f32; MAX_VARS] {
        &self.gate_threshold
    }

    /// The variable names.
    #[must_use]
    pub fn variables(&self) -> &[String] {
        &self.names
    }

    /// The index of a variable.
    pub fn var_index(&self, name: &str) -> Result<usize, SindyError> {
        self.names.iter().position(|known| known == name).ok_or_else(|| SindyError::UnknownVariable(name.to_owned()))
    }

    /// The terms, in column order.
    #[must_use]
    pub fn terms(&self) -> &[Monomial] {
        &self.terms
    }

    /// The number of terms (columns of Theta).
    #[must_use]
    pub fn len(&self) -> usize {
        self.terms.len()
    }

    /// Whether the library has no term.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.terms.is_empty()
    }

    /// The human-readable name of a monomial: `1`, `cl_afc`, `cl_afc*cmu`, `cl_roll^3*[cmu]`
    /// (powers in variable order, then the gates in brackets).
    #[must_use]
    pub fn monomial_name(&self, term: &Monomial) -> String {
        let var_name = |var: usize| self.names.get(var).cloned().unwrap_or_else(|| format!("x{var}"));
        let mut factors: Vec<String> = Vec::new();
        for (var, &power) in term.powers().iter().enumerate() {
            match power {
                0 => {}
                1 => factors.push(var_name(var)),
                _ => factors.push(format!("{}^{power}", var_name(var))),
            }
        }
        for var in (0..MAX_VARS).filter(|&var| term.gate_mask & (1 << var) != 0) {
            factors.push(format!("[{}]", var_name(var)));
        }
        if factors.is_empty() { "1".to_owned() } else { factors.join("*") }
    }

    /// The names of all terms, in column order.
    #[must_use]
    pub fn term_names(&self) -> Vec<String> {
        self.terms.iter().map(|term| self.monomial_name(term)).collect()
    }

    /// The library matrix Theta: one row per sample, one column per term, each entry
    /// [`Monomial::eval_in`] of the sample with this library's gate thresholds.
    pub fn theta(&self, samples: &[[f64; MAX_VARS]]) -> Result<DMatrix<f64>, SindyError> {
        if samples.is_empty() {
            return Err(SindyError::EmptyData { what: "samples" });
        }
        if self.terms.is_empty() {
            return Err(SindyError::EmptyData { what: "library terms" });
        }
        self.check_samples(samples)?;
        let theta = DMatrix::from_fn(samples.len(), self.terms.len(), |row, col| {
            self.terms[col].eval_in(&samples[row], &self.gate_threshold)
        });
        for (col, column) in theta.column_iter().enumerate() {
            if let Some(row) = column.iter().position(|value| !value.is_finite()) {
                return Err(SindyError::NonFinite { name: self.monomial_name(&self.terms[col]), row });
            }
        }
        Ok(theta)
    }

    /// The prediction `sum_j coeffs[j] * term_j(sample)` in f64 (zero coefficients skipped).
    pub fn predict(&self, coeffs: &[f64], sample: &[f64; MAX_VARS]) -> Result<f64, SindyError> {
        self.check_coeffs(coeffs)?;
        Ok(self
            .terms
            .iter()
            .zip(coeffs)
            .filter(|&(_, &coeff)| coeff != 0.0)
            .map(|(term, &coeff)| coeff * term.eval_in(sample, &self.gate_threshold))
            .sum())
    }

    /// The core's sparse model of a coefficient vector (one coefficient per term, physical
    /// units): the non-zero coefficients rounded to f32, in library order, with this library's
    /// gate thresholds. A coefficient whose f32 rounding is zero is dropped like a zero one.
    pub fn to_sparse_model(&self, coeffs: &[f64]) -> Result<SparseModel, SindyError> {
        self.check_coeffs(coeffs)?;
        let mut used = Vec::new();
        for (term, &coeff) in self.terms.iter().zip(coeffs) {
            // The nearest f32 (IEEE 754 round-to-nearest); overflow gives an infinity.
            let narrow = coeff as f32;
            if !narrow.is_finite() {
                return Err(SindyError::CoefficientOutOfRange { term: self.monomial_name(term), value: coeff });
            }
            if narrow != 0.0 {
                used.push(Term { coeff: narrow, monomial: *term });
            }
        }
        if used.len() > MAX_TERMS {
            return Err(SindyError::TooManyTerms { found: used.len() });
        }
        let mut model = SparseModel { gate_threshold: self.gate_threshold, ..SparseModel::ZERO };
        model.terms[..used.len()].copy_from_slice(&used);
        model.n_terms = u8::try_from(used.len()).map_err(|_| SindyError::TooManyTerms { found: used.len() })?;
        Ok(model)
    }

    /// Checks that a coefficient vector has one entry per term.
    fn check_coeffs(&self, coeffs: &[f64]) -> Result<(), SindyError> {
        if coeffs.len() == self.terms.len() {
            Ok(())
        } else {
            Err(SindyError::DimensionMismatch { what: "coefficients", expected: self.terms.len(), found: coeffs.len() })
        }
    }

    /// Checks that the library's variables are finite in every sample (naming the variable).
    fn check_samples(&self, samples: &[[f64; MAX_VARS]]) -> Result<(), SindyError> {
        for (row, sample) in samples.iter().enumerate() {
            if let Some(var) = (0..self.names.len()).find(|&var| !sample[var].is_finite()) {
                return Err(SindyError::NonFinite { name: self.names[var].clone(), row });
            }
        }
        Ok(())
    }

    /// Rejects variables beyond the library's and factors out of the canonical order.
    fn validate(&self, term: &Monomial) -> Result<(), SindyError> {
        let n_vars = self.names.len();
        if !term.is_canonical(n_vars) || term.gate_mask >> n_vars != 0 {
            return Err(self.invalid(term, "uses a variable the library does not have, or unordered factors"));
        }
        Ok(())
    }

    /// The error for a rejected term, naming it with generic variable names where needed.
    fn invalid(&self, term: &Monomial, reason: &'static str) -> SindyError {
        SindyError::InvalidTerm { term: self.monomial_name(term), reason }
    }
}

/// Appends the monomials of exactly `degree` in the variables `start..n_vars` (times the
/// powers already in `powers`), in lexicographic order of the non-decreasing index tuples;
/// a total degree above [`MAX_DEGREE`] (which the caller rules out) gives no monomial.
fn push_combinations(n_vars: usize, degree: u8, start: usize, powers: &mut [u8; MAX_VARS], out: &mut Vec<Monomial>) {
    if degree == 0 {
        out.extend(Monomial::from_powers(powers, 0));
        return;
    }
    for var in start..n_vars {
        powers[var] += 1;
        push_combinations(n_vars, degree - 1, var, powers, out);
        powers[var] -= 1;
    }
}

#[cfg(test)]
mod tests {
    use estimator_core::sparse::Factor;

    use super::*;

    fn plant_library() -> Library {
        let mut library = Library::polynomial(&["cl_afc", "cmu", "dcmu", "alpha"], 2, true).unwrap();
        let square = library.monomial(&[("cl_afc", 2)], &[]).unwrap();
        assert!(library.exclude_term(&square));
        library
    }

    #[test]
    fn polynomial_order_and_names_follow_pysindy() {
        let library = Library::polynomial(&["x", "y"], 3, true).unwrap();
        let expected = ["1", "x", "y", "x^2", "x*y", "y^2", "x^3", "x^2*y", "x*y^2", "y^3"];
        assert_eq!(library.term_names(), expected);
        let plant = plant_library();
        assert_eq!(plant.len(), 14, "1 + 4 + 10 - 1 terms");
        assert_eq!(plant.term_names()[5..8], ["cl_afc*cmu", "cl_afc*dcmu", "cl_afc*alpha"]);
        let no_constant = Library::polynomial(&["x", "y"], 1, false).unwrap();
        assert_eq!(no_constant.term_names(), ["x", "y"]);
    }

    #[test]
    fn degrees_never_exceed_the_core_limit() {
        let library = Library::polynomial(&["a", "b"], 3, true).unwrap();
        assert!(library.terms().iter().all(|term| term.degree() <= MAX_DEGREE as u32));
        assert!(library.term_names().contains(&"a^2*b".to_owned()));
        assert_eq!(library.len(), 10);
        assert!(matches!(Library::polynomial(&["a", "b"], 4, true), Err(SindyError::DegreeTooHigh { found: 4 })));
        let mut other = Library::new(&["a"]).unwrap();
        assert!(matches!(other.monomial(&[("a", 2), ("a", 2)], &[]), Err(SindyError::InvalidTerm { .. })));
        let foreign = Monomial::from_powers(&[0, 1, 0, 0, 0, 0, 0], 0).unwrap();
        assert!(matches!(other.push(foreign), Err(SindyError::InvalidTerm { .. })));
        let unordered = Monomial { factors: [Factor::Var0, Factor::Var0, Factor::One], gate_mask: 0 };
        assert!(other.push(unordered).is_ok());
        let mut two = Library::new(&["a", "b"]).unwrap();
        let unordered = Monomial { factors: [Factor::Var1, Factor::Var0, Factor::One], gate_mask: 0 };
        assert!(matches!(two.push(unordered), Err(SindyError::InvalidTerm { .. })));
    }

    #[test]
    fn gates_and_names() {
        let mut library = Library::new(&["cl_roll", "cmu"]).unwrap();
        let cubic = library.monomial(&[("cl_roll", 3)], &[]).unwrap();
        library.push(cubic).unwrap();
        library.push(Monomial::ONE).unwrap();
        assert_eq!(library.gate_where("cmu", |term| term.degree() > 0).unwrap(), 1);
        assert_eq!(library.term_names(), ["cl_roll^3*[cmu]", "1"]);
        library.gate_all("cl_roll").unwrap();
        assert_eq!(library.term_names(), ["cl_roll^3*[cl_roll]*[cmu]", "[cl_roll]"]);
        assert!(matches!(library.gate_all("nope"), Err(SindyError::UnknownVariable(_))));
        let mut clash = Library::new(&["x", "c"]).unwrap();
        clash.push(clash.monomial(&[("x", 1)], &[]).unwrap()).unwrap();
        clash.push(clash.monomial(&[("x", 1)], &["c"]).unwrap()).unwrap();
        assert!(clash.gate_all("c").is_err());
        assert_eq!(clash.term_names(), ["x", "x*[c]"], "a failed gating leaves the library unchanged");
    }

    #[test]
    fn variable_limits() {
        let names = ["a", "b", "c", "d", "e", "f", "g", "h"];
        assert!(Library::new(&names[..MAX_VARS]).is_ok());
        let too_many = &names[..=MAX_VARS];
        assert_eq!(Library::new(too_many), Err(SindyError::TooManyVariables { found: MAX_VARS + 1 }));
        assert!(matches!(Library::new(&["a", "a"]), Err(SindyError::InvalidVariableName(_))));
        assert!(matches!(Library::new(&[]), Err(SindyError::EmptyData { .. })));
    }

    #[test]
    fn theta_is_monomial_eval_in_and_the_sparse_model_agrees() {
        let mut library = plant_library();
        library.gate_where("cmu", |term| term.powers()[0] == 1).unwrap();
        library.set_gate_threshold("cmu", 1e-3).unwrap();
        let samples: Vec<[f64; MAX_VARS]> = (0..50)
            .map(|k| {
                let t = f64::from(k);
                [
                    0.1 * (0.3 * t).sin(),
                    if k % 3 == 0 { 0.0 } else { 0.01 * (0.7 * t).cos() },
                    0.002,
                    0.17,
                    0.0,
                    0.0,
                    0.0,
                ]
            })
            .collect();
        let theta = library.theta(&samples).unwrap();
        let coeffs: Vec<f64> = (0..library.len()).map(|j| if j % 4 == 1 { 0.5 + j as f64 } else { 0.0 }).collect();
        let model = library.to_sparse_model(&coeffs).unwrap();
        assert_eq!(usize::from(model.n_terms), coeffs.iter().filter(|&&c| c != 0.0).count());
        for (row, sample) in samples.iter().enumerate() {
            for (col, term) in library.terms().iter().enumerate() {
                assert_eq!(theta[(row, col)], term.eval_in(sample, library.gate_thresholds()));
            }
            let predicted = library.predict(&coeffs, sample).unwrap();
            assert!((model.eval_in(sample) - predicted).abs() <= 1e-12 * predicted.abs().max(1.0));
        }
    }

    #[test]
    fn conversion_and_evaluation_errors() {
        let library = Library::polynomial(&["a", "b", "c", "d"], 2, true).unwrap();
        assert_eq!(library.len(), 15);
        assert_eq!(library.to_sparse_model(&[1.0; 15]).unwrap().n_terms, 15);
        let big = Library::polynomial(&["a", "b", "c", "d", "e"], 2, true).unwrap();
        assert_eq!(big.to_sparse_model(&vec![1.0; big.len()]), Err(SindyError::TooManyTerms { found: 21 }));
        assert!(matches!(library.to_sparse_model(&[1.0]), Err(SindyError::DimensionMismatch { .. })));
        let mut huge = vec![0.0; 15];
        huge[3] = 1e300;
        assert!(matches!(library.to_sparse_model(&huge), Err(SindyError::CoefficientOutOfRange { .. })));
        let bad = [[0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0]];
        assert_eq!(library.theta(&bad), Err(SindyError::NonFinite { name: "b".to_owned(), row: 0 }));
        let overflow = [[1e200, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]];
        assert_eq!(library.theta(&overflow), Err(SindyError::NonFinite { name: "a^2".to_owned(), row: 0 }));
        assert!(matches!(library.theta(&[]), Err(SindyError::EmptyData { .. })));
    }
}

//! The errors of the SINDy engine.

use estimator_core::coeffs::{MAX_DEGREE, MAX_TERMS, MAX_VARS};
use thiserror::Error;

/// Everything that can go wrong while building a library, fitting or selecting a model.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SindyError {
    /// A data set, a library or a list of thresholds has no element.
    #[error("empty input: {what}")]
    EmptyData {
        /// What was empty (for example "samples" or "library terms").
        what: &'static str,
    },
    /// Two sizes that must agree do not.
    #[error("dimension mismatch in {what}: expected {expected}, found {found}")]
    DimensionMismatch {
        /// Which pair of sizes disagrees.
        what: &'static str,
        /// The size required by the other operand.
        expected: usize,
        /// The size given.
        found: usize,
    },
    /// A value is NaN or infinite.
    #[error("non-finite value in {name} at row {row}")]
    NonFinite {
        /// The variable, library term or column that holds the value.
        name: String,
        /// The sample (row) index.
        row: usize,
    },
    /// More non-zero terms than the core's sparse model can hold.
    #[error("{found} non-zero terms, the core holds at most {MAX_TERMS}")]
    TooManyTerms {
        /// The number of non-zero terms.
        found: usize,
    },
    /// More variables than a monomial can hold.
    #[error("{found} variables, a monomial holds at most {MAX_VARS}")]
    TooManyVariables {
        /// The number of variables given.
        found: usize,
    },
    /// A polynomial library of a degree the core cannot evaluate.
    #[error("a library of degree {found}: the core evaluates terms of degree at most {MAX_DEGREE}")]
    DegreeTooHigh {
        /// The degree asked for.
        found: u8,
    },
    /// A monomial uses a variable the library does not have, or a degree above the core's limit.
    #[error("invalid term {term}: {reason} (degree at most {MAX_DEGREE})")]
    InvalidTerm {
        /// The term, written with the variable indices (`x0^2*x3`).
        term: String,
        /// Why it is rejected.
        reason: &'static str,
    },
    /// A variable name is not in the library.
    #[error("unknown variable {0:?}")]
    UnknownVariable(String),
    /// A variable name occurs twice or is empty.
    #[error("invalid variable name {0:?} (empty or repeated)")]
    InvalidVariableName(String),
    /// A configuration value is outside its domain.
    #[error("invalid configuration: {0}")]
    InvalidConfig(&'static str),
    /// A coefficient does not fit in an f32.
    #[error("coefficient {value} of term {term} does not fit in an f32")]
    CoefficientOutOfRange {
        /// The term's name.
        term: String,
        /// The coefficient.
        value: f64,
    },
    /// A decomposition of the small least-squares problem did not converge.
    #[error("numerical failure: {0}")]
    NumericalFailure(&'static str),
    /// No sweep point satisfies the selection rule.
    #[error("no model satisfies the selection: {0}")]
    NoEligibleModel(String),
}

//! Sparse identification of nonlinear dynamics (SINDy; Brunton, Proctor & Kutz, PNAS 113(15),
//! 2016) by sequentially thresholded least squares on a thin QR factorisation of the library.
//!
//! The pieces, in the order a fit uses them:
//!
//! - [`Library`]: candidate terms (the core's [`Monomial`](estimator_core::sparse::Monomial)s)
//!   over named variables, the library matrix Theta, and the conversion of a fitted
//!   coefficient vector into the core's [`SparseModel`](estimator_core::sparse::SparseModel);
//! - [`QrProblem`]: `[Theta | y]` reduced once to its p x p triangular factor, so that every
//!   later solve is independent of the number of samples;
//! - [`stls`] / [`stls_dense`]: PySINDy-exact STLS (ridge iterations, support test, unbias)
//!   on the factor or on the full library, with [`Normalisation`] of the columns;
//! - [`sweep`] and [`Sweep::select`]: a threshold sweep deduplicated by support, held-out
//!   scores, the Pareto front and an information-criterion selection.

mod error;
mod library;
mod linalg;
mod qr;
mod select;
mod stls;
mod sweep;
#[cfg(test)]
mod testdata;

pub use error::SindyError;
pub use library::Library;
/// The matrix types of the public API (nalgebra 0.34), re-exported so that callers need no
/// direct dependency on the same version.
pub use nalgebra::{DMatrix, DVector};
pub use qr::{Normalisation, QrProblem};
pub use select::{
    HeldoutScore, InformationCriterion, ScoredPoint, ScoredSweep, SelectionConfig, SelectionRule, pareto_front,
};
pub use stls::{StlsConfig, StlsFit, stls, stls_dense};
pub use sweep::{Sweep, SweepPoint, log_thresholds, sweep};

//! Fitting every block of the estimator on a dataset's training part.

pub mod actuator;
pub mod card;
pub mod coupling;
pub mod dare;
pub mod egk;
pub mod envelope;
mod error;
pub mod fusion;
pub mod heldout;
pub mod pipeline;
pub mod plant;
pub mod pressure;
pub mod prior;
pub mod signals;
pub mod sparse_fit;
pub mod split;
#[cfg(test)]
mod test_noise;

pub use error::FitError;

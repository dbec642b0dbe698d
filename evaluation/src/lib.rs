//! The paper's analysis of a model and of raw recordings.
//!
//! - [`evaluate`]: a model on the held-out runs: the paper's tables and figures, bootstrap
//!   intervals, the noise-robustness test, the information of each pressure channel;
//! - [`analysis`]: the superposition table on raw recordings, before any model;
//! - [`fault_study`]: how the estimator copes with one faulty sensor on held-out data.

pub mod analysis;
pub mod evaluate;
pub mod fault_study;

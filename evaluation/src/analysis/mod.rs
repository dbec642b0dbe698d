//! The paper's analyses of a dataset.

pub mod superposition;

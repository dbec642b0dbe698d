//! Reliability: how the estimator copes with faulty sensors, and how the loaders cope
//! with bad files.
//!
//! - [`faults`]: the fault study on held-out data (detection latency, error with one fault);
//! - [`fuzz`]: a seeded, structure-aware mutation fuzzer for every loader (dataset CSV and
//!   manifest, coefficient blob, scenario files);
//! - [`soak`]: a long run of the estimator on noisy input with random faults.

pub mod faults;
pub mod fuzz;
pub mod soak;

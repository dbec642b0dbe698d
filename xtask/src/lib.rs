//! The developer tasks' checks that are more than a command: the loaders' fuzzer and the
//! estimator's soak run (`cargo xtask fuzz`, `cargo xtask soak`). They live here, not in the
//! user's tools, because they check this code rather than a user's data; the cargo-fuzz targets
//! in `fuzz/` call the same entry points.
//!
//! - [`fuzz`]: a seeded, structure-aware mutation fuzzer for every loader;
//! - [`soak`]: a long run of the estimator on noisy input with random faults.

pub mod fuzz;
pub mod soak;

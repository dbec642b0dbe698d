//! Host tools: fitting, code generation, replay, evaluation, diagnosis and reports.
//!
//! The library holds everything the `host-tools` binary does, so that the integration tests
//! call the same code the command line runs.

pub mod analysis;

//! Host tools: fitting, code generation, replay, evaluation, diagnosis and reports.
//!
//! The library holds everything the `host-tools` binary does, so that the integration tests
//! call the same code the command line runs.

pub mod analysis;
pub mod codegen;
pub mod evaluate;
pub mod fit;
pub mod model;
pub mod plot;
pub mod qemu;
pub mod replay;
pub mod report;
pub mod sil;
pub mod sindy;

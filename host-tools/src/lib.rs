//! Host tools: fitting, code generation, replay, evaluation, SIL and QEMU runs, reports.
//!
//! The library holds everything the `host-tools` binary does, so that the integration tests
//! call the same code the command line runs (`docs/spec/cli.md` is the command line's
//! contract). f64 throughout; the estimator itself (estimator-core, f32) is what replays,
//! evaluations and the SIL harness run, so the numbers they report are the flying code's.
//!
//! - [`sindy`]: sparse regression (STLS on a thin QR of the library, threshold sweeps, model
//!   selection), checked against PySINDy;
//! - [`fit`]: every block of the estimator from a dataset's training part, and the model card;
//! - [`codegen`]: the coefficient set as const tables in estimator-core;
//! - [`replay`], [`evaluate`], [`sil`], [`qemu`]: running the estimator on recordings, the
//!   paper's analysis, the closed loop, the firmware in QEMU;
//! - [`report`], [`plot`]: report folders (Markdown, HTML, SVG, JSON);
//! - [`model`]: loading `--model` (a model folder or its blob) or the built-in tables;
//! - [`analysis`]: the paper's superposition table on raw recordings;
//! - [`reliability`]: the sensor-fault study, the loaders' fuzzer and the soak run;
//! - [`command`]: every subcommand as a function returning a typed summary.

pub mod analysis;
pub mod codegen;
pub mod command;
pub mod diagnose;
pub mod digest;
pub mod evaluate;
pub mod fit;
pub mod hil;
pub mod model;
pub mod plot;
pub mod progress;
pub mod qemu;
pub mod reliability;
pub mod replay;
pub mod report;
pub mod sil;
pub mod sindy;
pub mod stats;
pub mod validate;

//! The model: every coefficient of the estimator fitted from a dataset, the model folder it is
//! written to, the const tables generated from it, and the replay of recordings through the
//! estimator that flies.
//!
//! f64 throughout the fits; the estimator itself (estimator-core, f32) is what the replay runs,
//! so the numbers the evaluation and the diagnosis report are the flying code's.
//!
//! - [`fit`]: every block of the estimator from a dataset's training part, and the model card;
//! - [`model`]: loading `--model` (a model folder or its blob) or the built-in tables;
//! - [`codegen`]: the coefficient set as const tables in estimator-core;
//! - [`replay`]: the estimator stepped over a recording, as the firmware steps it;
//! - [`digest`]: content hashes.

pub mod codegen;
pub mod digest;
pub mod fit;
pub mod model;
pub mod replay;

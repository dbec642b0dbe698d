//! The sim-to-real gap: where a model and a recording disagree, which effect causes it, and how
//! far the gap shrinks once that effect is added (`docs/spec/diagnosis.md` is the output's
//! contract); and the blind validation that checks the diagnosis on campaigns whose truth it
//! does not see.
//!
//! - [`diagnose`]: the residual ledger, the candidate families, the sensor findings and the
//!   verdict;
//! - [`validate`]: blind campaigns (this project's tunnel or another program's), sealed truth,
//!   scoring.

pub mod diagnose;
pub mod validate;

//! The workspace's integration tests: one binary, one module per topic.
//!
//! Two tiers. Plain `cargo test` runs the fast one, a few minutes on a laptop. The slow tier
//! (QEMU, the soak, full campaigns and full diagnoses) is marked `#[ignore = "slow tier ..."]`
//! and runs from `./ci.sh test` (`cargo test -- --include-ignored`); run one slow test with
//! `cargo test -p tests -- --ignored NAME`.
#![allow(missing_docs)]

// Data several topics share, made once per binary: the default campaign.
mod fixture;

// Reading and writing the dataset format (docs/spec/dataset-format.md): round trips and
// every error class.
mod dataset;

// The synthetic wind tunnel: determinism, Table 1 on the default campaign, effects.
mod tunnel;

// The SINDy engine against PySINDy fixtures, and the threshold sweep's model selection.
mod sindy;

// Fitting and code generation: committed default tables, reproducibility, missing runs.
mod fit;

// The command line's library functions on a small campaign, checked on their summaries.
mod command;

// Replay and evaluation: per-run estimates, report folders, missing kinds of run.
mod evaluate;

// The SIL harness: the stepped tunnel against simulate_run, closed-loop reductions.
mod sil;

// The firmware in QEMU (STM32F405) against the host replay: same outputs, instruction counts.
mod firmware;

// The sim-to-real gap diagnosis: contract JSON, named effects, clean recordings, a blind slice.
mod diagnose;

// Reliability: sensor faults in replays and the SIL loop, the fault study's goals, the loaders'
// fuzzer, the soak, and folders that stay complete or absent when the writer is killed.
mod reliability;

// The tree on its own: the contracts in docs/spec/, no path outside the repository.
mod docs;

// How the workspace builds: the Python extension reuses the test build's crates.
mod workspace;

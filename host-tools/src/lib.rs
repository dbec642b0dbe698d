//! The `host-tools` command line as a library: every subcommand as a function returning a typed
//! summary ([`command`]), so that the integration tests and the Python package call the same
//! code the command line runs (`docs/spec/cli.md` is the command line's contract), and the
//! progress bar the binary shows ([`progress`]).
//!
//! The work itself lives in the library crates below this one:
//!
//! - `sindy`: sparse regression (STLS on a thin QR of the library, threshold sweeps, model
//!   selection), checked against PySINDy;
//! - `stats`: summary statistics, one definition each;
//! - `reports`: report folders (Markdown, HTML, SVG, JSON);
//! - `model-fit`: every block of the estimator fitted from a dataset, the model folder and card,
//!   the generated tables, the replay;
//! - `evaluation`: the paper's analysis, the superposition table, the sensor-fault study;
//! - `diagnosis`: the sim-to-real gap diagnosis and its blind validation;
//! - `rigs` (feature `rigs`, on by default): the firmware in QEMU, the hardware-in-the-loop run
//!   and the SIL report. The Python package builds without it.

pub mod command;
pub mod progress;

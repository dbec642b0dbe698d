//! The command line: its subcommands (`docs/spec/cli.md`). Each subcommand's flags are the
//! `clap` struct its library function takes ([`host_tools::command`]).

use clap::{Parser, Subcommand};
use host_tools::command::data::{SimulateArgs, SuperpositionArgs};
use host_tools::command::diagnosis::{DiagnoseArgs, ValidateArgs};
use host_tools::command::firmware::{HilArgs, QemuReplayArgs, SilArgs};
use host_tools::command::model::{CodegenArgs, EvaluateArgs, FitArgs, ReplayArgs};
use host_tools::command::reliability::FaultsArgs;

#[derive(Debug, Parser)]
#[command(
    name = "host-tools",
    version,
    about = "Roll-moment estimator tools for a rolling delta wing with trailing-edge blowing"
)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Debug, Subcommand)]
pub(crate) enum Command {
    /// Record a dataset with the synthetic wind tunnel (default: the paper's campaign, no effects).
    Simulate(SimulateArgs),
    /// Print the paper's Table 1 (validity of superposition) for a dataset.
    Superposition(SuperpositionArgs),
    /// Fit every coefficient of the estimator on a dataset's training part; write a model folder.
    Fit(FitArgs),
    /// Write a model's coefficient set as const tables into estimator-core (or check them).
    Codegen(CodegenArgs),
    /// Run the estimator (the code that flies) over a dataset; write every stage's estimates.
    Replay(ReplayArgs),
    /// The paper's tables and figures on held-out data, as a report folder.
    Evaluate(EvaluateArgs),
    /// Closed-loop SIL comparison of the controller scenarios against the synthetic tunnel.
    Sil(SilArgs),
    /// Build the firmware, replay one run in QEMU (STM32F405) and compare with the host replay.
    QemuReplay(QemuReplayArgs),
    /// Hardware-in-the-loop: the firmware's 1 kHz loop in QEMU, fed runs over its serial link.
    Hil(HilArgs),
    /// Sim-to-real gap diagnosis: where the gap lies, which effect causes it, how far it shrinks.
    Diagnose(DiagnoseArgs),
    /// Blind campaign: seeded cases with known effects, diagnosed without the answer, scored.
    ValidateDiagnosis(ValidateArgs),
    /// Inject sensor faults into a dataset's held-out part: detection latency and error per fault.
    Faults(FaultsArgs),
}

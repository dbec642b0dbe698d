//! The `host-tools` command line: one binary whose subcommands follow the user's workflow
//! (`shared/spec/cli.md`).

mod commands;
mod flags;

use std::process::ExitCode;

use clap::Parser;
use commands::{data, diagnosis, firmware, model, reliability};
use flags::{Cli, Command};

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Simulate(args) => data::simulate(args),
        Command::Superposition(args) => data::superposition(args),
        Command::Fit(args) => model::fit(args),
        Command::Codegen(args) => model::codegen(args),
        Command::Replay(args) => model::replay(args),
        Command::Evaluate(args) => model::evaluate(args),
        Command::Sil(args) => firmware::sil(args),
        Command::QemuReplay(args) => firmware::qemu_replay(args),
        Command::Hil(args) => firmware::hil(args),
        Command::Diagnose(args) => diagnosis::diagnose(args),
        Command::ValidateDiagnosis(args) => diagnosis::validate_diagnosis(args),
        Command::Faults(args) => reliability::faults(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

//! The `host-tools` command line: one binary whose subcommands follow the user's workflow
//! (`docs/spec/cli.md`). It parses ([`flags`]) and dispatches to the library's commands
//! ([`host_tools::command`]), which return typed summaries; it prints them.

mod flags;

use std::process::ExitCode;

use clap::Parser;
use flags::{Cli, Command};
use host_tools::command::{data, diagnosis, firmware, model, reliability};
use host_tools::progress::Terminal;

fn main() -> ExitCode {
    match run(Cli::parse().command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

/// Runs one command. A command that answers a question prints its summary on stdout; one that
/// only writes files (`simulate`, `codegen`, `replay`) says what it wrote on stderr, where
/// timing, notes and warnings go for all.
fn run(command: Command) -> anyhow::Result<()> {
    let progress = Terminal::new();
    match command {
        Command::Simulate(args) => {
            let summary = data::simulate(&args, &progress)?;
            drop(progress);
            eprint!("{summary}");
        }
        Command::Superposition(args) => {
            let summary = data::superposition(&args)?;
            if args.json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                print!("{summary}");
            }
        }
        Command::Fit(args) => {
            let summary = model::fit(&args, &progress)?;
            drop(progress);
            print!("{summary}");
            eprintln!("wrote {} in {:.1} s", summary.out.display(), summary.elapsed_s);
        }
        Command::Codegen(args) => eprint!("{}", model::codegen(&args)?),
        Command::Replay(args) => {
            let summary = model::replay(&args, &progress)?;
            drop(progress);
            eprint!("{summary}");
        }
        Command::Evaluate(args) => {
            let summary = model::evaluate(&args, &progress)?;
            drop(progress);
            for warning in &summary.warnings {
                eprintln!("warning: {warning}");
            }
            print!("{summary}");
            eprintln!("evaluated in {:.1} s", summary.elapsed_s);
        }
        Command::Sil(args) => {
            let summary = firmware::sil(&args, &progress)?;
            drop(progress);
            print!("{summary}");
            eprintln!("SIL in {:.1} s", summary.elapsed_s);
        }
        Command::QemuReplay(args) => {
            let summary = firmware::qemu_replay(&args, &progress)?;
            drop(progress);
            print!("{summary}");
        }
        Command::Hil(args) => {
            let summary = firmware::hil(&args, &progress)?;
            drop(progress);
            print!("{summary}");
        }
        Command::Diagnose(args) => {
            let summary = diagnosis::diagnose(&args, &progress)?;
            drop(progress);
            if summary.signature == diagnosis::SignatureSource::BuiltIn {
                eprintln!(
                    "note: no diagnosis signature of this sim; the built-in model's (default campaign) sets the floor"
                );
            }
            print!("{summary}");
        }
        Command::ValidateDiagnosis(args) => {
            let summary = diagnosis::validate_diagnosis(&args, &progress)?;
            drop(progress);
            print!("{summary}");
        }
        Command::Faults(args) => {
            let summary = reliability::faults(&args, &progress)?;
            drop(progress);
            print!("{summary}");
            eprintln!("fault study in {:.1} s", summary.elapsed_s);
        }
    }
    Ok(())
}

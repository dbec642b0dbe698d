//! The `host-tools` command line: one binary whose subcommands follow the user's workflow
//! (`shared/spec/cli.md`).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use clap::{Parser, Subcommand};
use firmware_sim::campaign::Scenario;
use indicatif::{ProgressBar, ProgressStyle};

#[derive(Debug, Parser)]
#[command(
    name = "host-tools",
    version,
    about = "Roll-moment estimator tools for a rolling delta wing with trailing-edge blowing"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Record a dataset with the synthetic wind tunnel (default: the paper's campaign, no effects).
    Simulate(SimulateArgs),
    /// Print the paper's Table 1 (validity of superposition) for a dataset.
    Superposition(SuperpositionArgs),
}

#[derive(Debug, clap::Args)]
struct SimulateArgs {
    /// Dataset folder to write (replaced atomically if it exists).
    #[arg(long)]
    out: PathBuf,
    /// Scenario file (TOML); keys it does not set keep the paper's values.
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Master seed (overrides the scenario's).
    #[arg(long)]
    seed: Option<u64>,
    /// Duration of every run, s (overrides the scenario's).
    #[arg(long = "duration-s")]
    duration_s: Option<f64>,
    /// Switch an effect on: NAME or NAME:key=value,... (repeatable), e.g.
    /// `--effect actuator_delay:delay_s=0.03`.
    #[arg(long = "effect", value_name = "EFFECT")]
    effects: Vec<String>,
}

#[derive(Debug, clap::Args)]
struct SuperpositionArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    data: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Simulate(args) => simulate(args),
        Command::Superposition(args) => superposition(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

/// `simulate`: scenario -> synthetic tunnel -> dataset folder.
fn simulate(args: SimulateArgs) -> anyhow::Result<()> {
    let mut scenario = match &args.scenario {
        Some(path) => Scenario::from_file(path)?,
        None => Scenario::default(),
    };
    if let Some(seed) = args.seed {
        scenario.seed = seed;
    }
    if let Some(duration_s) = args.duration_s {
        scenario.duration_s = duration_s;
    }
    for effect in &args.effects {
        scenario.apply_effect_arg(effect)?;
    }
    scenario.validate()?;
    let started = Instant::now();
    let n_runs = scenario.alphas_deg.len() * scenario.kinds.len();
    let progress = progress_bar(n_runs as u64, "simulating runs");
    let dataset = scenario.simulate(&|| progress.inc(1))?;
    progress.set_message("writing dataset");
    firmware_sim::dataset::write_dataset(&args.out, &dataset)
        .with_context(|| format!("writing the dataset to {}", args.out.display()))?;
    progress.finish_and_clear();
    eprintln!(
        "wrote {} runs to {} in {:.1} s",
        dataset.runs.len(),
        args.out.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `superposition`: the paper's Table 1 for a dataset.
fn superposition(args: SuperpositionArgs) -> anyhow::Result<()> {
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let rows = host_tools::analysis::superposition::superposition_table(&dataset)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!("Table 1: validity of superposition, Delta C_l = C_l,RollAFC - C_l,Roll - C_l,AFC");
    println!(
        "{:>9}  {:>22}  {:>22}  {:>12}  {:>12}",
        "alpha_deg", "sigma(dCl)/mean(ClRA)", "sigma(dCl)/sigma(ClRA)", "sigma(dCl)", "mean(ClRA)"
    );
    for row in rows {
        println!(
            "{:>9.1}  {:>21.1}%  {:>21.1}%  {:>12.3e}  {:>12.3e}",
            row.alpha_deg,
            100.0 * row.ratio_to_mean,
            100.0 * row.ratio_to_std,
            row.delta_std,
            row.rollact_mean
        );
    }
    Ok(())
}

fn progress_bar(length: u64, message: &'static str) -> ProgressBar {
    let bar = ProgressBar::new(length);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg} [{bar:30}] {pos}/{len} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(message);
    bar
}

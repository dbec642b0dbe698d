//! Developer tasks of this workspace, run as `cargo xtask TASK` (the alias in
//! `.cargo/config.toml`; rust-analyzer's `xtask` layout): they check the code, not a user's
//! data, so they are not in the user's `host-tools` (whose commands follow
//! `shared/spec/cli.md`).
//!
//! - `codegen [--check]`: the committed default model's const tables in estimator-core
//!   (`host-tools codegen --model models/default`, the contract's command, does the same for any
//!   model);
//! - `fuzz`: every loader against mutated inputs; fails on any finding;
//! - `soak`: the estimator on a long noisy, faulty input; fails if an estimate leaves its bound.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use host_tools::progress::{progress_bar, spinner};

/// Developer tasks: code generation check, fuzzing, soak.
#[derive(Debug, Parser)]
#[command(name = "cargo xtask", version, about)]
struct Cli {
    #[command(subcommand)]
    task: Task,
}

#[derive(Debug, Subcommand)]
enum Task {
    /// Write (or with --check compare) the default model's const tables in estimator-core
    Codegen(CodegenArgs),
    /// Fuzz every loader (or the chosen ones) with mutated inputs; fails on any finding
    Fuzz(FuzzArgs),
    /// Step the estimator a long time on noisy input with random faults; fails if an estimate leaves its bound
    Soak(SoakArgs),
}

#[derive(Debug, clap::Args)]
struct CodegenArgs {
    /// Only compare with the committed file; fail if it is stale.
    #[arg(long)]
    check: bool,
}

#[derive(Debug, clap::Args)]
struct FuzzArgs {
    /// Loader to fuzz (repeatable): dataset-csv, manifest, blob, scenario; default: all.
    #[arg(long = "target")]
    targets: Vec<host_tools::reliability::fuzz::Target>,
    /// Mutated inputs per target.
    #[arg(long, default_value_t = 1_000_000)]
    execs: u64,
    /// Seed of the mutations.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// An input slower than this is a finding, ms.
    #[arg(long = "time-limit-ms", default_value_t = 1000)]
    time_limit_ms: u64,
    /// Only write the valid seed inputs of every target into DIR/TARGET/ (the corpus for the
    /// cargo-fuzz targets in fuzz/), then stop.
    #[arg(long = "write-seeds", value_name = "DIR")]
    write_seeds: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
struct SoakArgs {
    /// Steps in all.
    #[arg(long, default_value_t = 100_000_000)]
    steps: u64,
    /// Seed of the input, the noise and the faults.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Independent runs the steps are split into, run in parallel (default: one per core).
    #[arg(long)]
    streams: Option<u64>,
    /// Model folder or model.bin (default: the built-in tables).
    #[arg(long)]
    model: Option<PathBuf>,
}

fn main() -> ExitCode {
    let result = match Cli::parse().task {
        Task::Codegen(args) => codegen(&args),
        Task::Fuzz(args) => fuzz(args),
        Task::Soak(args) => soak(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

/// `codegen`: the committed default model -> `estimator-core/src/coeffs/generated.rs`.
fn codegen(args: &CodegenArgs) -> anyhow::Result<()> {
    use host_tools::codegen::{DEFAULT_PROVENANCE, check, default_model, default_target, render, write};
    let model = default_model();
    let (set, _) = host_tools::model::load(Some(&model))?;
    let text = render(&set, DEFAULT_PROVENANCE)?;
    let target = default_target();
    if args.check {
        check(&target, &text, &model.display().to_string())?;
        eprintln!("{} is up to date with {}", target.display(), model.display());
    } else {
        write(&target, &text)?;
        eprintln!("wrote {}", target.display());
    }
    Ok(())
}

/// `fuzz`: every loader (or the chosen ones) against mutated inputs; fails on any finding.
fn fuzz(args: FuzzArgs) -> anyhow::Result<()> {
    use host_tools::reliability::fuzz::{FuzzConfig, Target, fuzz};
    let targets = if args.targets.is_empty() { Target::ALL.to_vec() } else { args.targets };
    if let Some(dir) = &args.write_seeds {
        return write_seeds(dir, &targets);
    }
    let mut n_findings = 0;
    for target in targets {
        let config = FuzzConfig {
            target,
            execs: args.execs,
            seed: args.seed,
            time_limit: std::time::Duration::from_millis(args.time_limit_ms),
        };
        let progress = progress_bar(args.execs, "fuzzing");
        let outcome = fuzz(&config, &|done| progress.set_position(done));
        progress.finish_and_clear();
        println!(
            "{}: {} executions in {:.1} s ({:.0}/s), seed {}: {} accepted, {} rejected with {} error kinds, slowest {} us, {} findings",
            target.name(),
            outcome.execs,
            outcome.elapsed_s,
            outcome.execs as f64 / outcome.elapsed_s.max(1e-9),
            outcome.seed,
            outcome.accepted,
            outcome.rejected,
            outcome.errors.len(),
            outcome.slowest_exec_us,
            outcome.n_findings
        );
        for finding in &outcome.findings {
            let shown: String = finding.input.chars().take(300).collect();
            println!("  finding at execution {}: {}\n    input (start): {shown:?}", finding.exec_idx, finding.what);
        }
        n_findings += outcome.n_findings;
    }
    anyhow::ensure!(n_findings == 0, "{n_findings} findings");
    Ok(())
}

/// Writes the seed inputs of `targets` into `dir/TARGET/seed-N` (complete or absent; libFuzzer
/// adds its own inputs to these folders later, and a new `--write-seeds` replaces them).
fn write_seeds(dir: &std::path::Path, targets: &[host_tools::reliability::fuzz::Target]) -> anyhow::Result<()> {
    const MARKER: &str = "SEEDS.md";
    firmware_sim::atomic::write_folder::<anyhow::Error>(dir, MARKER, |tmp| {
        std::fs::write(
            tmp.join(MARKER),
            "Seed inputs of the loaders' fuzz targets, by `cargo xtask fuzz --write-seeds`.\n",
        )?;
        for &target in targets {
            let target_dir = tmp.join(target.name());
            std::fs::create_dir(&target_dir)?;
            for (idx, seed) in host_tools::reliability::fuzz::seeds(target).iter().enumerate() {
                std::fs::write(target_dir.join(format!("seed-{idx}")), seed)?;
            }
        }
        Ok(())
    })?;
    eprintln!("wrote the seeds of {} targets into {}", targets.len(), dir.display());
    Ok(())
}

/// `soak`: a long run on noisy input with random faults; fails if an estimate leaves its bound.
fn soak(args: SoakArgs) -> anyhow::Result<()> {
    use host_tools::reliability::soak::{RECOVERED_ERROR_BOUND, RECOVERY_STEPS, SoakConfig, soak};
    let (set, source) = host_tools::model::load(args.model.as_deref())?;
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get) as u64;
    let config = SoakConfig { steps: args.steps, seed: args.seed, streams: args.streams.unwrap_or(cores) };
    let spinner = spinner(format!("soaking {} steps", args.steps));
    let outcome = soak(&set, &config);
    spinner.finish_and_clear();
    println!(
        "soak, model {source}: {} steps in {} streams, seed {}, {:.1} s ({:.2e} steps/s); {} fault episodes; \
         non-finite steps {}; worst |C_l - reference| {:.3e}, {:.3e} on the {} steps {RECOVERY_STEPS} or more after \
         a fault (bound {RECOVERED_ERROR_BOUND:.0e}); worst |C_l| {:.3e}; state resets {}",
        outcome.steps,
        outcome.streams,
        outcome.seed,
        outcome.elapsed_s,
        outcome.steps as f64 / outcome.elapsed_s.max(1e-9),
        outcome.fault_episodes,
        outcome.non_finite_steps,
        outcome.worst_error,
        outcome.worst_recovered_error,
        outcome.recovered_steps,
        outcome.worst_abs_cl,
        outcome.state_resets
    );
    let [low, high] = outcome.cl_bounds;
    println!(
        "envelope: C_l bounds [{low:.4e}, {high:.4e}] (fitted range and margin); worst |C_l| {:.3e} (without the \
         envelope {:.3e}); steps limited {}, flagged ESTIMATE_LIMITED {}, limited but not flagged {}, beyond the \
         envelope {}",
        outcome.worst_abs_cl,
        outcome.worst_abs_cl_unbounded,
        outcome.limited_steps,
        outcome.flagged_steps,
        outcome.unflagged_limited_steps,
        outcome.beyond_envelope_steps
    );
    anyhow::ensure!(
        outcome.passed(),
        "the soak failed: an estimate was not finite, stayed off the reference after a fault, left the envelope, or was \
         limited unflagged"
    );
    Ok(())
}

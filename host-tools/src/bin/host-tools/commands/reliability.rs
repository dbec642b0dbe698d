//! `faults`, `fuzz` and `soak`: the estimator under faulty and hostile input.

use std::time::Instant;

use anyhow::Context;

use crate::flags::*;
use crate::progress::*;

/// `faults`: the sensor-fault study on held-out data, as a report folder.
pub(crate) fn faults(args: FaultsArgs) -> anyhow::Result<()> {
    use host_tools::reliability::faults::{COLUMNS, StudyConfig, fault_study, study_report, table_rows};
    let started = Instant::now();
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let (set, source) = host_tools::model::load(args.model.as_deref())?;
    let split = host_tools::fit::split::Split::with_holdout(args.holdout_fraction);
    let config = StudyConfig { split, seed: args.seed, ..StudyConfig::default() };
    let spinner = spinner("injecting faults".into());
    let study = fault_study(&dataset, &set, &config)?;
    let report = study_report(&study, &format!("Data `{}`, model {source}", args.data.display()));
    let json =
        serde_json::json!({ "data": args.data.display().to_string(), "model": source.to_string(), "study": study });
    host_tools::report::write_report(&args.report, &report, "faults.json", &json)
        .with_context(|| format!("writing the report {}", args.report.display()))?;
    spinner.finish_and_clear();
    println!("fault-free held-out RMS: C_l {:.3e}, pressure path {:.3e}", study.clean_rms, study.clean_pressure_rms);
    println!("{}", COLUMNS.join(" | "));
    for row in table_rows(&study) {
        println!("{}", row.join(" | "));
    }
    println!("report: {}", args.report.join("report.html").display());
    eprintln!("fault study in {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}

/// `fuzz`: every loader (or the chosen ones) against mutated inputs; fails on any finding.
pub(crate) fn fuzz(args: FuzzArgs) -> anyhow::Result<()> {
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
pub(crate) fn write_seeds(
    dir: &std::path::Path,
    targets: &[host_tools::reliability::fuzz::Target],
) -> anyhow::Result<()> {
    const MARKER: &str = "SEEDS.md";
    firmware_sim::atomic::write_folder::<anyhow::Error>(dir, MARKER, |tmp| {
        std::fs::write(
            tmp.join(MARKER),
            "Seed inputs of the loaders' fuzz targets, by `host-tools fuzz --write-seeds`.\n",
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
pub(crate) fn soak(args: SoakArgs) -> anyhow::Result<()> {
    use host_tools::reliability::soak::{ERROR_BOUND, SoakConfig, soak};
    let (set, source) = host_tools::model::load(args.model.as_deref())?;
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get) as u64;
    let config = SoakConfig { steps: args.steps, seed: args.seed, streams: args.streams.unwrap_or(cores) };
    let spinner = spinner(format!("soaking {} steps", args.steps));
    let outcome = soak(&set, &config);
    spinner.finish_and_clear();
    println!(
        "soak, model {source}: {} steps in {} streams, seed {}, {:.1} s ({:.2e} steps/s); {} fault episodes; \
         non-finite steps {}; worst |C_l - reference| {:.3e} (bound {ERROR_BOUND}); worst |C_l| {:.3e}; state resets {}",
        outcome.steps,
        outcome.streams,
        outcome.seed,
        outcome.elapsed_s,
        outcome.steps as f64 / outcome.elapsed_s.max(1e-9),
        outcome.fault_episodes,
        outcome.non_finite_steps,
        outcome.worst_error,
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
        "the soak failed: an estimate was not finite, left the bound or the envelope, or was limited unflagged"
    );
    Ok(())
}

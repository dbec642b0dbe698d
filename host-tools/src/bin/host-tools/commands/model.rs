//! `fit`, `codegen`, `replay` and `evaluate`: the model from a dataset to the flying tables and
//! back over the data.

use std::time::Instant;

use anyhow::Context;
use indicatif::ProgressBar;

use crate::flags::*;
use host_tools::progress::*;

/// `fit`: dataset -> model folder.
pub(crate) fn fit(args: FitArgs) -> anyhow::Result<()> {
    if !(0.0..1.0).contains(&args.holdout_fraction) {
        anyhow::bail!("--holdout-fraction must be in [0, 1), found {}", args.holdout_fraction);
    }
    let started = Instant::now();
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let config = host_tools::fit::pipeline::FitConfig {
        split: host_tools::fit::split::Split::with_holdout(args.holdout_fraction),
        ..Default::default()
    };
    let spinner = ProgressBar::new_spinner();
    spinner.enable_steady_tick(std::time::Duration::from_millis(120));
    let outcome = host_tools::fit::pipeline::fit_dataset(&dataset, &config, &|stage| {
        spinner.set_message(format!("fitting: {stage}"))
    })
    .with_context(|| format!("fitting {}", args.data.display()))?;
    spinner.set_message("fitting: the model's diagnosis signature on its held-out data");
    let signature = host_tools::diagnose::signature(&dataset, &outcome.set, config.split)
        .with_context(|| format!("the diagnosis signature on {}", args.data.display()))?;
    spinner.set_message("writing the model folder");
    let described = format!("{} (seed {})", args.data.display(), args.seed);
    host_tools::fit::card::write_model_folder(&args.out, &outcome, &described, Some(&signature))?;
    spinner.finish_and_clear();
    print_heldout(&outcome.report);
    eprintln!("wrote {} in {:.1} s", args.out.display(), started.elapsed().as_secs_f64());
    Ok(())
}

/// The held-out table of a fit on stdout.
pub(crate) fn print_heldout(report: &host_tools::fit::pipeline::FitReport) {
    use host_tools::fit::heldout::HeldoutAlpha;
    println!("held-out RMS of C_l (replay through the fitted core; {})", report.split);
    let line = |cells: &[&str]| cells.iter().map(|cell| format!("{cell:>13}")).collect::<Vec<_>>().join(" ");
    println!("{}", line(&HeldoutAlpha::COLUMNS));
    for row in &report.heldout.per_alpha {
        let cells = row.cells();
        println!("{}", line(&cells.each_ref().map(String::as_str)));
    }
}

/// `codegen`: model -> const tables in estimator-core (or a check of them).
pub(crate) fn codegen(args: CodegenArgs) -> anyhow::Result<()> {
    let (set, source) = host_tools::model::load(Some(&args.model))?;
    let is_default = |path: &std::path::Path| {
        let canonical = |p: &std::path::Path| std::fs::canonicalize(p).ok();
        let folder = if path.is_dir() { path.to_path_buf() } else { path.parent().unwrap_or(path).to_path_buf() };
        canonical(&folder).is_some() && canonical(&folder) == canonical(&host_tools::codegen::default_model())
    };
    let provenance = args.provenance.unwrap_or_else(|| {
        if is_default(&args.model) {
            host_tools::codegen::DEFAULT_PROVENANCE.to_owned()
        } else {
            format!("the fit in {source}")
        }
    });
    let text = host_tools::codegen::render(&set, &provenance)?;
    let target = args.out.unwrap_or_else(host_tools::codegen::default_target);
    if args.check {
        host_tools::codegen::check(&target, &text, &args.model.display().to_string())?;
        eprintln!("{} is up to date with {}", target.display(), args.model.display());
    } else {
        host_tools::codegen::write(&target, &text)?;
        eprintln!("wrote {}", target.display());
    }
    Ok(())
}

/// `replay`: dataset + model -> per-run estimate CSVs.
pub(crate) fn replay(args: ReplayArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let (set, source) = host_tools::model::load(args.model.as_deref())?;
    let spinner = spinner(format!("replaying {} runs", dataset.runs.len()));
    let described = format!("data {}, model {source}", args.data.display());
    let n_runs = host_tools::replay::write_replay_with_faults(
        &args.out,
        &dataset,
        &set,
        &described,
        &args.faults,
        args.fault_seed,
    )?;
    spinner.finish_and_clear();
    eprintln!("replayed {n_runs} runs into {} in {:.1} s", args.out.display(), started.elapsed().as_secs_f64());
    Ok(())
}

/// `evaluate`: the paper's analysis on held-out data, as a report folder.
pub(crate) fn evaluate(args: EvaluateArgs) -> anyhow::Result<()> {
    use host_tools::evaluate::{EvaluationConfig, Replayed, evaluate, evaluation_report, figures, with_balance_noise};
    let started = Instant::now();
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let (set, source) = host_tools::model::load(args.model.as_deref())?;
    let split = host_tools::fit::split::Split::with_holdout(args.holdout_fraction);
    let config = EvaluationConfig { split, seed: args.seed, ..EvaluationConfig::default() };
    let spinner = spinner("evaluating: replay, tables, noise sweep".into());
    let (evaluation, replayed) = evaluate(&dataset, &set, &config)?;
    spinner.set_message("evaluating: figures");
    let sigma = config.figure_noise;
    let noisy = with_balance_noise(&dataset, sigma, args.seed);
    let fit_config = host_tools::fit::pipeline::FitConfig { split, ..Default::default() };
    let noisy_figure = match host_tools::fit::pipeline::refit_coupling(&noisy, &set, &fit_config) {
        Ok(refitted) => Some(Replayed::new(&noisy, &refitted)),
        Err(error) => {
            eprintln!(
                "warning: the figure with balance noise {sigma} is left out: refitting the coupling failed: {error}"
            );
            None
        }
    };
    let figures = figures(&dataset, &replayed, &split, &evaluation, noisy_figure.as_ref().map(|r| (&noisy, r, sigma)));
    let described = format!("Data `{}`, model {source}.", args.data.display());
    let report = evaluation_report(&evaluation, figures, &described);
    let json = serde_json::json!({ "data": args.data.display().to_string(), "model": source.to_string(), "evaluation": evaluation });
    host_tools::report::write_report(&args.report, &report, "evaluation.json", &json)
        .with_context(|| format!("writing the report {}", args.report.display()))?;
    spinner.finish_and_clear();
    print_evaluation(&evaluation);
    println!("report: {}", args.report.join("report.html").display());
    eprintln!("evaluated in {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}

/// The evaluation's tables on stdout.
pub(crate) fn print_evaluation(evaluation: &host_tools::evaluate::Evaluation) {
    println!("Table 1 (held-out): alpha, sigma(dCl)/mean(ClRA), sigma(dCl)/sigma(ClRA)");
    for row in &evaluation.table1 {
        println!("  {:>5.1}  {:>6.1} %  {:>6.1} %", row.alpha_deg, 100.0 * row.ratio_to_mean, 100.0 * row.ratio_to_std);
    }
    println!(
        "Tables 2 and 3 (held-out): alpha, E_SINDy/E_lin [95 % interval], corr linear, corr operator, change [95 % interval]"
    );
    for row in &evaluation.coupling {
        println!(
            "  {:>5.1}  {:>6.3} {:<14}  {:>9.6}  {:>9.6}  {:+.2e} {}",
            row.alpha_deg,
            row.ratio,
            bracketed(row.ratio_ci95, |v| format!("{v:.3}")),
            row.corr_linear,
            row.corr_operator,
            row.corr_operator - row.corr_linear,
            bracketed(row.corr_change_ci95, |v| format!("{v:+.2e}"))
        );
    }
    println!("Blocks (held-out): alpha, block, RMS, correlation, RMS / balance noise");
    for row in &evaluation.blocks {
        println!(
            "  {:>5.1}  {:<9} {:>10.3e}  {:>7.4}  {:>5.2}",
            row.alpha_deg, row.block, row.rms, row.correlation, row.rms_over_noise
        );
    }
    println!(
        "Fusion (roll runs, held-out): alpha, fused/eGK RMS [95 % interval], fused/pressure path RMS [95 % interval]"
    );
    for row in &evaluation.fusion {
        println!(
            "  {:>5.1}  {:.4} {}  {:.4} {}",
            row.alpha_deg,
            row.over_egk,
            bracketed(row.over_egk_ci95, |v| format!("{v:.4}")),
            row.over_pressure,
            bracketed(row.over_pressure_ci95, |v| format!("{v:.4}"))
        );
    }
    println!(
        "What the pressures know about the eGK's error (roll runs, held-out): alpha, eGK, fused, eGK + best linear use of the pressures"
    );
    for row in &evaluation.pressure_information {
        println!(
            "  {:>5.1}  {:>10.4e}  {:>10.4e}  {:>10.4e}  ({:+.2} %)",
            row.alpha_deg,
            row.egk_rms,
            row.fused_rms,
            row.best_linear_rms,
            100.0 * (row.best_linear_rms / row.egk_rms - 1.0)
        );
    }
    println!(
        "Noise robustness (operator refitted on noisy data): sigma, alpha, E_SINDy/E_lin, corr linear, corr operator"
    );
    for level in &evaluation.noise_robustness {
        for row in &level.per_alpha {
            println!(
                "  {:.2e}  {:>5.1}  {:>6.3}  {:>7.4}  {:>7.4}",
                level.sigma, row.alpha_deg, row.ratio, row.corr_linear, row.corr_operator
            );
        }
    }
}

/// A bootstrap interval as `[low, high]` with each end written by `each`, `[-]` without one.
pub(crate) fn bracketed(interval: Option<[f64; 2]>, each: impl Fn(f64) -> String) -> String {
    interval.map_or_else(|| "[-]".to_owned(), |[low, high]| format!("[{}, {}]", each(low), each(high)))
}

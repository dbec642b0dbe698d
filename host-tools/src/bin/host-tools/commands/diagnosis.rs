//! `diagnose` and `validate-diagnosis`: the sim-to-real gap and its blind campaign.

use std::time::Instant;

use anyhow::Context;

use crate::flags::*;
use host_tools::progress::*;

/// `diagnose`: dataset (+ model) -> report folder with diagnosis.json.
pub(crate) fn diagnose(args: DiagnoseArgs) -> anyhow::Result<()> {
    use host_tools::diagnose::{DiagnoseConfig, diagnose, report};
    let started = Instant::now();
    let dataset = firmware_sim::dataset::load_dataset(&args.real)?;
    let model = match &args.model {
        Some(path) => {
            let (set, source) = host_tools::model::load(Some(path))?;
            Some((set, source.to_string()))
        }
        None => None,
    };
    // The model's own signature, written by `fit` beside model.bin; else the built-in model's.
    let own_signature = match &args.model {
        Some(path) => host_tools::diagnose::signature_beside(path)?,
        None => None,
    };
    if own_signature.is_none() {
        eprintln!("note: no diagnosis signature of this sim; the built-in model's (default campaign) sets the floor");
    }
    let signature = Some(own_signature.unwrap_or_else(host_tools::diagnose::default_signature));
    let config =
        DiagnoseConfig { split: host_tools::fit::split::Split::with_holdout(args.holdout_fraction), signature };
    let spinner = spinner("diagnosing".into());
    let (diagnosis, evidence) =
        diagnose(&dataset, model.as_ref().map(|(set, name)| (set, name.clone())), &config, &|stage| {
            spinner.set_message(format!("diagnosing: {stage}"))
        })?;
    spinner.set_message("diagnosing: writing the report");
    let report = report::build(&diagnosis, &evidence, &args.real.display().to_string());
    let json = serde_json::to_value(&diagnosis)?;
    host_tools::report::write_report(&args.report, &report, "diagnosis.json", &json)
        .with_context(|| format!("writing the report {}", args.report.display()))?;
    spinner.finish_and_clear();
    println!("verdict: {}", diagnosis.verdict.as_str());
    for effect in &diagnosis.effects {
        println!(
            "  {:<18} block {:<12} held-out gap {:.3e} -> {:.3e} (shrink {:.2})",
            effect.name, effect.block, effect.heldout_rms_before, effect.heldout_rms_after, effect.shrink
        );
    }
    if let Some(unexplained) = &diagnosis.unexplained {
        println!("  {}", unexplained.description);
    }
    println!(
        "diagnosis took {:.1} s; report: {}",
        started.elapsed().as_secs_f64(),
        args.report.join("report.html").display()
    );
    Ok(())
}

/// `validate-diagnosis`: the blind campaign -> report folder with validation.json.
pub(crate) fn validate_diagnosis(args: ValidateArgs) -> anyhow::Result<()> {
    use host_tools::validate::{CampaignConfig, external, run_campaign};
    let started = Instant::now();
    if let Some(dir) = &args.campaign {
        let count = std::fs::read_to_string(dir.join("campaign.json"))
            .ok()
            .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
            .and_then(|index| index["cases"].as_array().map(Vec::len))
            .unwrap_or(0);
        let progress = progress_bar(count as u64, "diagnosing the campaign's cases");
        let outcome = external::run(dir, &|| progress.inc(1))?;
        progress.finish_and_clear();
        let described = format!(
            "{} cases of the campaign {} (master seed {}), written by another program; the model fitted on its clean recording in {:.0} s; took {:.0} s.",
            outcome.records.len(),
            dir.display(),
            outcome.seed,
            outcome.fit_s,
            started.elapsed().as_secs_f64()
        );
        return write_validation(&args.report, &outcome.records, &described, &format!("campaign {}", dir.display()));
    }
    let config = CampaignConfig {
        cases: args.cases,
        seed: args.seed,
        duration_s: args.duration_s,
        classes: args.classes,
        keep: args.keep,
        ..CampaignConfig::default()
    };
    let progress = progress_bar(args.cases as u64, "diagnosing blind cases");
    let records = run_campaign(&config, &|| progress.inc(1));
    progress.finish_and_clear();
    let described = format!(
        "{} cases, master seed {}, runs of {} s at one angle of attack each (roll, actuation, roll+actuation); took {:.0} s.",
        records.len(),
        args.seed,
        args.duration_s,
        started.elapsed().as_secs_f64()
    );
    write_validation(&args.report, &records, &described, &format!("{config:?}"))
}

/// Scores `records`, writes the campaign's report folder and prints the acceptance table.
pub(crate) fn write_validation(
    folder: &std::path::Path,
    records: &[host_tools::validate::CaseRecord],
    described: &str,
    config: &str,
) -> anyhow::Result<()> {
    use host_tools::validate::score;
    let summary = score::summarise(records);
    let report = score::report(records, &summary, described);
    let json = serde_json::json!({ "config": config, "summary": summary, "cases": records });
    host_tools::report::write_report(folder, &report, "validation.json", &json)
        .with_context(|| format!("writing the report {}", folder.display()))?;
    print!(
        "{}",
        report.sections[0].tables[0]
            .rows
            .iter()
            .map(|row| format!("{:<48} {:>8} {:>10}\n", row[0], row[1], row[2]))
            .collect::<String>()
    );
    println!(
        "{:<18} {}",
        "right/cases",
        score::RATIO_BINS
            .iter()
            .map(|(lo, hi)| if hi.is_finite() { format!("{lo:.0}-{hi:.0}") } else { format!(">={lo:.0}") })
            .map(|bin| format!("{bin:<7}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    for (class, cells) in &summary.accuracy_by_ratio {
        println!("{class:<18} {}", cells.iter().map(|(r, t)| format!("{r:>3}/{t:<3}")).collect::<Vec<_>>().join(" "));
    }
    println!("{described}\nreport: {}", folder.join("report.html").display());
    Ok(())
}

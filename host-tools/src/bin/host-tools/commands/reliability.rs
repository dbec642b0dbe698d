//! `faults`: the estimator under sensor faults on held-out data.

use std::time::Instant;

use anyhow::Context;

use crate::flags::*;
use host_tools::progress::*;

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

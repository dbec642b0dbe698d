//! `faults`: the estimator under sensor faults on held-out data.

use std::fmt;
use std::path::PathBuf;
use std::time::Instant;

use super::{CommandError, Progress, holdout_split};
use evaluation::fault_study::{COLUMNS, FaultStudy, StudyConfig, fault_study, study_report, table_rows};

/// The flags of `faults`.
#[derive(Debug, Clone, clap::Args)]
pub struct FaultsArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub data: PathBuf,
    /// Model folder or model.bin (default: the built-in tables).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Report folder to write (report.md, report.html, faults.json).
    #[arg(long)]
    pub report: PathBuf,
    /// Seed of the faults' random choices (spikes, dropped samples).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Share of every run, at its end, that is held out (must match the fit's).
    #[arg(long = "holdout-fraction", default_value_t = model_fit::fit::split::DEFAULT_HOLDOUT_FRACTION)]
    pub holdout_fraction: f64,
}

/// What `faults` measured and wrote.
#[derive(Debug, Clone)]
pub struct FaultsSummary {
    /// Detection latency and error per fault type.
    pub study: FaultStudy,
    /// The report's HTML page.
    pub report: PathBuf,
    /// Wall time, s.
    pub elapsed_s: f64,
}

impl fmt::Display for FaultsSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "fault-free held-out RMS: C_l {:.3e}, pressure path {:.3e}",
            self.study.clean_rms, self.study.clean_pressure_rms
        )?;
        writeln!(f, "{}", COLUMNS.join(" | "))?;
        for row in table_rows(&self.study) {
            writeln!(f, "{}", row.join(" | "))?;
        }
        writeln!(f, "report: {}", self.report.display())
    }
}

/// `faults`: the sensor-fault study on held-out data, as a report folder.
pub fn faults(args: &FaultsArgs, progress: &dyn Progress) -> Result<FaultsSummary, CommandError> {
    let split = holdout_split(args.holdout_fraction)?;
    let started = Instant::now();
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let (set, source) = model_fit::model::load(args.model.as_deref())?;
    let config = StudyConfig { split, seed: args.seed, ..StudyConfig::default() };
    progress.stage("injecting faults", None);
    let study = fault_study(&dataset, &set, &config)?;
    let report = study_report(&study, &format!("Data `{}`, model {source}", args.data.display()));
    let json =
        serde_json::json!({ "data": args.data.display().to_string(), "model": source.to_string(), "study": study });
    reports::write_report(&args.report, &report, "faults.json", &json).map_err(CommandError::write(&args.report))?;
    Ok(FaultsSummary { study, report: args.report.join("report.html"), elapsed_s: started.elapsed().as_secs_f64() })
}

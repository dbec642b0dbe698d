//! `diagnose` and `validate-diagnosis`: the sim-to-real gap and its blind campaign.

use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Instant;

use super::{CommandError, Progress, holdout_split};
use diagnosis::diagnose::DiagnoseConfig;
use diagnosis::diagnose::result::Diagnosis;
use diagnosis::validate::CaseRecord;
use diagnosis::validate::score::{self, Summary};

/// The flags of `diagnose`.
#[derive(Debug, Clone, clap::Args)]
pub struct DiagnoseArgs {
    /// The recorded ("real") dataset folder (or its manifest.toml).
    #[arg(long)]
    pub real: PathBuf,
    /// The sim: a model folder or model.bin (default: nominal models fitted on the training part
    /// of the data itself).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Report folder to write (diagnosis.json, report.md, report.html, SVG plots).
    #[arg(long)]
    pub report: PathBuf,
    /// Share of every run, at its end, that is held out.
    #[arg(long = "holdout-fraction", default_value_t = model_fit::fit::split::DEFAULT_HOLDOUT_FRACTION)]
    pub holdout_fraction: f64,
}

/// The flags of `validate-diagnosis`.
#[derive(Debug, Clone, clap::Args)]
pub struct ValidateArgs {
    /// Number of cases (they cycle through no effect, every vocabulary effect and two outside it).
    #[arg(long, default_value_t = 140)]
    pub cases: usize,
    /// Master seed of the campaign.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Report folder (report.md, report.html, validation.json).
    #[arg(long)]
    pub report: PathBuf,
    /// Duration of every run of a case, s.
    #[arg(long = "duration-s", default_value_t = 30.0)]
    pub duration_s: f64,
    /// Only these classes (comma-separated: none, effect names).
    #[arg(long, value_delimiter = ',')]
    pub classes: Vec<String>,
    /// Keep every case's recording, model and signature in this folder (to rerun `diagnose`).
    #[arg(long)]
    pub keep: Option<PathBuf>,
    /// Only the cases with these ids (comma-separated, below `--cases`), each drawn as in the
    /// whole campaign: to diagnose one case of a campaign again.
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<usize>,
    /// Score a campaign written by another program instead (tools/foreign-tunnel/campaign.py):
    /// its clean recording is fitted, every case diagnosed, then its sealed truths read.
    #[arg(long, conflicts_with_all = ["cases", "seed", "duration_s", "classes", "keep", "only"])]
    pub campaign: Option<PathBuf>,
}

/// Whose diagnosis signature set the floor of what counts as a gap.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SignatureSource {
    /// The model's own, written by `fit` beside its blob.
    Model(PathBuf),
    /// The built-in model's on the default campaign (no signature beside the model).
    BuiltIn,
}

/// What `diagnose` found and wrote.
#[derive(Debug, Clone)]
pub struct DiagnoseSummary {
    /// The diagnosis (`diagnosis.json`, the contract of `docs/spec/diagnosis.md`).
    pub diagnosis: Diagnosis,
    /// Whose signature was used.
    pub signature: SignatureSource,
    /// The report's HTML page.
    pub report: PathBuf,
    /// Wall time, s.
    pub elapsed_s: f64,
}

impl fmt::Display for DiagnoseSummary {
    /// The verdict, each named effect with its held-out shrink, what stays unexplained.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let diagnosis = &self.diagnosis;
        writeln!(f, "verdict: {}", diagnosis.verdict.as_str())?;
        for effect in &diagnosis.effects {
            writeln!(
                f,
                "  {:<18} block {:<12} held-out gap {:.3e} -> {:.3e} (shrink {:.2})",
                effect.name, effect.block, effect.heldout_rms_before, effect.heldout_rms_after, effect.shrink
            )?;
        }
        if let Some(unexplained) = &diagnosis.unexplained {
            writeln!(f, "  {}", unexplained.description)?;
        }
        writeln!(f, "diagnosis took {:.1} s; report: {}", self.elapsed_s, self.report.display())
    }
}

/// `diagnose`: dataset (+ model) -> report folder with `diagnosis.json`.
pub fn diagnose(args: &DiagnoseArgs, progress: &dyn Progress) -> Result<DiagnoseSummary, CommandError> {
    let split = holdout_split(args.holdout_fraction)?;
    let started = Instant::now();
    let dataset = firmware_sim::dataset::load_dataset(&args.real)?;
    let model = match &args.model {
        Some(path) => {
            let (set, source) = model_fit::model::load(Some(path))?;
            Some((set, source.to_string()))
        }
        None => None,
    };
    // The model's own signature, written by `fit` beside model.bin; else the built-in model's.
    let own = match &args.model {
        Some(path) => diagnosis::diagnose::signature_beside(path)?.map(|found| (found, path.clone())),
        None => None,
    };
    let (signature, source) = match own {
        Some((found, path)) => (Some(found), SignatureSource::Model(path)),
        None => (None, SignatureSource::BuiltIn),
    };
    let sim = model.as_ref().map(|(set, name)| (set, name.clone()));
    let (diagnosis, report) = diagnose_loaded(&dataset, &args.real, sim, signature, split, progress)?;
    let json = serde_json::to_value(&diagnosis).map_err(|error| CommandError::write(&args.report)(error.into()))?;
    reports::write_report(&args.report, &report, "diagnosis.json", &json).map_err(CommandError::write(&args.report))?;
    Ok(DiagnoseSummary {
        diagnosis,
        signature: source,
        report: args.report.join("report.html"),
        elapsed_s: started.elapsed().as_secs_f64(),
    })
}

/// The diagnosis of a loaded dataset that came from `origin` (named in the report), as
/// `diagnose` makes it, and its report; nothing is written. `sim` is the model and its name
/// (nominal models fitted on the data's training part when `None`); `signature` its diagnosis
/// signature (the built-in model's when `None`).
pub fn diagnose_loaded(
    dataset: &firmware_sim::dataset::Dataset,
    origin: &Path,
    sim: Option<(&estimator_core::coeffs::CoefficientSet, String)>,
    signature: Option<diagnosis::diagnose::Signature>,
    split: model_fit::fit::split::Split,
    progress: &dyn Progress,
) -> Result<(Diagnosis, reports::Report), CommandError> {
    let signature = signature.unwrap_or_else(diagnosis::diagnose::default_signature);
    let config = DiagnoseConfig { split, signature: Some(signature) };
    progress.stage("diagnosing", None);
    let (diagnosis, evidence) = diagnosis::diagnose::diagnose(dataset, sim, &config, &|stage| {
        progress.stage(&format!("diagnosing: {stage}"), None);
    })?;
    progress.stage("diagnosing: writing the report", None);
    let report = diagnosis::diagnose::report::build(&diagnosis, &evidence, &origin.display().to_string());
    Ok((diagnosis, report))
}

/// What `validate-diagnosis` scored and wrote.
#[derive(Debug, Clone)]
pub struct ValidationSummary {
    /// Every case with its diagnosis and score.
    pub records: Vec<CaseRecord>,
    /// The acceptance figures.
    pub summary: Summary,
    /// The acceptance table's rows (criterion, value, goal), as in the report.
    pub acceptance: Vec<Vec<String>>,
    /// Where the cases came from and how long they took.
    pub described: String,
    /// The report's HTML page.
    pub report: PathBuf,
}

impl fmt::Display for ValidationSummary {
    /// The acceptance table and the accuracy by effect-to-noise ratio.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for row in &self.acceptance {
            let cell = |idx: usize| row.get(idx).map_or("", String::as_str);
            writeln!(f, "{:<48} {:>8} {:>10}", cell(0), cell(1), cell(2))?;
        }
        let bins: Vec<String> = score::RATIO_BINS
            .iter()
            .map(|(lo, hi)| if hi.is_finite() { format!("{lo:.0}-{hi:.0}") } else { format!(">={lo:.0}") })
            .map(|bin| format!("{bin:<7}"))
            .collect();
        writeln!(f, "{:<18} {}", "right/cases", bins.join(" "))?;
        for (class, cells) in &self.summary.accuracy_by_ratio {
            let cells: Vec<String> = cells.iter().map(|(r, t)| format!("{r:>3}/{t:<3}")).collect();
            writeln!(f, "{class:<18} {}", cells.join(" "))?;
        }
        writeln!(f, "{}\nreport: {}", self.described, self.report.display())
    }
}

/// `validate-diagnosis`: the blind campaign (or `--campaign`, one written by another program)
/// -> report folder with `validation.json`.
pub fn validate_diagnosis(args: &ValidateArgs, progress: &dyn Progress) -> Result<ValidationSummary, CommandError> {
    use diagnosis::validate::{CampaignConfig, external, run_campaign};
    let started = Instant::now();
    if let Some(dir) = &args.campaign {
        let count = std::fs::read_to_string(dir.join("campaign.json"))
            .ok()
            .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
            .and_then(|index| index["cases"].as_array().map(Vec::len));
        progress.stage("diagnosing the campaign's cases", count.map(|n| n as u64));
        let outcome = external::run(dir, &|| progress.step())?;
        let described = format!(
            "{} cases of the campaign {} (master seed {}), written by another program; the model fitted on its clean recording in {:.0} s; took {:.0} s.",
            outcome.records.len(),
            dir.display(),
            outcome.seed,
            outcome.fit_s,
            started.elapsed().as_secs_f64()
        );
        return write_validation(&args.report, outcome.records, described, &format!("campaign {}", dir.display()));
    }
    let config = CampaignConfig {
        cases: args.cases,
        seed: args.seed,
        duration_s: args.duration_s,
        classes: args.classes.clone(),
        keep: args.keep.clone(),
        only: args.only.clone(),
        ..CampaignConfig::default()
    };
    if let Some(id) = args.only.iter().find(|id| **id >= args.cases) {
        return Err(CommandError::Flag {
            flag: "--only",
            expected: format!("must name case ids below --cases ({}), found {id}", args.cases),
        });
    }
    let n_cases = if args.only.is_empty() { args.cases } else { args.only.len() };
    progress.stage("diagnosing blind cases", Some(n_cases as u64));
    let records = run_campaign(&config, &|| progress.step());
    let described = format!(
        "{} cases, master seed {}, runs of {} s at one angle of attack each (roll, actuation, roll+actuation); took {:.0} s.",
        records.len(),
        args.seed,
        args.duration_s,
        started.elapsed().as_secs_f64()
    );
    write_validation(&args.report, records, described, &format!("{config:?}"))
}

/// Scores `records` and writes the campaign's report folder.
fn write_validation(
    folder: &Path,
    records: Vec<CaseRecord>,
    described: String,
    config: &str,
) -> Result<ValidationSummary, CommandError> {
    let scored = validation_report(&records, &described, config);
    reports::write_report(folder, &scored.report, "validation.json", &scored.json)
        .map_err(CommandError::write(folder))?;
    Ok(ValidationSummary {
        records,
        summary: scored.summary,
        acceptance: scored.acceptance,
        described,
        report: folder.join("report.html"),
    })
}

/// A campaign's scores, before anything is written.
#[derive(Debug, Clone)]
pub struct ScoredCampaign {
    /// The acceptance figures.
    pub summary: Summary,
    /// The acceptance table's rows (criterion, goal, value), as in the report.
    pub acceptance: Vec<Vec<String>>,
    /// The report (tables).
    pub report: reports::Report,
    /// `validation.json`: the configuration as `config`, the summary, every case.
    pub json: serde_json::Value,
}

/// The scores of a campaign's `records` and its report, as `validate-diagnosis` writes them;
/// `described` says where the cases came from, `config` how they were drawn.
#[must_use]
pub fn validation_report(records: &[CaseRecord], described: &str, config: &str) -> ScoredCampaign {
    let summary = score::summarise(records);
    let report = score::report(records, &summary, described);
    let json = serde_json::json!({ "config": config, "summary": summary, "cases": records });
    let acceptance = report.sections.first().and_then(|section| section.tables.first()).map(|table| table.rows.clone());
    ScoredCampaign { summary, acceptance: acceptance.unwrap_or_default(), report, json }
}

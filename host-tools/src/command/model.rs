//! `fit`, `codegen`, `replay` and `evaluate`: the model from a dataset to the flying tables and
//! back over the data.

use std::fmt;
use std::path::PathBuf;
use std::time::Instant;

use firmware_sim::fault::FaultSpec;

use estimator_core::coeffs::CoefficientSet;

use super::{CommandError, Progress, holdout_split};
use evaluation::evaluate::{
    Evaluation, EvaluationConfig, Replayed, evaluate as evaluate_held_out, evaluation_report, figures,
    with_balance_noise,
};
use model_fit::fit::pipeline::{FitConfig, FitOutcome, FitReport, fit_dataset, refit_coupling};

/// The flags of `fit`.
#[derive(Debug, Clone, clap::Args)]
pub struct FitArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub data: PathBuf,
    /// Model folder to write (model.bin, model.md, model.json, plots); replaced atomically.
    #[arg(long)]
    pub out: PathBuf,
    /// Seed, recorded in the model card (the fit itself is deterministic).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Share of every run, at its end, held out from fitting.
    #[arg(long = "holdout-fraction", default_value_t = model_fit::fit::split::DEFAULT_HOLDOUT_FRACTION)]
    pub holdout_fraction: f64,
}

/// The flags of `codegen`.
#[derive(Debug, Clone, clap::Args)]
pub struct CodegenArgs {
    /// Model folder (or its model.bin).
    #[arg(long)]
    pub model: PathBuf,
    /// Only compare with the committed files; fail if they are stale.
    #[arg(long)]
    pub check: bool,
    /// The generated module's folder (default: estimator-core/src/coeffs/generated of this
    /// workspace).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Where the tables come from, written into the generated module's header.
    #[arg(long)]
    pub provenance: Option<String>,
}

/// The flags of `replay`.
#[derive(Debug, Clone, clap::Args)]
pub struct ReplayArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub data: PathBuf,
    /// Model folder or model.bin (default: the built-in tables).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Folder for the per-run estimate CSVs (replaced atomically).
    #[arg(long)]
    pub out: PathBuf,
    /// Inject a sensor fault (repeatable), e.g. `stuck:cp07@10s`, `bias:cp02=0.3@5s`,
    /// `drop:phi=0.2`, `missing:cmu` (see firmware_sim::fault).
    #[arg(long = "fault", value_name = "SPEC")]
    pub faults: Vec<FaultSpec>,
    /// Seed of the faults' random choices.
    #[arg(long = "fault-seed", default_value_t = 1)]
    pub fault_seed: u64,
}

/// The flags of `evaluate`.
#[derive(Debug, Clone, clap::Args)]
pub struct EvaluateArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub data: PathBuf,
    /// Model folder or model.bin (default: the built-in tables).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Report folder to write (report.html, report.md, SVG plots, evaluation.json).
    #[arg(long)]
    pub report: PathBuf,
    /// Seed of the noise added in the robustness test.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Share of every run, at its end, that is evaluated (must match the fit's).
    #[arg(long = "holdout-fraction", default_value_t = model_fit::fit::split::DEFAULT_HOLDOUT_FRACTION)]
    pub holdout_fraction: f64,
}

/// What `fit` wrote: the model folder and the fit's numbers.
#[derive(Debug, Clone)]
pub struct FitSummary {
    /// The model folder.
    pub out: PathBuf,
    /// The fitted coefficient set, as written to `model.bin`.
    pub set: CoefficientSet,
    /// The fit's report (the model card's numbers), its held-out table among them.
    pub report: FitReport,
    /// Wall time, s.
    pub elapsed_s: f64,
}

impl fmt::Display for FitSummary {
    /// The held-out table.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use model_fit::fit::heldout::HeldoutAlpha;
        writeln!(f, "held-out RMS of C_l (replay through the fitted core; {})", self.report.split)?;
        let line = |cells: &[&str]| cells.iter().map(|cell| format!("{cell:>13}")).collect::<Vec<_>>().join(" ");
        writeln!(f, "{}", line(&HeldoutAlpha::COLUMNS))?;
        for row in &self.report.heldout.per_alpha {
            let cells = row.cells();
            writeln!(f, "{}", line(&cells.each_ref().map(String::as_str)))?;
        }
        Ok(())
    }
}

/// `fit`: dataset -> model folder (complete or absent), with the model's diagnosis signature
/// on its own held-out data.
pub fn fit(args: &FitArgs, progress: &dyn Progress) -> Result<FitSummary, CommandError> {
    let split = holdout_split(args.holdout_fraction)?;
    let started = Instant::now();
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let described = format!("{} (seed {})", args.data.display(), args.seed);
    let FittedModel { set, report, files } = fit_loaded(&dataset, &args.data, &described, split, progress)?;
    progress.stage("writing the model folder", None);
    model_fit::fit::card::write_model_files(&args.out, &files)?;
    Ok(FitSummary { out: args.out.clone(), set, report, elapsed_s: started.elapsed().as_secs_f64() })
}

/// A fitted model held in memory: the set, the fit's numbers, and the files of its model
/// folder (name, bytes; [`model_fit::fit::card::model_files`]), written or not.
#[derive(Debug, Clone)]
pub struct FittedModel {
    /// The fitted coefficient set.
    pub set: CoefficientSet,
    /// The fit's report.
    pub report: FitReport,
    /// The model folder's files: blob, `model.json`, card, diagnosis signature, plots.
    pub files: Vec<(String, Vec<u8>)>,
}

/// The fit of a loaded dataset, as `fit` makes it, without writing anything: `origin` is where
/// the data came from (named in errors), `described` the card's account of it.
pub fn fit_loaded(
    dataset: &firmware_sim::dataset::Dataset,
    origin: &std::path::Path,
    described: &str,
    split: model_fit::fit::split::Split,
    progress: &dyn Progress,
) -> Result<FittedModel, CommandError> {
    let config = FitConfig { split, ..Default::default() };
    let failed = |source| CommandError::Fit { data: origin.to_path_buf(), source };
    let outcome =
        fit_dataset(dataset, &config, &|stage| progress.stage(&format!("fitting: {stage}"), None)).map_err(failed)?;
    progress.stage("fitting: the model's diagnosis signature on its held-out data", None);
    let signature = diagnosis::diagnose::signature(dataset, &outcome.set, config.split)?;
    let signature = (diagnosis::diagnose::SIGNATURE_FILE, serde_json::to_vec_pretty(&signature).unwrap_or_default());
    let files = model_fit::fit::card::model_files(&outcome, described, &[signature]).map_err(|error| {
        model_fit::model::ModelError::ToBlob { path: origin.join(model_fit::model::BLOB_FILE), error }
    })?;
    let FitOutcome { set, report } = outcome;
    Ok(FittedModel { set, report, files })
}

/// What `codegen` did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CodegenSummary {
    /// The generated file.
    pub target: PathBuf,
    /// The model it was generated from.
    pub model: PathBuf,
    /// `--check`: compared only (and it was up to date); else written.
    pub checked: bool,
}

impl fmt::Display for CodegenSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.checked {
            writeln!(f, "{} is up to date with {}", self.target.display(), self.model.display())
        } else {
            writeln!(f, "wrote {}", self.target.display())
        }
    }
}

/// `codegen`: model -> const tables in estimator-core, or (`--check`) an error when the
/// committed tables differ from the model's.
pub fn codegen(args: &CodegenArgs) -> Result<CodegenSummary, CommandError> {
    let (set, source) = model_fit::model::load(Some(&args.model))?;
    let is_default = |path: &std::path::Path| {
        let canonical = |p: &std::path::Path| std::fs::canonicalize(p).ok();
        let folder = if path.is_dir() { path.to_path_buf() } else { path.parent().unwrap_or(path).to_path_buf() };
        canonical(&folder).is_some() && canonical(&folder) == canonical(&model_fit::codegen::default_model())
    };
    let provenance = args.provenance.clone().unwrap_or_else(|| {
        if is_default(&args.model) {
            model_fit::codegen::DEFAULT_PROVENANCE.to_owned()
        } else {
            format!("the fit in {source}")
        }
    });
    let generated = model_fit::codegen::render(&set, &provenance)?;
    let target = args.out.clone().unwrap_or_else(model_fit::codegen::default_target);
    if args.check {
        model_fit::codegen::check(&target, &generated, &args.model.display().to_string())?;
    } else {
        model_fit::codegen::write(&target, &generated)?;
    }
    Ok(CodegenSummary { target, model: args.model.clone(), checked: args.check })
}

/// What `replay` wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplaySummary {
    /// The replay folder.
    pub out: PathBuf,
    /// Runs replayed.
    pub n_runs: usize,
    /// Wall time, s.
    pub elapsed_s: f64,
}

impl fmt::Display for ReplaySummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "replayed {} runs into {} in {:.1} s", self.n_runs, self.out.display(), self.elapsed_s)
    }
}

/// `replay`: dataset + model -> per-run estimate CSVs (with `--fault`, on faulted inputs).
pub fn replay(args: &ReplayArgs, progress: &dyn Progress) -> Result<ReplaySummary, CommandError> {
    let started = Instant::now();
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let (set, source) = model_fit::model::load(args.model.as_deref())?;
    progress.stage(&format!("replaying {} runs", dataset.runs.len()), None);
    let described = format!("data {}, model {source}", args.data.display());
    let n_runs = model_fit::replay::write_replay_with_faults(
        &args.out,
        &dataset,
        &set,
        &described,
        &args.faults,
        args.fault_seed,
    )?;
    Ok(ReplaySummary { out: args.out.clone(), n_runs, elapsed_s: started.elapsed().as_secs_f64() })
}

/// What `evaluate` found and wrote.
#[derive(Debug, Clone)]
pub struct EvaluateSummary {
    /// The paper's tables on the held-out part.
    pub evaluation: Evaluation,
    /// The report's HTML page.
    pub report: PathBuf,
    /// What the report leaves out, and why.
    pub warnings: Vec<String>,
    /// Wall time, s.
    pub elapsed_s: f64,
}

/// `evaluate`: the paper's analysis on held-out data, as a report folder.
pub fn evaluate(args: &EvaluateArgs, progress: &dyn Progress) -> Result<EvaluateSummary, CommandError> {
    let split = holdout_split(args.holdout_fraction)?;
    let started = Instant::now();
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let (set, source) = model_fit::model::load(args.model.as_deref())?;
    let evaluated = evaluate_loaded(&dataset, &args.data, &set, &source.to_string(), args.seed, split, progress)?;
    reports::write_report(&args.report, &evaluated.report, "evaluation.json", &evaluated.json)
        .map_err(CommandError::write(&args.report))?;
    Ok(EvaluateSummary {
        evaluation: evaluated.evaluation,
        report: args.report.join("report.html"),
        warnings: evaluated.warnings,
        elapsed_s: started.elapsed().as_secs_f64(),
    })
}

/// The evaluation of a loaded dataset, as `evaluate` makes it, before anything is written.
#[derive(Debug, Clone)]
pub struct Evaluated {
    /// The paper's tables on the held-out part.
    pub evaluation: Evaluation,
    /// The report (tables and figures).
    pub report: reports::Report,
    /// `evaluation.json`.
    pub json: serde_json::Value,
    /// What the report leaves out, and why.
    pub warnings: Vec<String>,
}

/// The paper's analysis of `set` (from `source`) on the held-out part of a loaded dataset that
/// came from `origin` (named in the report and in errors), with the noise of the robustness
/// test seeded by `seed`; nothing is written.
pub fn evaluate_loaded(
    dataset: &firmware_sim::dataset::Dataset,
    origin: &std::path::Path,
    set: &CoefficientSet,
    source: &str,
    seed: u64,
    split: model_fit::fit::split::Split,
    progress: &dyn Progress,
) -> Result<Evaluated, CommandError> {
    let config = EvaluationConfig { split, seed, ..EvaluationConfig::default() };
    progress.stage("evaluating: replay, tables, noise sweep", None);
    let failed = |source| CommandError::Evaluate { data: origin.to_path_buf(), source };
    let (evaluation, replayed) = evaluate_held_out(dataset, set, &config).map_err(failed)?;
    progress.stage("evaluating: figures", None);
    let sigma = config.figure_noise;
    let noisy = with_balance_noise(dataset, sigma, seed);
    let fit_config = FitConfig { split, ..Default::default() };
    let mut warnings = Vec::new();
    let noisy_figure = match refit_coupling(&noisy, set, &fit_config) {
        Ok(refitted) => Some(Replayed::new(&noisy, &refitted)),
        Err(error) => {
            warnings.push(format!(
                "the figure with balance noise {sigma} is left out: refitting the coupling failed: {error}"
            ));
            None
        }
    };
    let figures = figures(dataset, &replayed, &split, &evaluation, noisy_figure.as_ref().map(|r| (&noisy, r, sigma)));
    let described = format!("Data `{}`, model {source}.", origin.display());
    let report = evaluation_report(&evaluation, figures, &described);
    let json = serde_json::json!({ "data": origin.display().to_string(), "model": source, "evaluation": evaluation });
    Ok(Evaluated { evaluation, report, json, warnings })
}

impl fmt::Display for EvaluateSummary {
    /// The evaluation's tables and the report's page.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let evaluation = &self.evaluation;
        writeln!(f, "Table 1 (held-out): alpha, sigma(dCl)/mean(ClRA), sigma(dCl)/sigma(ClRA)")?;
        for row in &evaluation.table1 {
            writeln!(
                f,
                "  {:>5.1}  {:>6.1} %  {:>6.1} %",
                row.alpha_deg,
                100.0 * row.ratio_to_mean,
                100.0 * row.ratio_to_std
            )?;
        }
        writeln!(
            f,
            "Tables 2 and 3 (held-out): alpha, E_SINDy/E_lin [95 % interval], corr linear, corr operator, change [95 % interval]"
        )?;
        for row in &evaluation.coupling {
            writeln!(
                f,
                "  {:>5.1}  {:>6.3} {:<14}  {:>9.6}  {:>9.6}  {:+.2e} {}",
                row.alpha_deg,
                row.ratio,
                bracketed(row.ratio_ci95, |v| format!("{v:.3}")),
                row.corr_linear,
                row.corr_operator,
                row.corr_operator - row.corr_linear,
                bracketed(row.corr_change_ci95, |v| format!("{v:+.2e}"))
            )?;
        }
        writeln!(f, "Blocks (held-out): alpha, block, RMS, correlation, RMS / balance noise")?;
        for row in &evaluation.blocks {
            writeln!(
                f,
                "  {:>5.1}  {:<9} {:>10.3e}  {:>7.4}  {:>5.2}",
                row.alpha_deg, row.block, row.rms, row.correlation, row.rms_over_noise
            )?;
        }
        writeln!(
            f,
            "Fusion (roll runs, held-out): alpha, fused/eGK RMS [95 % interval], fused/pressure path RMS [95 % interval]"
        )?;
        for row in &evaluation.fusion {
            writeln!(
                f,
                "  {:>5.1}  {:.4} {}  {:.4} {}",
                row.alpha_deg,
                row.over_egk,
                bracketed(row.over_egk_ci95, |v| format!("{v:.4}")),
                row.over_pressure,
                bracketed(row.over_pressure_ci95, |v| format!("{v:.4}"))
            )?;
        }
        writeln!(
            f,
            "What the pressures know about the eGK's error (roll runs, held-out): alpha, eGK, fused, eGK + best linear use of the pressures"
        )?;
        for row in &evaluation.pressure_information {
            writeln!(
                f,
                "  {:>5.1}  {:>10.4e}  {:>10.4e}  {:>10.4e}  ({:+.2} %)",
                row.alpha_deg,
                row.egk_rms,
                row.fused_rms,
                row.best_linear_rms,
                100.0 * (row.best_linear_rms / row.egk_rms - 1.0)
            )?;
        }
        writeln!(
            f,
            "Noise robustness (operator refitted on noisy data): sigma, alpha, E_SINDy/E_lin, corr linear, corr operator"
        )?;
        for level in &evaluation.noise_robustness {
            for row in &level.per_alpha {
                writeln!(
                    f,
                    "  {:.2e}  {:>5.1}  {:>6.3}  {:>7.4}  {:>7.4}",
                    level.sigma, row.alpha_deg, row.ratio, row.corr_linear, row.corr_operator
                )?;
            }
        }
        writeln!(f, "report: {}", self.report.display())
    }
}

/// A bootstrap interval as `[low, high]` with each end written by `each`, `[-]` without one.
fn bracketed(interval: Option<[f64; 2]>, each: impl Fn(f64) -> String) -> String {
    interval.map_or_else(|| "[-]".to_owned(), |[low, high]| format!("[{}, {}]", each(low), each(high)))
}

//! The `host-tools` command line: one binary whose subcommands follow the user's workflow
//! (`shared/spec/cli.md`).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use clap::{Parser, Subcommand};
use firmware_sim::campaign::Scenario;
use firmware_sim::fault::FaultSpec;
use host_tools::qemu::SparseCode;
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
    /// Fit every coefficient of the estimator on a dataset's training part; write a model folder.
    Fit(FitArgs),
    /// Write a model's coefficient set as const tables into estimator-core (or check them).
    Codegen(CodegenArgs),
    /// Run the estimator (the code that flies) over a dataset; write every stage's estimates.
    Replay(ReplayArgs),
    /// The paper's tables and figures on held-out data, as a report folder.
    Evaluate(EvaluateArgs),
    /// Closed-loop SIL comparison of the controller scenarios against the synthetic tunnel.
    Sil(SilArgs),
    /// Build the firmware, replay one run in QEMU (STM32F405) and compare with the host replay.
    QemuReplay(QemuReplayArgs),
    /// Hardware-in-the-loop: the firmware's 1 kHz loop in QEMU, fed runs over its serial link.
    Hil(HilArgs),
    /// Sim-to-real gap diagnosis: where the gap lies, which effect causes it, how far it shrinks.
    Diagnose(DiagnoseArgs),
    /// Blind campaign: seeded cases with known effects, diagnosed without the answer, scored.
    ValidateDiagnosis(ValidateArgs),
    /// Inject sensor faults into a dataset's held-out part: detection latency and error per fault.
    Faults(FaultsArgs),
    /// Fuzz a loader with seeded, structure-aware mutations of valid inputs.
    Fuzz(FuzzArgs),
    /// Step the estimator for a long time on noisy input with random faults.
    Soak(SoakArgs),
}

#[derive(Debug, clap::Args)]
struct ValidateArgs {
    /// Number of cases (they cycle through no effect, every vocabulary effect and two outside it).
    #[arg(long, default_value_t = 140)]
    cases: usize,
    /// Master seed of the campaign.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Report folder (report.md, report.html, validation.json).
    #[arg(long)]
    report: PathBuf,
    /// Duration of every run of a case, s.
    #[arg(long = "duration-s", default_value_t = 30.0)]
    duration_s: f64,
    /// Only these classes (comma-separated: none, effect names).
    #[arg(long, value_delimiter = ',')]
    classes: Vec<String>,
    /// Keep every case's recording, model and signature in this folder (to rerun `diagnose`).
    #[arg(long)]
    keep: Option<PathBuf>,
    /// Score a campaign written by another program instead (tools/foreign-tunnel/campaign.py):
    /// its clean recording is fitted, every case diagnosed, then its sealed truths read.
    #[arg(long, conflicts_with_all = ["cases", "seed", "duration_s", "classes", "keep"])]
    campaign: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
struct DiagnoseArgs {
    /// The recorded ("real") dataset folder (or its manifest.toml).
    #[arg(long)]
    real: PathBuf,
    /// The sim: a model folder or model.bin (default: nominal models fitted on the training part
    /// of the data itself).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Report folder to write (diagnosis.json, report.md, report.html, SVG plots).
    #[arg(long)]
    report: PathBuf,
    /// Share of every run, at its end, that is held out.
    #[arg(long = "holdout-fraction", default_value_t = host_tools::fit::split::DEFAULT_HOLDOUT_FRACTION)]
    holdout_fraction: f64,
}

#[derive(Debug, clap::Args)]
struct QemuReplayArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    data: PathBuf,
    /// The run: its file as written in the manifest (e.g. runs/roll_actuation_a20.csv).
    #[arg(long)]
    run: PathBuf,
    /// Replay only the first N samples.
    #[arg(long)]
    samples: Option<usize>,
    /// Folder for the firmware's input, output, defmt log and summary (written completely or
    /// not at all).
    #[arg(long)]
    out: PathBuf,
    /// QEMU time limit, s.
    #[arg(long, default_value_t = 600)]
    timeout_s: u64,
    /// Read the sparse models from the tables instead of running their generated code (the cost
    /// of a coefficient set loaded at run time).
    #[arg(long)]
    interpreted: bool,
}

#[derive(Debug, clap::Args)]
struct HilArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    data: PathBuf,
    /// A run: its file as written in the manifest (e.g. runs/rollact_a20.csv); repeat it for
    /// several; without it, every run of the dataset.
    #[arg(long)]
    run: Vec<PathBuf>,
    /// Stream only the first N samples of each run.
    #[arg(long)]
    samples: Option<usize>,
    /// Send this model folder's coefficient blob (model.bin) over the link before the run;
    /// without it the firmware flies its built-in tables.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Folder for hil.json, summary.txt and the firmware's defmt logs (written completely or
    /// not at all).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Debug, clap::Args)]
struct ReplayArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    data: PathBuf,
    /// Model folder or model.bin (default: the built-in tables).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Folder for the per-run estimate CSVs (replaced atomically).
    #[arg(long)]
    out: PathBuf,
    /// Inject a sensor fault (repeatable), e.g. `stuck:cp07@10s`, `bias:cp02=0.3@5s`,
    /// `drop:phi=0.2`, `missing:cmu` (see firmware_sim::fault).
    #[arg(long = "fault", value_name = "SPEC")]
    faults: Vec<FaultSpec>,
    /// Seed of the faults' random choices.
    #[arg(long = "fault-seed", default_value_t = 1)]
    fault_seed: u64,
}

#[derive(Debug, clap::Args)]
struct EvaluateArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    data: PathBuf,
    /// Model folder or model.bin (default: the built-in tables).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Report folder to write (report.html, report.md, SVG plots, evaluation.json).
    #[arg(long)]
    report: PathBuf,
    /// Seed of the noise added in the robustness test.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Share of every run, at its end, that is evaluated (must match the fit's).
    #[arg(long = "holdout-fraction", default_value_t = host_tools::fit::split::DEFAULT_HOLDOUT_FRACTION)]
    holdout_fraction: f64,
}

#[derive(Debug, clap::Args)]
struct FitArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    data: PathBuf,
    /// Model folder to write (model.bin, model.md, model.json, plots); replaced atomically.
    #[arg(long)]
    out: PathBuf,
    /// Seed, recorded in the model card (the fit itself is deterministic).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Share of every run, at its end, held out from fitting.
    #[arg(long = "holdout-fraction", default_value_t = host_tools::fit::split::DEFAULT_HOLDOUT_FRACTION)]
    holdout_fraction: f64,
}

#[derive(Debug, clap::Args)]
struct CodegenArgs {
    /// Model folder (or its model.bin).
    #[arg(long)]
    model: PathBuf,
    /// Only compare with the committed file; fail if it is stale.
    #[arg(long)]
    check: bool,
    /// The generated file (default: estimator-core/src/coeffs/generated.rs of this workspace).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Where the tables come from, written into the generated file's header.
    #[arg(long)]
    provenance: Option<String>,
}

#[derive(Debug, clap::Args)]
struct SimulateArgs {
    /// Dataset folder to write (replaced atomically if it exists).
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    scenario: ScenarioArgs,
}

/// The scenario options shared by `simulate` and `sil`.
#[derive(Debug, clap::Args)]
struct ScenarioArgs {
    /// Scenario file (TOML: alphas, duration, seed, physical parameters, effects); keys it does
    /// not set keep the paper's values.
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

impl ScenarioArgs {
    /// The scenario file (or `default` without one) with the command line's overrides, and a
    /// description of where it came from.
    fn resolve(&self, default: Scenario, default_described: &str) -> anyhow::Result<(Scenario, String)> {
        let (mut scenario, mut described) = match &self.scenario {
            Some(path) => (Scenario::from_file(path)?, format!("`{}`", path.display())),
            None => (default, default_described.to_owned()),
        };
        if let Some(seed) = self.seed {
            scenario.seed = seed;
        }
        if let Some(duration_s) = self.duration_s {
            scenario.duration_s = duration_s;
        }
        for effect in &self.effects {
            scenario.apply_effect_arg(effect)?;
            described.push_str(&format!(", effect {effect}"));
        }
        scenario.validate()?;
        Ok((scenario, described))
    }
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
        Command::Fit(args) => fit(args),
        Command::Codegen(args) => codegen(args),
        Command::Replay(args) => replay(args),
        Command::Evaluate(args) => evaluate(args),
        Command::Sil(args) => sil(args),
        Command::QemuReplay(args) => qemu_replay(args),
        Command::Hil(args) => hil(args),
        Command::Diagnose(args) => diagnose(args),
        Command::ValidateDiagnosis(args) => validate_diagnosis(args),
        Command::Faults(args) => faults(args),
        Command::Fuzz(args) => fuzz(args),
        Command::Soak(args) => soak(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

/// `diagnose`: dataset (+ model) -> report folder with diagnosis.json.
fn diagnose(args: DiagnoseArgs) -> anyhow::Result<()> {
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
        Some(path) => {
            let folder =
                if path.is_dir() { path.clone() } else { path.parent().map(PathBuf::from).unwrap_or_default() };
            let file = folder.join(host_tools::diagnose::SIGNATURE_FILE);
            match std::fs::read_to_string(&file) {
                Ok(text) => Some(
                    serde_json::from_str(&text)
                        .with_context(|| format!("{}: not a diagnosis signature", file.display()))?,
                ),
                Err(_) => None,
            }
        }
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
fn validate_diagnosis(args: ValidateArgs) -> anyhow::Result<()> {
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
fn write_validation(
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

/// `simulate`: scenario -> synthetic tunnel -> dataset folder.
fn simulate(args: SimulateArgs) -> anyhow::Result<()> {
    let (scenario, _) = args.scenario.resolve(Scenario::default(), "the paper's campaign")?;
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

/// `fit`: dataset -> model folder.
fn fit(args: FitArgs) -> anyhow::Result<()> {
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
fn print_heldout(report: &host_tools::fit::pipeline::FitReport) {
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
fn codegen(args: CodegenArgs) -> anyhow::Result<()> {
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
fn replay(args: ReplayArgs) -> anyhow::Result<()> {
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

/// `qemu-replay`: the firmware in QEMU against the host replay, one run.
fn qemu_replay(args: QemuReplayArgs) -> anyhow::Result<()> {
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let run = dataset
        .runs
        .iter()
        .find(|run| run.meta.file == args.run)
        .with_context(|| format!("no run {} in {}", args.run.display(), args.data.display()))?;
    let timeout = std::time::Duration::from_secs(args.timeout_s);
    // QEMU works in a temporary folder that becomes `--out` only once the summary is written:
    // complete or absent, like every other output folder.
    let mut summary = String::new();
    firmware_sim::atomic::write_folder::<anyhow::Error>(&args.out, "summary.txt", |tmp| {
        let code = if args.interpreted { SparseCode::Interpreted } else { SparseCode::Compiled };
        let replay = host_tools::qemu::qemu_replay(run, args.samples, tmp, timeout, code)?;
        summary = host_tools::qemu::summary(&replay);
        std::fs::write(tmp.join("summary.txt"), &summary).context("writing summary.txt")
    })?;
    print!("{summary}");
    Ok(())
}

/// `hil`: the firmware's real-time loop in QEMU against the host's loop, run by run.
fn hil(args: HilArgs) -> anyhow::Result<()> {
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let runs: Vec<&firmware_sim::dataset::Run> = if args.run.is_empty() {
        dataset.runs.iter().collect()
    } else {
        args.run
            .iter()
            .map(|file| {
                dataset
                    .runs
                    .iter()
                    .find(|run| run.meta.file == *file)
                    .with_context(|| format!("no run {} in {}", file.display(), args.data.display()))
            })
            .collect::<anyhow::Result<_>>()?
    };
    let blob = match &args.model {
        Some(dir) => {
            let file = dir.join("model.bin");
            let bytes = std::fs::read(&file).with_context(|| format!("reading the blob {}", file.display()))?;
            Some((file, bytes))
        }
        None => None,
    };
    let (mut text, mut totals) = (String::new(), String::new());
    firmware_sim::atomic::write_folder::<anyhow::Error>(&args.out, "hil.json", |tmp| {
        let mut results = Vec::new();
        for run in &runs {
            let stem = run.meta.file.file_stem().map_or_else(|| "run".into(), |s| s.to_string_lossy().into_owned());
            let dir = tmp.join(&stem);
            std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
            let samples = host_tools::hil::samples_of(run, args.samples);
            let blob = blob.as_ref().map(|(file, bytes)| (file.as_path(), bytes.as_slice()));
            let result = host_tools::hil::hil(&run.meta.file, &samples, blob, &dir)
                .with_context(|| format!("hil of {}", run.meta.file.display()))?;
            let summary = host_tools::hil::summary(&result);
            eprint!("{summary}");
            text.push_str(&summary);
            results.push(result);
        }
        totals = host_tools::hil::totals(&results);
        text.push_str(&totals);
        std::fs::write(tmp.join("summary.txt"), &text).context("writing summary.txt")?;
        let json = serde_json::json!({ "runs": results, "totals": host_tools::hil::totals_json(&results) });
        std::fs::write(tmp.join("hil.json"), serde_json::to_string_pretty(&json)?).context("writing hil.json")
    })?;
    print!("{totals}");
    Ok(())
}

/// `evaluate`: the paper's analysis on held-out data, as a report folder.
fn evaluate(args: EvaluateArgs) -> anyhow::Result<()> {
    use host_tools::evaluate::{EvaluationConfig, Replayed, evaluate, evaluation_report, figures, with_balance_noise};
    let started = Instant::now();
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let (set, source) = host_tools::model::load(args.model.as_deref())?;
    let split = host_tools::fit::split::Split::with_holdout(args.holdout_fraction);
    let config = EvaluationConfig { split, seed: args.seed, ..EvaluationConfig::default() };
    let spinner = spinner("evaluating: replay, tables, noise sweep".into());
    let (evaluation, replayed) = evaluate(&dataset, &set, &config)?;
    spinner.set_message("evaluating: figures");
    let sigma = 0.001;
    let noisy = with_balance_noise(&dataset, sigma, args.seed);
    let fit_config = host_tools::fit::pipeline::FitConfig { split, ..Default::default() };
    let noisy_figure = match host_tools::fit::pipeline::refit_coupling(&noisy, &set, &fit_config) {
        Ok(refitted) => Some(Replayed::new(&noisy, &refitted)),
        Err(_) => None,
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
fn print_evaluation(evaluation: &host_tools::evaluate::Evaluation) {
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

fn spinner(message: String) -> ProgressBar {
    let spinner = ProgressBar::new_spinner();
    spinner.enable_steady_tick(std::time::Duration::from_millis(120));
    spinner.set_message(message);
    spinner
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

#[derive(Debug, clap::Args)]
struct SilArgs {
    /// Model folder or model.bin (default: the built-in tables).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Report folder to write (report.html, report.md, SVG plots, sil.json).
    #[arg(long)]
    report: PathBuf,
    /// The scenario; without a file, the paper's campaign at 20 s per run.
    #[command(flatten)]
    scenario: ScenarioArgs,
    /// Choose the feedback and causality gains by a grid search at another seed first.
    #[arg(long)]
    tune: bool,
    /// Seed of the gain search (default: the report's seed + 1).
    #[arg(long = "tune-seed")]
    tune_seed: Option<u64>,
    /// Causality filter time constant T_F, s (overrides the model's).
    #[arg(long = "causality-tau-s")]
    causality_tau_s: Option<f64>,
    /// Proportional feedback gain (overrides the model's).
    #[arg(long)]
    kp: Option<f64>,
    /// Integral feedback gain, 1/s (overrides the model's).
    #[arg(long)]
    ki: Option<f64>,
    /// Inject a sensor fault into every run (repeatable), e.g. `dead:cp03@5s`, `drop:cl=0.2`.
    #[arg(long = "fault", value_name = "SPEC")]
    faults: Vec<FaultSpec>,
}

/// `sil`: the controller scenarios in closed loop with the synthetic tunnel, as a report folder.
fn sil(args: SilArgs) -> anyhow::Result<()> {
    use firmware_sim::sil::{Gains, Mode, SilSettings, TuneGrid, run_scenario_with_faults, tune};
    let started = Instant::now();
    let default = Scenario { duration_s: 20.0, ..Scenario::default() };
    let (scenario, described) = args.scenario.resolve(default, "the paper's campaign, 20 s per run")?;
    let (model_set, source) = host_tools::model::load(args.model.as_deref())?;
    let settings = SilSettings::default();
    let mut tuning = None;
    let mut gains = Gains::of(&model_set);
    if args.tune {
        let tune_seed = args.tune_seed.unwrap_or(scenario.seed.wrapping_add(1));
        let tune_scenario = Scenario { seed: tune_seed, ..scenario.clone() };
        let grid = TuneGrid::default();
        let progress = progress_bar(grid.len() as u64, "gain search");
        let points = tune(&tune_scenario, &model_set, &grid, &settings, &|| progress.inc(1))?;
        progress.finish_and_clear();
        if let Some(best) = points.first() {
            gains = best.gains;
        }
        tuning = Some((tune_seed, points));
    }
    gains.causality_tau_s = args.causality_tau_s.unwrap_or(gains.causality_tau_s);
    gains.feedback_kp = args.kp.unwrap_or(gains.feedback_kp);
    gains.feedback_ki = args.ki.unwrap_or(gains.feedback_ki);
    let set = gains.apply(&model_set)?;
    let n_runs = scenario.alphas_deg.len() * Mode::ALL.len();
    let progress = progress_bar(n_runs as u64, "closed-loop runs");
    let results = run_scenario_with_faults(&scenario, &set, &Mode::ALL, &settings, &args.faults, &|| progress.inc(1))?;
    progress.set_message("writing the report");
    let mut described = described;
    for fault in &args.faults {
        described.push_str(&format!(", fault {fault}"));
    }
    let context = host_tools::sil::SilContext { model: source.to_string(), scenario: described, tuning };
    host_tools::sil::write_sil_report(&args.report, &results, &context)
        .with_context(|| format!("writing the report {}", args.report.display()))?;
    progress.finish_and_clear();
    println!("SIL, seed {}: RMS of C_l per scenario", results.seed);
    println!("  {}", host_tools::sil::summary_header().join(" | "));
    for row in host_tools::sil::summary_rows(&results) {
        println!("  {}", row.join(" | "));
    }
    println!("{}", host_tools::sil::verdict(&results));
    println!("report: {}", args.report.join("report.html").display());
    eprintln!("SIL in {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}

#[derive(Debug, clap::Args)]
struct FaultsArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    data: PathBuf,
    /// Model folder or model.bin (default: the built-in tables).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Report folder to write (report.md, report.html, faults.json).
    #[arg(long)]
    report: PathBuf,
    /// Seed of the faults' random choices (spikes, dropped samples).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Share of every run, at its end, that is held out (must match the fit's).
    #[arg(long = "holdout-fraction", default_value_t = host_tools::fit::split::DEFAULT_HOLDOUT_FRACTION)]
    holdout_fraction: f64,
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

/// `faults`: the sensor-fault study on held-out data, as a report folder.
fn faults(args: FaultsArgs) -> anyhow::Result<()> {
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
fn soak(args: SoakArgs) -> anyhow::Result<()> {
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

/// A bootstrap interval as `[low, high]` with each end written by `each`, `[-]` without one.
fn bracketed(interval: Option<[f64; 2]>, each: impl Fn(f64) -> String) -> String {
    interval.map_or_else(|| "[-]".to_owned(), |[low, high]| format!("[{}, {}]", each(low), each(high)))
}

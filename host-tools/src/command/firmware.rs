//! `sil`, `qemu-replay` and `hil`: the closed loop and the firmware in QEMU.

use std::fmt;
use std::path::PathBuf;
use std::time::Instant;

use firmware_sim::campaign::Scenario;
use firmware_sim::fault::FaultSpec;
use firmware_sim::sil::SilResults;

use super::closed_loop::{ClosedLoop, GainArgs, closed_loop};
use super::data::ScenarioArgs;
use super::{CommandError, Progress, run_named};
use rigs::hil::HilRun;
use rigs::qemu::{Program, QemuReplay, SparseCode};

/// The flags of `sil`.
#[derive(Debug, Clone, clap::Args)]
pub struct SilArgs {
    /// Model folder or model.bin (default: the built-in tables).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Report folder to write (report.html, report.md, SVG plots, sil.json).
    #[arg(long)]
    pub report: PathBuf,
    /// The scenario; without a file, the paper's campaign at 20 s per run.
    /// The scenario and its overrides.
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// How the controller's gains are chosen.
    #[command(flatten)]
    pub gains: GainArgs,
    /// Inject a sensor fault into every run (repeatable), e.g. `dead:cp03@5s`, `drop:cl=0.2`.
    #[arg(long = "fault", value_name = "SPEC")]
    pub faults: Vec<FaultSpec>,
}

/// The flags of `qemu-replay`.
#[derive(Debug, Clone, clap::Args)]
pub struct QemuReplayArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub data: PathBuf,
    /// The run: its file as written in the manifest (e.g. runs/rollact_a20.csv).
    #[arg(long)]
    pub run: PathBuf,
    /// Replay only the first N samples.
    #[arg(long)]
    pub samples: Option<usize>,
    /// Folder for the firmware's input, output, defmt log and summary (written completely or
    /// not at all).
    #[arg(long)]
    pub out: PathBuf,
    /// QEMU time limit, s.
    #[arg(long, default_value_t = 600)]
    pub timeout_s: u64,
    /// Read the sparse models from the tables instead of running their generated code (the cost
    /// of a coefficient set loaded at run time).
    #[arg(long, conflicts_with = "c_example")]
    pub interpreted: bool,
    /// Fly the C example instead of the Rust firmware: the estimator through its C interface
    /// (estimator-ffi/c-example, built with arm-none-eabi-gcc).
    #[arg(long = "c-example")]
    pub c_example: bool,
    /// With --c-example: the model folder (or its model.bin) whose blob the C program loads at
    /// run time; without it, the built-in tables fly.
    #[arg(long, requires = "c_example")]
    pub model: Option<PathBuf>,
}

/// The flags of `hil`.
#[derive(Debug, Clone, clap::Args)]
pub struct HilArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub data: PathBuf,
    /// A run: its file as written in the manifest (e.g. runs/rollact_a20.csv); repeat it for
    /// several; without it, every run of the dataset.
    #[arg(long)]
    pub run: Vec<PathBuf>,
    /// Stream only the first N samples of each run.
    #[arg(long)]
    pub samples: Option<usize>,
    /// Send this model folder's coefficient blob (model.bin) over the link before the run;
    /// without it the firmware flies its built-in tables.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Folder for hil.json, summary.txt and the firmware's defmt logs (written completely or
    /// not at all).
    #[arg(long)]
    pub out: PathBuf,
}

/// What `sil` ran and wrote.
#[derive(Debug, Clone)]
pub struct SilSummary {
    /// Every closed-loop run.
    pub results: SilResults,
    /// The report's HTML page.
    pub report: PathBuf,
    /// Wall time, s.
    pub elapsed_s: f64,
}

impl fmt::Display for SilSummary {
    /// RMS of the moment per scenario and mode, and the verdict.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "SIL, seed {}: RMS of C_l per scenario", self.results.seed)?;
        writeln!(f, "  {}", rigs::sil::summary_header().join(" | "))?;
        for row in rigs::sil::summary_rows(&self.results) {
            writeln!(f, "  {}", row.join(" | "))?;
        }
        writeln!(f, "{}", rigs::sil::verdict(&self.results))?;
        writeln!(f, "report: {}", self.report.display())
    }
}

/// `sil`: the controller scenarios in closed loop with the synthetic tunnel, as a report folder.
pub fn sil(args: &SilArgs, progress: &dyn Progress) -> Result<SilSummary, CommandError> {
    let started = Instant::now();
    let default = Scenario { duration_s: 20.0, ..Scenario::default() };
    let (scenario, described) = args.scenario.resolve(default, "the paper's campaign, 20 s per run")?;
    let (model_set, source) = model_fit::model::load(args.model.as_deref())?;
    let source = source.to_string();
    let ClosedLoop { results, context } =
        closed_loop(&scenario, &described, (&model_set, &source), &args.gains, &args.faults, progress)?;
    progress.stage("writing the report", None);
    rigs::sil::write_sil_report(&args.report, &results, &context).map_err(CommandError::write(&args.report))?;
    Ok(SilSummary { results, report: args.report.join("report.html"), elapsed_s: started.elapsed().as_secs_f64() })
}

/// What `qemu-replay` measured.
#[derive(Debug, Clone)]
pub struct QemuReplaySummary {
    /// The firmware's outputs against the host's, its instructions per step and memory.
    pub replay: QemuReplay,
    /// The output folder (`summary.txt` and QEMU's files).
    pub out: PathBuf,
}

impl fmt::Display for QemuReplaySummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&rigs::qemu::summary(&self.replay))
    }
}

/// `qemu-replay`: the firmware in QEMU against the host replay, one run. QEMU works in a
/// temporary folder that becomes `--out` only once the summary is written: complete or absent,
/// like every other output folder.
pub fn qemu_replay(args: &QemuReplayArgs, progress: &dyn Progress) -> Result<QemuReplaySummary, CommandError> {
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let run = run_named(&dataset, &args.run, &args.data)?;
    let timeout = std::time::Duration::from_secs(args.timeout_s);
    let program = if args.c_example {
        let blob = match &args.model {
            Some(path) => Some(model_fit::model::blob_bytes(path)?),
            None => None,
        };
        Program::CExample { blob }
    } else if args.interpreted {
        Program::Firmware(SparseCode::Interpreted)
    } else {
        Program::Firmware(SparseCode::Compiled)
    };
    progress.stage("building the firmware and replaying in QEMU", None);
    let mut done = None;
    firmware_sim::atomic::write_folder::<CommandError>(&args.out, "summary.txt", |tmp| {
        let replay = rigs::qemu::qemu_replay(run, args.samples, tmp, timeout, &program)
            .map_err(CommandError::firmware(format!("replaying {} in QEMU", args.run.display())))?;
        let path = tmp.join("summary.txt");
        std::fs::write(&path, rigs::qemu::summary(&replay)).map_err(CommandError::write(&path))?;
        done = Some(replay);
        Ok(())
    })?;
    let replay = done.ok_or_else(|| CommandError::Write {
        path: args.out.clone(),
        source: std::io::Error::other("the QEMU replay left no summary"),
    })?;
    Ok(QemuReplaySummary { replay, out: args.out.clone() })
}

/// What `hil` measured, run by run.
#[derive(Debug, Clone)]
pub struct HilSummary {
    /// Every run's comparison and timing.
    pub runs: Vec<HilRun>,
    /// The output folder (`summary.txt`, `hil.json`, one folder per run).
    pub out: PathBuf,
}

impl fmt::Display for HilSummary {
    /// The totals over the runs.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&rigs::hil::totals(&self.runs))
    }
}

/// `hil`: the firmware's real-time loop in QEMU against the host's loop, run by run; each
/// run's summary goes to `progress` as it finishes.
pub fn hil(args: &HilArgs, progress: &dyn Progress) -> Result<HilSummary, CommandError> {
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    let runs: Vec<&firmware_sim::dataset::Run> = if args.run.is_empty() {
        dataset.runs.iter().collect()
    } else {
        args.run.iter().map(|file| run_named(&dataset, file, &args.data)).collect::<Result<_, _>>()?
    };
    let blob = match &args.model {
        Some(dir) => {
            let file = dir.join("model.bin");
            let bytes = std::fs::read(&file)
                .map_err(|source| model_fit::model::ModelError::Io { path: file.clone(), source })?;
            Some((file, bytes))
        }
        None => None,
    };
    progress.stage("hardware in the loop", Some(runs.len() as u64));
    let mut results = Vec::new();
    firmware_sim::atomic::write_folder::<CommandError>(&args.out, "hil.json", |tmp| {
        let mut text = String::new();
        for run in &runs {
            let stem = run.meta.file.file_stem().map_or_else(|| "run".into(), |s| s.to_string_lossy().into_owned());
            let dir = tmp.join(&stem);
            std::fs::create_dir_all(&dir).map_err(CommandError::write(&dir))?;
            let samples = rigs::hil::samples_of(run, args.samples);
            let blob = blob.as_ref().map(|(file, bytes)| (file.as_path(), bytes.as_slice()));
            let result = rigs::hil::hil(&run.meta.file, &samples, blob, &dir)
                .map_err(CommandError::firmware(format!("hil of {}", run.meta.file.display())))?;
            let summary = rigs::hil::summary(&result);
            progress.stage(summary.trim_end(), None);
            progress.step();
            text.push_str(&summary);
            results.push(result);
        }
        text.push_str(&rigs::hil::totals(&results));
        let path = tmp.join("summary.txt");
        std::fs::write(&path, &text).map_err(CommandError::write(&path))?;
        let json = serde_json::json!({ "runs": results, "totals": rigs::hil::totals_json(&results) });
        let path = tmp.join("hil.json");
        let text = serde_json::to_string_pretty(&json).map_err(|error| CommandError::write(&path)(error.into()))?;
        std::fs::write(&path, text).map_err(CommandError::write(&path))
    })?;
    Ok(HilSummary { runs: results, out: args.out.clone() })
}

//! The command line's flags: one `clap` struct per subcommand (`shared/spec/cli.md`).

use std::path::PathBuf;

use firmware_sim::campaign::Scenario;
use firmware_sim::fault::FaultSpec;

use clap::{Parser, Subcommand};

#[derive(Debug, Parser)]
#[command(
    name = "host-tools",
    version,
    about = "Roll-moment estimator tools for a rolling delta wing with trailing-edge blowing"
)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Debug, Subcommand)]
pub(crate) enum Command {
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
}

#[derive(Debug, clap::Args)]
pub(crate) struct ValidateArgs {
    /// Number of cases (they cycle through no effect, every vocabulary effect and two outside it).
    #[arg(long, default_value_t = 140)]
    pub(crate) cases: usize,
    /// Master seed of the campaign.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Report folder (report.md, report.html, validation.json).
    #[arg(long)]
    pub(crate) report: PathBuf,
    /// Duration of every run of a case, s.
    #[arg(long = "duration-s", default_value_t = 30.0)]
    pub(crate) duration_s: f64,
    /// Only these classes (comma-separated: none, effect names).
    #[arg(long, value_delimiter = ',')]
    pub(crate) classes: Vec<String>,
    /// Keep every case's recording, model and signature in this folder (to rerun `diagnose`).
    #[arg(long)]
    pub(crate) keep: Option<PathBuf>,
    /// Score a campaign written by another program instead (tools/foreign-tunnel/campaign.py):
    /// its clean recording is fitted, every case diagnosed, then its sealed truths read.
    #[arg(long, conflicts_with_all = ["cases", "seed", "duration_s", "classes", "keep"])]
    pub(crate) campaign: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
pub(crate) struct DiagnoseArgs {
    /// The recorded ("real") dataset folder (or its manifest.toml).
    #[arg(long)]
    pub(crate) real: PathBuf,
    /// The sim: a model folder or model.bin (default: nominal models fitted on the training part
    /// of the data itself).
    #[arg(long)]
    pub(crate) model: Option<PathBuf>,
    /// Report folder to write (diagnosis.json, report.md, report.html, SVG plots).
    #[arg(long)]
    pub(crate) report: PathBuf,
    /// Share of every run, at its end, that is held out.
    #[arg(long = "holdout-fraction", default_value_t = host_tools::fit::split::DEFAULT_HOLDOUT_FRACTION)]
    pub(crate) holdout_fraction: f64,
}

#[derive(Debug, clap::Args)]
pub(crate) struct QemuReplayArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub(crate) data: PathBuf,
    /// The run: its file as written in the manifest (e.g. runs/roll_actuation_a20.csv).
    #[arg(long)]
    pub(crate) run: PathBuf,
    /// Replay only the first N samples.
    #[arg(long)]
    pub(crate) samples: Option<usize>,
    /// Folder for the firmware's input, output, defmt log and summary (written completely or
    /// not at all).
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// QEMU time limit, s.
    #[arg(long, default_value_t = 600)]
    pub(crate) timeout_s: u64,
    /// Read the sparse models from the tables instead of running their generated code (the cost
    /// of a coefficient set loaded at run time).
    #[arg(long)]
    pub(crate) interpreted: bool,
}

#[derive(Debug, clap::Args)]
pub(crate) struct HilArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub(crate) data: PathBuf,
    /// A run: its file as written in the manifest (e.g. runs/rollact_a20.csv); repeat it for
    /// several; without it, every run of the dataset.
    #[arg(long)]
    pub(crate) run: Vec<PathBuf>,
    /// Stream only the first N samples of each run.
    #[arg(long)]
    pub(crate) samples: Option<usize>,
    /// Send this model folder's coefficient blob (model.bin) over the link before the run;
    /// without it the firmware flies its built-in tables.
    #[arg(long)]
    pub(crate) model: Option<PathBuf>,
    /// Folder for hil.json, summary.txt and the firmware's defmt logs (written completely or
    /// not at all).
    #[arg(long)]
    pub(crate) out: PathBuf,
}

#[derive(Debug, clap::Args)]
pub(crate) struct ReplayArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub(crate) data: PathBuf,
    /// Model folder or model.bin (default: the built-in tables).
    #[arg(long)]
    pub(crate) model: Option<PathBuf>,
    /// Folder for the per-run estimate CSVs (replaced atomically).
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Inject a sensor fault (repeatable), e.g. `stuck:cp07@10s`, `bias:cp02=0.3@5s`,
    /// `drop:phi=0.2`, `missing:cmu` (see firmware_sim::fault).
    #[arg(long = "fault", value_name = "SPEC")]
    pub(crate) faults: Vec<FaultSpec>,
    /// Seed of the faults' random choices.
    #[arg(long = "fault-seed", default_value_t = 1)]
    pub(crate) fault_seed: u64,
}

#[derive(Debug, clap::Args)]
pub(crate) struct EvaluateArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub(crate) data: PathBuf,
    /// Model folder or model.bin (default: the built-in tables).
    #[arg(long)]
    pub(crate) model: Option<PathBuf>,
    /// Report folder to write (report.html, report.md, SVG plots, evaluation.json).
    #[arg(long)]
    pub(crate) report: PathBuf,
    /// Seed of the noise added in the robustness test.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Share of every run, at its end, that is evaluated (must match the fit's).
    #[arg(long = "holdout-fraction", default_value_t = host_tools::fit::split::DEFAULT_HOLDOUT_FRACTION)]
    pub(crate) holdout_fraction: f64,
}

#[derive(Debug, clap::Args)]
pub(crate) struct FitArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub(crate) data: PathBuf,
    /// Model folder to write (model.bin, model.md, model.json, plots); replaced atomically.
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Seed, recorded in the model card (the fit itself is deterministic).
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Share of every run, at its end, held out from fitting.
    #[arg(long = "holdout-fraction", default_value_t = host_tools::fit::split::DEFAULT_HOLDOUT_FRACTION)]
    pub(crate) holdout_fraction: f64,
}

#[derive(Debug, clap::Args)]
pub(crate) struct CodegenArgs {
    /// Model folder (or its model.bin).
    #[arg(long)]
    pub(crate) model: PathBuf,
    /// Only compare with the committed file; fail if it is stale.
    #[arg(long)]
    pub(crate) check: bool,
    /// The generated file (default: estimator-core/src/coeffs/generated.rs of this workspace).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Where the tables come from, written into the generated file's header.
    #[arg(long)]
    pub(crate) provenance: Option<String>,
}

#[derive(Debug, clap::Args)]
pub(crate) struct SimulateArgs {
    /// Dataset folder to write (replaced atomically if it exists).
    #[arg(long)]
    pub(crate) out: PathBuf,
    #[command(flatten)]
    pub(crate) scenario: ScenarioArgs,
}

/// The scenario options shared by `simulate` and `sil`.
#[derive(Debug, clap::Args)]
pub(crate) struct ScenarioArgs {
    /// Scenario file (TOML: alphas, duration, seed, physical parameters, effects); keys it does
    /// not set keep the paper's values.
    #[arg(long)]
    pub(crate) scenario: Option<PathBuf>,
    /// Master seed (overrides the scenario's).
    #[arg(long)]
    pub(crate) seed: Option<u64>,
    /// Duration of every run, s (overrides the scenario's).
    #[arg(long = "duration-s")]
    pub(crate) duration_s: Option<f64>,
    /// Switch an effect on: NAME or NAME:key=value,... (repeatable), e.g.
    /// `--effect actuator_delay:delay_s=0.03`.
    #[arg(long = "effect", value_name = "EFFECT")]
    pub(crate) effects: Vec<String>,
}

impl ScenarioArgs {
    /// The scenario file (or `default` without one) with the command line's overrides, and a
    /// description of where it came from.
    pub(crate) fn resolve(&self, default: Scenario, default_described: &str) -> anyhow::Result<(Scenario, String)> {
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
pub(crate) struct SuperpositionArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub(crate) data: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Debug, clap::Args)]
pub(crate) struct SilArgs {
    /// Model folder or model.bin (default: the built-in tables).
    #[arg(long)]
    pub(crate) model: Option<PathBuf>,
    /// Report folder to write (report.html, report.md, SVG plots, sil.json).
    #[arg(long)]
    pub(crate) report: PathBuf,
    /// The scenario; without a file, the paper's campaign at 20 s per run.
    #[command(flatten)]
    pub(crate) scenario: ScenarioArgs,
    /// Choose the feedback and causality gains by a grid search at another seed first.
    #[arg(long)]
    pub(crate) tune: bool,
    /// Seed of the gain search (default: the report's seed + 1).
    #[arg(long = "tune-seed")]
    pub(crate) tune_seed: Option<u64>,
    /// Causality filter time constant T_F, s (overrides the model's).
    #[arg(long = "causality-tau-s")]
    pub(crate) causality_tau_s: Option<f64>,
    /// Proportional feedback gain (overrides the model's).
    #[arg(long)]
    pub(crate) kp: Option<f64>,
    /// Integral feedback gain, 1/s (overrides the model's).
    #[arg(long)]
    pub(crate) ki: Option<f64>,
    /// Inject a sensor fault into every run (repeatable), e.g. `dead:cp03@5s`, `drop:cl=0.2`.
    #[arg(long = "fault", value_name = "SPEC")]
    pub(crate) faults: Vec<FaultSpec>,
}

#[derive(Debug, clap::Args)]
pub(crate) struct FaultsArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub(crate) data: PathBuf,
    /// Model folder or model.bin (default: the built-in tables).
    #[arg(long)]
    pub(crate) model: Option<PathBuf>,
    /// Report folder to write (report.md, report.html, faults.json).
    #[arg(long)]
    pub(crate) report: PathBuf,
    /// Seed of the faults' random choices (spikes, dropped samples).
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Share of every run, at its end, that is held out (must match the fit's).
    #[arg(long = "holdout-fraction", default_value_t = host_tools::fit::split::DEFAULT_HOLDOUT_FRACTION)]
    pub(crate) holdout_fraction: f64,
}

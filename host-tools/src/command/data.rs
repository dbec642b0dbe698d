//! `simulate` and `superposition`: recordings of the synthetic tunnel and the paper's Table 1.

use std::fmt;
use std::path::PathBuf;
use std::time::Instant;

use firmware_sim::campaign::Scenario;

use super::{CommandError, Progress};
use evaluation::analysis::superposition::{SuperpositionRow, superposition_table};

/// The flags of `simulate`.
#[derive(Debug, Clone, clap::Args)]
pub struct SimulateArgs {
    /// Dataset folder to write (replaced atomically if it exists).
    #[arg(long)]
    pub out: PathBuf,
    /// The scenario and its overrides.
    #[command(flatten)]
    pub scenario: ScenarioArgs,
}

/// The scenario options shared by `simulate` and `sil`.
#[derive(Debug, Clone, clap::Args)]
pub struct ScenarioArgs {
    /// Scenario file (TOML: alphas, duration, seed, physical parameters, effects); keys it does
    /// not set keep the paper's values.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Master seed (overrides the scenario's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Duration of every run, s (overrides the scenario's).
    #[arg(long = "duration-s")]
    pub duration_s: Option<f64>,
    /// Switch an effect on: NAME or NAME:key=value,... (repeatable), e.g.
    /// `--effect actuator_delay:delay_s=0.03`.
    #[arg(long = "effect", value_name = "EFFECT")]
    pub effects: Vec<String>,
}

impl ScenarioArgs {
    /// The scenario file (or `default` without one) with the command line's overrides, and a
    /// description of where it came from.
    pub fn resolve(&self, default: Scenario, default_described: &str) -> Result<(Scenario, String), CommandError> {
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

/// The flags of `superposition`.
#[derive(Debug, Clone, clap::Args)]
pub struct SuperpositionArgs {
    /// Dataset folder (or its manifest.toml).
    #[arg(long)]
    pub data: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// What `simulate` wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulateSummary {
    /// The dataset folder.
    pub out: PathBuf,
    /// Runs written.
    pub n_runs: usize,
    /// Wall time, s.
    pub elapsed_s: f64,
}

impl fmt::Display for SimulateSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "wrote {} runs to {} in {:.1} s", self.n_runs, self.out.display(), self.elapsed_s)
    }
}

/// `simulate`: scenario -> synthetic tunnel -> dataset folder (complete or absent).
pub fn simulate(args: &SimulateArgs, progress: &dyn Progress) -> Result<SimulateSummary, CommandError> {
    let (scenario, _) = args.scenario.resolve(Scenario::default(), "the paper's campaign")?;
    let started = Instant::now();
    let n_runs = scenario.alphas_deg.len() * scenario.kinds.len();
    progress.stage("simulating runs", Some(n_runs as u64));
    let dataset = scenario.simulate(&|| progress.step())?;
    progress.stage("writing the dataset", None);
    firmware_sim::dataset::write_dataset(&args.out, &dataset)?;
    Ok(SimulateSummary {
        out: args.out.clone(),
        n_runs: dataset.runs.len(),
        elapsed_s: started.elapsed().as_secs_f64(),
    })
}

/// The paper's Table 1 of a dataset.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(transparent)]
pub struct SuperpositionSummary {
    /// One row per angle of attack.
    pub rows: Vec<SuperpositionRow>,
}

impl fmt::Display for SuperpositionSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "Table 1: validity of superposition, Delta C_l = C_l,RollAFC - C_l,Roll - C_l,AFC")?;
        writeln!(
            f,
            "{:>9}  {:>22}  {:>22}  {:>12}  {:>12}",
            "alpha_deg", "sigma(dCl)/mean(ClRA)", "sigma(dCl)/sigma(ClRA)", "sigma(dCl)", "mean(ClRA)"
        )?;
        for row in &self.rows {
            writeln!(
                f,
                "{:>9.1}  {:>21.1}%  {:>21.1}%  {:>12.3e}  {:>12.3e}",
                row.alpha_deg,
                100.0 * row.ratio_to_mean,
                100.0 * row.ratio_to_std,
                row.delta_std,
                row.rollact_mean
            )?;
        }
        Ok(())
    }
}

/// `superposition`: the paper's Table 1 for a dataset.
pub fn superposition(args: &SuperpositionArgs) -> Result<SuperpositionSummary, CommandError> {
    let dataset = firmware_sim::dataset::load_dataset(&args.data)?;
    Ok(SuperpositionSummary { rows: superposition_table(&dataset)? })
}

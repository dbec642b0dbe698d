//! The closed loop behind `sil`: the controller scenarios of one coefficient set in closed loop
//! with the synthetic tunnel, with the gains chosen as the flags say. No rig is needed, so the
//! Python package runs it too (a sweep over scenarios, `rollest.sil_sweep`); `sil` adds the
//! report folder.

use estimator_core::CoefficientSet;
use firmware_sim::campaign::Scenario;
use firmware_sim::fault::FaultSpec;
use firmware_sim::sil::{Gains, Mode, SilContext, SilResults, SilSettings, TuneGrid, run_scenario_with_faults, tune};

use super::{CommandError, Progress};

/// How `sil` chooses the controller's gains: the model's, searched on another seed first, and
/// overridden one by one.
#[derive(Debug, Clone, Default, PartialEq, clap::Args)]
pub struct GainArgs {
    /// Choose the feedback and causality gains by a grid search at another seed first.
    #[arg(long)]
    pub tune: bool,
    /// Seed of the gain search (default: the report's seed + 1).
    #[arg(long = "tune-seed")]
    pub tune_seed: Option<u64>,
    /// Causality filter time constant T_F, s (overrides the model's).
    #[arg(long = "causality-tau-s")]
    pub causality_tau_s: Option<f64>,
    /// Proportional feedback gain (overrides the model's).
    #[arg(long)]
    pub kp: Option<f64>,
    /// Integral feedback gain, 1/s (overrides the model's).
    #[arg(long)]
    pub ki: Option<f64>,
}

/// One scenario in closed loop: every run, and how they were produced (`sil.json`'s context).
#[derive(Debug, Clone)]
pub struct ClosedLoop {
    /// Every (alpha, mode) run.
    pub results: SilResults,
    /// The model's and the scenario's sources, the faults, the gain search.
    pub context: SilContext,
}

/// Runs every mode of [`Mode::ALL`] at every alpha of `scenario` (`described` says where it
/// came from) with `model` (its set and source), the gains chosen by `gains`, and `faults`
/// injected into every run.
pub fn closed_loop(
    scenario: &Scenario,
    described: &str,
    model: (&CoefficientSet, &str),
    gains: &GainArgs,
    faults: &[FaultSpec],
    progress: &dyn Progress,
) -> Result<ClosedLoop, CommandError> {
    let (model_set, source) = model;
    let settings = SilSettings::default();
    let mut tuning = None;
    let mut chosen = Gains::of(model_set);
    if gains.tune {
        let tune_seed = gains.tune_seed.unwrap_or(scenario.seed.wrapping_add(1));
        let tune_scenario = Scenario { seed: tune_seed, ..scenario.clone() };
        let grid = TuneGrid::default();
        progress.stage("gain search", Some(grid.len() as u64));
        let points = tune(&tune_scenario, model_set, &grid, &settings, &|| progress.step())?;
        if let Some(best) = points.first() {
            chosen = best.gains;
        }
        tuning = Some((tune_seed, points));
    }
    chosen.causality_tau_s = gains.causality_tau_s.unwrap_or(chosen.causality_tau_s);
    chosen.feedback_kp = gains.kp.unwrap_or(chosen.feedback_kp);
    chosen.feedback_ki = gains.ki.unwrap_or(chosen.feedback_ki);
    let set = chosen.apply(model_set)?;
    let n_runs = scenario.alphas_deg.len() * Mode::ALL.len();
    progress.stage("closed-loop runs", Some(n_runs as u64));
    let results = run_scenario_with_faults(scenario, &set, &Mode::ALL, &settings, faults, &|| progress.step())?;
    let mut described = described.to_owned();
    for fault in faults {
        described.push_str(&format!(", fault {fault}"));
    }
    Ok(ClosedLoop { results, context: SilContext { model: source.to_owned(), scenario: described, tuning } })
}

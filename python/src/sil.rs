//! One scenario in closed loop (`host-tools sil` without its report folder): the unit of work of
//! `rollest.sil_sweep`, which sends one to each worker. The scenario comes as TOML text, so a
//! worker on another machine needs no file of the coordinating process.

use firmware_sim::campaign::Scenario;
use firmware_sim::fault::FaultSpec;
use firmware_sim::sil::SilRecord;
use host_tools::command::closed_loop::{ClosedLoop, GainArgs, closed_loop};
use host_tools::command::data::ScenarioArgs;
use pyo3::prelude::*;

use crate::error::{RollestError, command_error, other_error};
use crate::model::Model;
use crate::workflow::Callback;

/// Runs every controller mode at every alpha of the scenario (the paper's campaign at 20 s per
/// run when `scenario_toml` is None; `scenario_name` names the text in errors and in the
/// record) with `model` (the built-in tables when None), overridden and with the gains and
/// faults as `host-tools sil`'s flags of the same names: `sil.json` as text.
#[pyfunction]
#[pyo3(signature = (
    model = None, scenario_toml = None, scenario_name = None, seed = None, duration_s = None,
    effects = Vec::new(), faults = Vec::new(), tune = false, tune_seed = None, causality_tau_s = None,
    kp = None, ki = None, progress = None,
))]
#[expect(clippy::too_many_arguments, reason = "the command line's flags, one keyword each in Python")]
pub fn sil(
    py: Python<'_>,
    model: Option<&Model>,
    scenario_toml: Option<String>,
    scenario_name: Option<String>,
    seed: Option<u64>,
    duration_s: Option<f64>,
    effects: Vec<String>,
    faults: Vec<String>,
    tune: bool,
    tune_seed: Option<u64>,
    causality_tau_s: Option<f64>,
    kp: Option<f64>,
    ki: Option<f64>,
    progress: Option<Py<PyAny>>,
) -> PyResult<String> {
    let (base, described) = match &scenario_toml {
        Some(text) => {
            let name = scenario_name.unwrap_or_else(|| "the scenario given".to_owned());
            let scenario = Scenario::from_bytes(&name, text.as_bytes()).map_err(|error| other_error(&error))?;
            (scenario, format!("`{name}`"))
        }
        None => (Scenario { duration_s: 20.0, ..Scenario::default() }, "the paper's campaign, 20 s per run".to_owned()),
    };
    let overrides = ScenarioArgs { scenario: None, seed, duration_s, effects };
    let (scenario, described) = overrides.resolve(base, &described).map_err(command_error)?;
    let faults = faults
        .iter()
        .map(|spec| {
            spec.parse::<FaultSpec>().map_err(|error| RollestError::new_err(format!("fault \"{spec}\": {error}")))
        })
        .collect::<PyResult<Vec<_>>>()?;
    let gains = GainArgs { tune, tune_seed, causality_tau_s, kp, ki };
    let built_in = estimator_core::coeffs::DEFAULT;
    let (set, source) = match model {
        Some(model) => (&*model.set, model.source_name().to_owned()),
        None => (&built_in, model_fit::model::ModelSource::BuiltIn.to_string()),
    };
    let callback = Callback::new(progress);
    let ran = py.detach(|| closed_loop(&scenario, &described, (set, &source), &gains, &faults, &callback));
    let ClosedLoop { results, context } = callback.finish(ran.map_err(command_error))?;
    serde_json::to_string(&SilRecord::new(&results, &context)).map_err(|error| other_error(&error))
}

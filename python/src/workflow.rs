//! The command line's workflows in-process: `simulate`, `fit`, `evaluate` and `diagnose` are
//! `host_tools::command` functions called with the command line's own argument structs (one
//! definition of every default), without the GIL, reporting progress to an optional Python
//! callable.

use std::path::PathBuf;

use host_tools::command::data::{ScenarioArgs, SimulateArgs};
use host_tools::command::diagnosis::DiagnoseArgs;
use host_tools::command::model::{EvaluateArgs, FitArgs};
use host_tools::command::{self, Progress};
use pyo3::prelude::*;
use std::sync::Mutex;

use crate::error::command_error;
use crate::model::Model;

/// A command's progress passed to a Python callable `progress(message, done, total)`: at each
/// new stage `done` is 0 and `total` its number of steps (None when not counted); each step
/// done calls it again with the count so far. The commands run on worker threads without the
/// GIL; each call takes it. The first exception the callable raises is kept, and raised when
/// the command returns.
struct Callback {
    callable: Option<Py<PyAny>>,
    /// The present stage: message, steps done, steps in all.
    stage: Mutex<(String, u64, Option<u64>)>,
    raised: Mutex<Option<PyErr>>,
}

impl Callback {
    fn new(callable: Option<Py<PyAny>>) -> Self {
        Self { callable, stage: Mutex::new((String::new(), 0, None)), raised: Mutex::new(None) }
    }

    fn call(&self, message: &str, done: u64, total: Option<u64>) {
        let Some(callable) = &self.callable else { return };
        Python::attach(|py| {
            if let Err(error) = callable.call1(py, (message, done, total)) {
                let mut raised = self.raised.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
                raised.get_or_insert(error);
            }
        });
    }

    /// The command's result, or the callable's first exception.
    fn finish<T>(self, result: PyResult<T>) -> PyResult<T> {
        match self.raised.into_inner().unwrap_or_else(std::sync::PoisonError::into_inner) {
            Some(error) => Err(error),
            None => result,
        }
    }
}

impl Progress for Callback {
    fn stage(&self, message: &str, steps: Option<u64>) {
        if self.callable.is_none() {
            return;
        }
        *self.stage.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = (message.to_owned(), 0, steps);
        self.call(message, 0, steps);
    }

    fn step(&self) {
        if self.callable.is_none() {
            return;
        }
        let (message, done, total) = {
            let mut stage = self.stage.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            stage.1 += 1;
            stage.clone()
        };
        self.call(&message, done, total);
    }
}

/// Writes a synthetic-tunnel campaign into `out` (the scenario file's values, overridden by the
/// arguments given); returns the number of runs.
#[pyfunction]
#[pyo3(signature = (out, scenario = None, seed = None, duration_s = None, effects = Vec::new(), progress = None))]
pub fn simulate(
    py: Python<'_>,
    out: PathBuf,
    scenario: Option<PathBuf>,
    seed: Option<u64>,
    duration_s: Option<f64>,
    effects: Vec<String>,
    progress: Option<Py<PyAny>>,
) -> PyResult<usize> {
    let args = SimulateArgs { out, scenario: ScenarioArgs { scenario, seed, duration_s, effects } };
    let callback = Callback::new(progress);
    let summary = py.detach(|| command::data::simulate(&args, &callback)).map_err(command_error);
    Ok(callback.finish(summary)?.n_runs)
}

/// Fits every coefficient on the training part of `data` and writes the model folder `out`.
#[pyfunction]
#[pyo3(signature = (data, out, seed = 1, holdout_fraction = model_fit::fit::split::DEFAULT_HOLDOUT_FRACTION, progress = None))]
pub fn fit(
    py: Python<'_>,
    data: PathBuf,
    out: PathBuf,
    seed: u64,
    holdout_fraction: f64,
    progress: Option<Py<PyAny>>,
) -> PyResult<Model> {
    let args = FitArgs { data, out, seed, holdout_fraction };
    let callback = Callback::new(progress);
    let summary = py.detach(|| command::model::fit(&args, &callback)).map_err(command_error);
    Model::from_folder(&callback.finish(summary)?.out)
}

/// The paper's analysis of `model` (the built-in tables when None) on the held-out part of
/// `data`, written into the report folder `report`; returns the report's page and the
/// evaluation's warnings.
#[pyfunction]
#[pyo3(signature = (data, report, model = None, seed = 1, holdout_fraction = model_fit::fit::split::DEFAULT_HOLDOUT_FRACTION, progress = None))]
pub fn evaluate(
    py: Python<'_>,
    data: PathBuf,
    report: PathBuf,
    model: Option<PathBuf>,
    seed: u64,
    holdout_fraction: f64,
    progress: Option<Py<PyAny>>,
) -> PyResult<(PathBuf, Vec<String>)> {
    let args = EvaluateArgs { data, model, report, seed, holdout_fraction };
    let callback = Callback::new(progress);
    let summary = py.detach(|| command::model::evaluate(&args, &callback)).map_err(command_error);
    let summary = callback.finish(summary)?;
    Ok((summary.report, summary.warnings))
}

/// The sim-to-real gap diagnosis of `real` against `model` (nominal models fitted on the data's
/// training part when None), written into the report folder `report`; returns the page.
#[pyfunction]
#[pyo3(signature = (real, report, model = None, holdout_fraction = model_fit::fit::split::DEFAULT_HOLDOUT_FRACTION, progress = None))]
pub fn diagnose(
    py: Python<'_>,
    real: PathBuf,
    report: PathBuf,
    model: Option<PathBuf>,
    holdout_fraction: f64,
    progress: Option<Py<PyAny>>,
) -> PyResult<PathBuf> {
    let args = DiagnoseArgs { real, model, report, holdout_fraction };
    let callback = Callback::new(progress);
    let summary = py.detach(|| command::diagnosis::diagnose(&args, &callback)).map_err(command_error);
    Ok(callback.finish(summary)?.report)
}

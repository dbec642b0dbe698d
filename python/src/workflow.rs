//! The command line's workflows in-process: `simulate`, `fit`, `evaluate` and `diagnose` are
//! `host_tools::command` functions called with the command line's own argument structs (one
//! definition of every default), without the GIL, reporting progress to an optional Python
//! callable.

use std::path::PathBuf;

use host_tools::command::data::{ScenarioArgs, SimulateArgs};
use host_tools::command::{self, Progress};
use pyo3::prelude::*;
use std::sync::Mutex;

use crate::dataset::Dataset;
use crate::error::command_error;
use crate::model::Model;

/// A command's progress passed to a Python callable `progress(message, done, total)`: at each
/// new stage `done` is 0 and `total` its number of steps (None when not counted); each step
/// done calls it again with the count so far. The commands run on worker threads without the
/// GIL; each call takes it. The first exception the callable raises is kept, and raised when
/// the command returns.
pub(crate) struct Callback {
    callable: Option<Py<PyAny>>,
    /// The present stage: message, steps done, steps in all.
    stage: Mutex<(String, u64, Option<u64>)>,
    raised: Mutex<Option<PyErr>>,
}

impl Callback {
    pub(crate) fn new(callable: Option<Py<PyAny>>) -> Self {
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
    pub(crate) fn finish<T>(self, result: PyResult<T>) -> PyResult<T> {
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

/// Fits every coefficient on the training part of `dataset`, in memory; with `out`, the model
/// folder is written there too (complete or not at all), as `host-tools fit --out` writes it.
#[pyfunction]
#[pyo3(signature = (dataset, out = None, seed = 1, holdout_fraction = model_fit::fit::split::DEFAULT_HOLDOUT_FRACTION, progress = None))]
pub fn fit(
    py: Python<'_>,
    dataset: &Dataset,
    out: Option<PathBuf>,
    seed: u64,
    holdout_fraction: f64,
    progress: Option<Py<PyAny>>,
) -> PyResult<Model> {
    let split = split_of(holdout_fraction)?;
    let origin = dataset.origin();
    let described = format!("{} (seed {seed})", origin.display());
    let callback = Callback::new(progress);
    let data = &dataset.inner;
    let fitted = py
        .detach(|| {
            let fitted = command::model::fit_loaded(data, &origin, &described, split, &callback)?;
            if let Some(out) = &out {
                callback.stage("writing the model folder", None);
                model_fit::fit::card::write_model_files(out, &fitted.files)?;
            }
            Ok::<_, command::CommandError>(fitted)
        })
        .map_err(command_error);
    let fitted = callback.finish(fitted)?;
    let source = match &out {
        Some(out) => model_fit::model::ModelSource::File(out.join(model_fit::model::BLOB_FILE)).to_string(),
        None => format!("the fit of {described}, in memory"),
    };
    Ok(Model::fitted(fitted, source, out))
}

/// The paper's analysis of `model` (the built-in tables when None) on the held-out part of
/// `dataset`: `evaluation.json` as text, and with `report` the report folder written there
/// (its page returned); the evaluation's warnings.
#[pyfunction]
#[pyo3(signature = (dataset, model = None, report = None, seed = 1, holdout_fraction = model_fit::fit::split::DEFAULT_HOLDOUT_FRACTION, progress = None))]
pub fn evaluate(
    py: Python<'_>,
    dataset: &Dataset,
    model: Option<&Model>,
    report: Option<PathBuf>,
    seed: u64,
    holdout_fraction: f64,
    progress: Option<Py<PyAny>>,
) -> PyResult<(String, Option<PathBuf>, Vec<String>)> {
    let split = split_of(holdout_fraction)?;
    let origin = dataset.origin();
    let built_in = estimator_core::coeffs::DEFAULT;
    let (set, source) = match model {
        Some(model) => (&*model.set, model.source_name().to_owned()),
        None => (&built_in, model_fit::model::ModelSource::BuiltIn.to_string()),
    };
    let callback = Callback::new(progress);
    let data = &dataset.inner;
    let evaluated = py
        .detach(|| {
            let evaluated = command::model::evaluate_loaded(data, &origin, set, &source, seed, split, &callback)?;
            if let Some(folder) = &report {
                reports::write_report(folder, &evaluated.report, "evaluation.json", &evaluated.json)
                    .map_err(command::CommandError::write(folder))?;
            }
            Ok::<_, command::CommandError>(evaluated)
        })
        .map_err(command_error);
    let evaluated = callback.finish(evaluated)?;
    let json = serde_json::to_string(&evaluated.json).map_err(|error| crate::error::other_error(&error))?;
    Ok((json, report.map(|folder| folder.join("report.html")), evaluated.warnings))
}

/// The sim-to-real gap diagnosis of `dataset` against `model` (nominal models fitted on the
/// data's training part when None) with the model's own diagnosis signature (the built-in
/// model's when it has none): `diagnosis.json` as text, and with `report` the report folder
/// written there (its page returned).
#[pyfunction]
#[pyo3(signature = (dataset, model = None, report = None, holdout_fraction = model_fit::fit::split::DEFAULT_HOLDOUT_FRACTION, progress = None))]
pub fn diagnose(
    py: Python<'_>,
    dataset: &Dataset,
    model: Option<&Model>,
    report: Option<PathBuf>,
    holdout_fraction: f64,
    progress: Option<Py<PyAny>>,
) -> PyResult<(String, Option<PathBuf>)> {
    let split = split_of(holdout_fraction)?;
    let origin = dataset.origin();
    let signature = model.map(Model::signature).transpose()?.flatten();
    let sim = model.map(|model| (&*model.set, model.source_name().to_owned()));
    let callback = Callback::new(progress);
    let data = &dataset.inner;
    let diagnosed = py
        .detach(|| {
            let (diagnosis, page) =
                command::diagnosis::diagnose_loaded(data, &origin, sim, signature, split, &callback)?;
            let json = serde_json::to_value(&diagnosis)
                .map_err(|error| command::CommandError::write(report.as_deref().unwrap_or(&origin))(error.into()))?;
            if let Some(folder) = &report {
                reports::write_report(folder, &page, "diagnosis.json", &json)
                    .map_err(command::CommandError::write(folder))?;
            }
            Ok::<_, command::CommandError>(json)
        })
        .map_err(command_error);
    let json = callback.finish(diagnosed)?;
    let text = serde_json::to_string(&json).map_err(|error| crate::error::other_error(&error))?;
    Ok((text, report.map(|folder| folder.join("report.html"))))
}

/// The split of a holdout fraction, or the command line's error for it.
fn split_of(holdout_fraction: f64) -> PyResult<model_fit::fit::split::Split> {
    command::holdout_split(holdout_fraction).map_err(command_error)
}

//! The command line's workflows in-process: `simulate`, `fit`, `evaluate` and `diagnose` are
//! `host_tools::command` functions called with the command line's own argument structs (one
//! definition of every default), without the GIL and without a progress bar.

use std::path::PathBuf;

use host_tools::command::data::{ScenarioArgs, SimulateArgs};
use host_tools::command::diagnosis::DiagnoseArgs;
use host_tools::command::model::{EvaluateArgs, FitArgs};
use host_tools::command::{self, Silent};
use pyo3::prelude::*;

use crate::error::command_error;
use crate::model::Model;

/// Writes a synthetic-tunnel campaign into `out` (the scenario file's values, overridden by the
/// arguments given); returns the number of runs.
#[pyfunction]
#[pyo3(signature = (out, scenario = None, seed = None, duration_s = None, effects = Vec::new()))]
pub fn simulate(
    py: Python<'_>,
    out: PathBuf,
    scenario: Option<PathBuf>,
    seed: Option<u64>,
    duration_s: Option<f64>,
    effects: Vec<String>,
) -> PyResult<usize> {
    let args = SimulateArgs { out, scenario: ScenarioArgs { scenario, seed, duration_s, effects } };
    let summary = py.detach(|| command::data::simulate(&args, &Silent)).map_err(command_error)?;
    Ok(summary.n_runs)
}

/// Fits every coefficient on the training part of `data` and writes the model folder `out`.
#[pyfunction]
#[pyo3(signature = (data, out, seed = 1, holdout_fraction = host_tools::fit::split::DEFAULT_HOLDOUT_FRACTION))]
pub fn fit(py: Python<'_>, data: PathBuf, out: PathBuf, seed: u64, holdout_fraction: f64) -> PyResult<Model> {
    let args = FitArgs { data, out, seed, holdout_fraction };
    let summary = py.detach(|| command::model::fit(&args, &Silent)).map_err(command_error)?;
    Model::from_folder(&summary.out)
}

/// The paper's analysis of `model` (the built-in tables when None) on the held-out part of
/// `data`, written into the report folder `report`; returns the report's page and the
/// evaluation's warnings.
#[pyfunction]
#[pyo3(signature = (data, report, model = None, seed = 1, holdout_fraction = host_tools::fit::split::DEFAULT_HOLDOUT_FRACTION))]
pub fn evaluate(
    py: Python<'_>,
    data: PathBuf,
    report: PathBuf,
    model: Option<PathBuf>,
    seed: u64,
    holdout_fraction: f64,
) -> PyResult<(PathBuf, Vec<String>)> {
    let args = EvaluateArgs { data, model, report, seed, holdout_fraction };
    let summary = py.detach(|| command::model::evaluate(&args, &Silent)).map_err(command_error)?;
    Ok((summary.report, summary.warnings))
}

/// The sim-to-real gap diagnosis of `real` against `model` (nominal models fitted on the data's
/// training part when None), written into the report folder `report`; returns the page.
#[pyfunction]
#[pyo3(signature = (real, report, model = None, holdout_fraction = host_tools::fit::split::DEFAULT_HOLDOUT_FRACTION))]
pub fn diagnose(
    py: Python<'_>,
    real: PathBuf,
    report: PathBuf,
    model: Option<PathBuf>,
    holdout_fraction: f64,
) -> PyResult<PathBuf> {
    let args = DiagnoseArgs { real, model, report, holdout_fraction };
    let summary = py.detach(|| command::diagnosis::diagnose(&args, &Silent)).map_err(command_error)?;
    Ok(summary.report)
}

//! `rollest._rollest`: the Python extension module of the `rollest` package.
//!
//! The same engine as the command line, in-process: the dataset loader, the synthetic tunnel, the
//! fit, the replay, the evaluation and the diagnosis are `host_tools::command` and
//! `firmware_sim::dataset` functions called with the command line's own argument structs, and
//! the estimator is estimator-core's f32 `Estimator`, stepped exactly as `host-tools replay`
//! steps it. The Python package (`python/rollest/__init__.py`) wraps this module with
//! NumPy/pandas conveniences and the type stubs an editor reads.
//!
//! Long calls release the GIL (`Python::detach`), so a notebook's other threads keep running.

mod campaign;
mod dataset;
mod error;
mod estimator;
mod model;
mod sil;
mod sindy;
mod workflow;

use pyo3::prelude::*;

/// The extension module.
#[pymodule]
fn _rollest(module: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = module.py();
    module.add("RollestError", py.get_type::<error::RollestError>())?;
    module.add("DatasetError", py.get_type::<error::DatasetError>())?;
    module.add_class::<dataset::Dataset>()?;
    module.add_class::<model::Model>()?;
    module.add_class::<estimator::Estimator>()?;
    module.add_class::<campaign::BlindCampaign>()?;
    module.add_class::<campaign::ForeignCampaign>()?;
    module.add_function(wrap_pyfunction!(dataset::load_dataset, module)?)?;
    module.add_function(wrap_pyfunction!(dataset::dataset_from_parts, module)?)?;
    module.add_function(wrap_pyfunction!(dataset::heldout_start, module)?)?;
    module.add_function(wrap_pyfunction!(workflow::simulate, module)?)?;
    module.add_function(wrap_pyfunction!(workflow::fit, module)?)?;
    module.add_function(wrap_pyfunction!(workflow::evaluate, module)?)?;
    module.add_function(wrap_pyfunction!(workflow::diagnose, module)?)?;
    module.add_function(wrap_pyfunction!(sil::sil, module)?)?;
    module.add_function(wrap_pyfunction!(sindy::stlsq, module)?)?;
    module.add("REPLAY_COLUMNS", model_fit::replay::REPLAY_COLUMNS.to_vec())?;
    module.add("ESTIMATE_COLUMNS", model_fit::replay::ESTIMATE_COLUMNS.to_vec())?;
    module.add("HEALTH_COLUMNS", model_fit::replay::HEALTH_COLUMNS.to_vec())?;
    module.add("DEFAULT_HOLDOUT_FRACTION", model_fit::fit::split::DEFAULT_HOLDOUT_FRACTION)?;
    // The package's version is the workspace's (pyproject.toml takes it from Cargo.toml).
    module.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}

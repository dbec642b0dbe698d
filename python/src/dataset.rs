//! `load_dataset`: a dataset folder (the contract of `docs/spec/dataset-format.md`) read by
//! firmware-sim's loader, its runs as NumPy arrays and its manifest as JSON for the Python side.

use std::path::PathBuf;
use std::sync::Arc;

use firmware_sim::dataset::Run;
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error::dataset_error;

/// A loaded dataset (the Python package's `Dataset` wraps it).
#[pyclass(module = "rollest._rollest", frozen)]
pub struct Dataset {
    pub(crate) inner: Arc<firmware_sim::dataset::Dataset>,
    pub(crate) path: PathBuf,
}

/// Reads a dataset folder (or its manifest.toml); raises `DatasetError` naming the file, row,
/// column or key on bad input.
#[pyfunction]
pub fn load_dataset(py: Python<'_>, path: PathBuf) -> PyResult<Dataset> {
    let loaded = py.detach(|| firmware_sim::dataset::load_dataset(&path));
    let inner = loaded.map_err(|error| dataset_error(&error))?;
    Ok(Dataset { inner: Arc::new(inner), path })
}

/// The first held-out sample of a run of `n_samples` when the final `holdout_fraction` of every
/// run is held out (the split of `fit`, `evaluate` and `diagnose`).
#[pyfunction]
pub fn heldout_start(n_samples: usize, holdout_fraction: f64) -> usize {
    model_fit::fit::split::Split::with_holdout(holdout_fraction).heldout(n_samples).start
}

#[pymethods]
impl Dataset {
    /// The folder (or manifest) it was read from.
    #[getter]
    fn path(&self) -> PathBuf {
        self.path.clone()
    }

    fn __len__(&self) -> usize {
        self.inner.runs.len()
    }

    /// The manifest's metadata as JSON: `tunnel`, `wing`, `extra` and `runs` (each run's `file`,
    /// `kind`, `alpha_deg`, `sample_hz`, `n_samples` and `extra`).
    fn manifest_json(&self) -> PyResult<String> {
        let dataset = &self.inner;
        let runs: Vec<serde_json::Value> = dataset
            .runs
            .iter()
            .map(|run| {
                serde_json::json!({
                    "file": run.meta.file.display().to_string(),
                    "kind": run.meta.kind.as_str(),
                    "alpha_deg": run.meta.alpha_deg,
                    "sample_hz": run.meta.sample_hz,
                    "n_samples": run.channels.len(),
                    "extra": run.meta.extra,
                })
            })
            .collect();
        let json = serde_json::json!({
            "tunnel": {
                "u_inf_mps": dataset.tunnel.u_inf_mps,
                "rho_kgm3": dataset.tunnel.rho_kgm3,
                "dynamic_pressure_pa": dataset.tunnel.dynamic_pressure_pa(),
            },
            "wing": {
                "chord_m": dataset.wing.chord_m,
                "span_m": dataset.wing.span_m,
                "area_m2": dataset.wing.area_m2,
                "ixx_kgm2": dataset.wing.ixx_kgm2,
                "mass_kg": dataset.wing.mass_kg,
            },
            "extra": dataset.extra,
            "runs": runs,
        });
        serde_json::to_string(&json).map_err(|error| crate::error::other_error(&error))
    }

    /// The channels of run `index` (manifest order) as float64 arrays, by the contract's column
    /// names (`cl` in C_l even when the file had `mx_nm`); optional channels only when recorded.
    fn run_arrays<'py>(&self, py: Python<'py>, index: usize) -> PyResult<Bound<'py, PyDict>> {
        let run = self.run(index)?;
        let channels = &run.channels;
        let columns = PyDict::new(py);
        let add = |name: &str, values: &[f64]| columns.set_item(name, PyArray1::from_slice(py, values));
        add("t_s", &channels.t_s)?;
        add("phi_deg", &channels.phi_deg)?;
        if let Some(alpha) = &channels.alpha_deg {
            add("alpha_deg", alpha)?;
        }
        add("cmu_port", &channels.cmu_port)?;
        add("cmu_stbd", &channels.cmu_stbd)?;
        for (tap, values) in channels.cp.iter().enumerate() {
            add(&format!("cp{:02}", tap + 1), values)?;
        }
        add("cl", &channels.cl)?;
        for (name, values) in [
            ("phi_cmd_deg", &channels.phi_cmd_deg),
            ("cmu_port_cmd", &channels.cmu_port_cmd),
            ("cmu_stbd_cmd", &channels.cmu_stbd_cmd),
        ] {
            if let Some(values) = values {
                add(name, values)?;
            }
        }
        Ok(columns)
    }
}

impl Dataset {
    /// Run `index`, or an `IndexError`.
    pub(crate) fn run(&self, index: usize) -> PyResult<&Run> {
        self.inner.runs.get(index).ok_or_else(|| {
            pyo3::exceptions::PyIndexError::new_err(format!(
                "run index {index}: expected below {}, the dataset's number of runs",
                self.inner.runs.len()
            ))
        })
    }
}

//! `load_dataset`: a dataset folder (the contract of `docs/spec/dataset-format.md`) read by
//! firmware-sim's loader, its runs as NumPy arrays and its manifest as JSON for the Python side.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use firmware_sim::dataset::{DatasetError as LoadError, Run, RunKind, RunMeta, Tunnel, Wing};
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error::dataset_error;

/// A dataset, read from a folder or built in memory (the Python package's `Dataset` wraps it).
#[pyclass(module = "rollest._rollest", frozen)]
pub struct Dataset {
    pub(crate) inner: Arc<firmware_sim::dataset::Dataset>,
    /// The folder (or manifest) it was read from; None when built in memory.
    pub(crate) path: Option<PathBuf>,
}

/// Where a dataset built in memory would lie: errors name its manifest and run files under it.
const IN_MEMORY: &str = "<in memory>";

/// Reads a dataset folder (or its manifest.toml); raises `DatasetError` naming the file, row,
/// column or key on bad input.
#[pyfunction]
pub fn load_dataset(py: Python<'_>, path: PathBuf) -> PyResult<Dataset> {
    let loaded = py.detach(|| firmware_sim::dataset::load_dataset(&path));
    let inner = loaded.map_err(|error| dataset_error(&error))?;
    Ok(Dataset { inner: Arc::new(inner), path: Some(path) })
}

/// The manifest's metadata a dataset built in memory takes, as the Python side passes it (JSON:
/// the names of `docs/spec/dataset-format.md`).
#[derive(Debug, serde::Deserialize)]
struct Metadata {
    tunnel: TunnelMeta,
    wing: Option<WingMeta>,
    #[serde(default)]
    extra: toml::Table,
    runs: Vec<RunMetadata>,
}

#[derive(Debug, serde::Deserialize)]
struct TunnelMeta {
    u_inf_mps: f64,
    rho_kgm3: f64,
}

#[derive(Debug, serde::Deserialize)]
struct WingMeta {
    chord_m: f64,
    span_m: f64,
    area_m2: f64,
    ixx_kgm2: f64,
    mass_kg: f64,
}

#[derive(Debug, serde::Deserialize)]
struct RunMetadata {
    file: String,
    kind: String,
    alpha_deg: f64,
    sample_hz: f64,
    #[serde(default)]
    extra: toml::Table,
}

/// A dataset from the manifest's metadata (`metadata_json`) and each run's columns by name
/// (float64 arrays), checked as a folder is when read: a `DatasetError` names the run's file,
/// the row, the column or the manifest key, under the folder `<in memory>`.
#[pyfunction]
pub fn dataset_from_parts(
    py: Python<'_>,
    metadata_json: &str,
    runs: Vec<Vec<(String, PyReadonlyArray1<'_, f64>)>>,
) -> PyResult<Dataset> {
    let folder = Path::new(IN_MEMORY);
    let manifest = folder.join("manifest.toml");
    let metadata: Metadata = serde_json::from_str(metadata_json).map_err(|error| {
        dataset_error(&LoadError::BadValue {
            file: manifest.clone(),
            key: "metadata".into(),
            expected: "the manifest's tunnel, wing, extra and runs",
            found: error.to_string(),
        })
    })?;
    if metadata.runs.len() != runs.len() {
        return Err(dataset_error(&LoadError::BadValue {
            file: manifest,
            key: "run".into(),
            expected: "one entry of metadata per run",
            found: format!("{} entries for {} runs", metadata.runs.len(), runs.len()),
        }));
    }
    let tunnel = Tunnel { u_inf_mps: metadata.tunnel.u_inf_mps, rho_kgm3: metadata.tunnel.rho_kgm3 };
    let wing = metadata.wing.map_or(Wing::PAPER, |w| Wing {
        chord_m: w.chord_m,
        span_m: w.span_m,
        area_m2: w.area_m2,
        ixx_kgm2: w.ixx_kgm2,
        mass_kg: w.mass_kg,
    });
    let columns: Vec<Vec<(String, Vec<f64>)>> = runs
        .iter()
        .map(|run| run.iter().map(|(name, values)| (name.clone(), values.as_array().to_vec())).collect())
        .collect();
    let built = py.detach(|| -> Result<firmware_sim::dataset::Dataset, LoadError> {
        let mut built = Vec::with_capacity(columns.len());
        for (index, (meta, columns)) in metadata.runs.into_iter().zip(columns).enumerate() {
            let kind = RunKind::parse(&meta.kind).ok_or_else(|| LoadError::UnknownKind {
                file: manifest.clone(),
                run_index: index + 1,
                found: meta.kind.clone(),
            })?;
            let file = PathBuf::from(&meta.file);
            let channels = firmware_sim::dataset::channels_from_columns(&folder.join(&file), columns, &tunnel, &wing)?;
            let meta = RunMeta { file, kind, alpha_deg: meta.alpha_deg, sample_hz: meta.sample_hz, extra: meta.extra };
            built.push(Run { meta, channels });
        }
        let dataset = firmware_sim::dataset::Dataset { tunnel, wing, extra: metadata.extra, runs: built };
        firmware_sim::dataset::check_dataset(folder, &dataset)?;
        Ok(dataset)
    });
    let inner = built.map_err(|error| dataset_error(&error))?;
    Ok(Dataset { inner: Arc::new(inner), path: None })
}

/// The first held-out sample of a run of `n_samples` when the final `holdout_fraction` of every
/// run is held out (the split of `fit`, `evaluate` and `diagnose`).
#[pyfunction]
pub fn heldout_start(n_samples: usize, holdout_fraction: f64) -> usize {
    model_fit::fit::split::Split::with_holdout(holdout_fraction).heldout(n_samples).start
}

#[pymethods]
impl Dataset {
    /// The folder (or manifest) it was read from; None when built in memory.
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        self.path.clone()
    }

    /// Writes the dataset into the folder `path` in the format (`docs/spec/dataset-format.md`),
    /// completely or not at all; reading it back gives the same values, bit for bit.
    fn write(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let dataset = &self.inner;
        py.detach(|| firmware_sim::dataset::write_dataset(&path, dataset)).map_err(|error| dataset_error(&error))
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
    /// A dataset built in memory (drawn by a campaign, say).
    pub(crate) fn in_memory(dataset: firmware_sim::dataset::Dataset) -> Self {
        Self { inner: Arc::new(dataset), path: None }
    }

    /// Where the data came from, as reports and errors name it: the folder it was read from,
    /// or `<in memory>`.
    pub(crate) fn origin(&self) -> PathBuf {
        self.path.clone().unwrap_or_else(|| PathBuf::from(IN_MEMORY))
    }

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

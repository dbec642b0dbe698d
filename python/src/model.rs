//! `Model`: a coefficient set with its model folder's files (blob, card, report, plots), loaded,
//! fitted or built in; saved as a model folder the command line reads; replayed over a dataset.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use diagnosis::diagnose::SIGNATURE_FILE;
use estimator_core::CoefficientSet;
use firmware_sim::campaign::mix_seed;
use firmware_sim::fault::{FaultSpec, apply_to_run};
use model_fit::model::{BLOB_FILE, ModelError};
use model_fit::replay::{RECORDED_COLUMNS, recorded_at};
use numpy::PyArray1;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use crate::dataset::Dataset;
use crate::error::other_error;
use crate::estimator::outputs_dict;

/// A model (the Python package's `Model` wraps it).
#[pyclass(module = "rollest._rollest", frozen)]
pub struct Model {
    pub(crate) set: Arc<CoefficientSet>,
    /// Where it came from, for reports.
    source: String,
    /// The model folder or blob file it was read from (None for the built-in tables): what
    /// the command line's `--model` takes.
    path: Option<PathBuf>,
    /// The folder's files, read when loaded (so that saving does not depend on the folder
    /// staying as it was): name and bytes.
    files: Vec<(String, Vec<u8>)>,
}

impl Model {
    /// Reads a model folder (or its model.bin): the set, and every file of the folder.
    pub(crate) fn read(path: &Path) -> Result<Self, ModelError> {
        let (set, source) = model_fit::model::load(Some(path))?;
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| ModelError::Io { path, source }
        };
        let mut files = Vec::new();
        if path.is_dir() {
            for entry in std::fs::read_dir(path).map_err(io(path))? {
                let entry = entry.map_err(io(path))?;
                let name = entry.file_name().to_string_lossy().into_owned();
                if entry.file_type().map_err(io(&entry.path()))?.is_file() && !name.starts_with('.') {
                    files.push((name, std::fs::read(entry.path()).map_err(io(&entry.path()))?));
                }
            }
            files.sort();
        } else {
            files.push((BLOB_FILE.to_owned(), std::fs::read(path).map_err(io(path))?));
            // The command line's `--model` takes the signature beside a blob too.
            let beside = path.parent().unwrap_or(Path::new("")).join(SIGNATURE_FILE);
            if beside.is_file() {
                files.push((SIGNATURE_FILE.to_owned(), std::fs::read(&beside).map_err(io(&beside))?));
            }
        }
        Ok(Self { set: Arc::new(set), source: source.to_string(), path: Some(path.to_path_buf()), files })
    }

    /// A model fitted in memory: `path` is the folder it was also written to, if any.
    pub(crate) fn fitted(
        fitted: host_tools::command::model::FittedModel,
        source: String,
        path: Option<PathBuf>,
    ) -> Self {
        Self { set: Arc::new(fitted.set), source, path, files: fitted.files }
    }

    /// A model from its coefficient set and diagnosis signature alone (no fit report): what a
    /// campaign hands to the processes that diagnose its cases.
    pub(crate) fn from_set(
        set: CoefficientSet,
        signature: &diagnosis::diagnose::Signature,
        source: String,
    ) -> PyResult<Self> {
        let blob = model_fit::model::encode(&set).map_err(|error| other_error(&error))?;
        let signature = serde_json::to_vec_pretty(signature).map_err(|error| other_error(&error))?;
        let files = vec![(BLOB_FILE.to_owned(), blob), (SIGNATURE_FILE.to_owned(), signature)];
        Ok(Self { set: Arc::new(set), source, path: None, files })
    }

    /// The model's diagnosis signature (written by the fit beside the blob), when it has one.
    pub(crate) fn signature(&self) -> PyResult<Option<diagnosis::diagnose::Signature>> {
        let Some((_, bytes)) = self.files.iter().find(|(name, _)| name == SIGNATURE_FILE) else { return Ok(None) };
        serde_json::from_slice(bytes).map(Some).map_err(|error| {
            crate::error::RollestError::new_err(format!(
                "{}: expected the model's diagnosis signature (JSON), found: {error}",
                self.path
                    .as_deref()
                    .map_or_else(|| SIGNATURE_FILE.to_owned(), |path| path.join(SIGNATURE_FILE).display().to_string())
            ))
        })
    }

    /// Where it came from, for reports.
    pub(crate) fn source_name(&self) -> &str {
        &self.source
    }

    fn file(&self, name: &str) -> Option<String> {
        self.files.iter().find(|(file, _)| file == name).map(|(_, bytes)| String::from_utf8_lossy(bytes).into_owned())
    }
}

#[pymethods]
impl Model {
    /// Reads a model folder (or its model.bin).
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        py.detach(|| Self::read(&path)).map_err(|error| other_error(&error))
    }

    /// The tables compiled into the estimator.
    #[staticmethod]
    fn built_in() -> PyResult<Self> {
        let set = estimator_core::coeffs::DEFAULT;
        let blob = model_fit::model::encode(&set).map_err(|error| other_error(&error))?;
        Ok(Self {
            set: Arc::new(set),
            source: model_fit::model::ModelSource::BuiltIn.to_string(),
            path: None,
            files: vec![(BLOB_FILE.to_owned(), blob)],
        })
    }

    /// A model from its folder's files (name, bytes), as [`Self::files`] gives them: how a
    /// model travels to another process (pickling). `path` is where it was read from, if
    /// anywhere.
    #[staticmethod]
    #[pyo3(signature = (source, files, path = None))]
    fn from_files(source: String, files: Vec<(String, Vec<u8>)>, path: Option<PathBuf>) -> PyResult<Self> {
        let blob = files
            .iter()
            .find(|(name, _)| name == BLOB_FILE)
            .ok_or_else(|| crate::error::RollestError::new_err(format!("expected a file named {BLOB_FILE}")))?;
        let set = estimator_core::blob::decode(&blob.1).map_err(|error| other_error(&error))?;
        Ok(Self { set: Arc::new(set), source, path, files })
    }

    /// The model folder's files (name, bytes): what [`Self::from_files`] takes.
    fn files(&self) -> Vec<(String, Vec<u8>)> {
        self.files.clone()
    }

    /// Where it came from.
    #[getter]
    fn source(&self) -> String {
        self.source.clone()
    }

    /// The model folder or blob file it was read from (None for the built-in tables).
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        self.path.clone()
    }

    /// The fixed step, s.
    #[getter]
    fn dt_s(&self) -> f32 {
        self.set.dt_s
    }

    /// Writes the model folder (every file it was read or fitted with; model.bin alone for the
    /// built-in tables), complete or not at all.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let files = &self.files;
        let written = py.detach(|| model_fit::fit::card::write_model_files(&path, files));
        written.map_err(|error| other_error(&error))
    }

    /// The coefficient set as JSON (every table by its field name).
    fn coefficients_json(&self) -> PyResult<String> {
        serde_json::to_string(&*self.set).map_err(|error| other_error(&error))
    }

    /// The model card (model.md), when the folder has one.
    fn card(&self) -> Option<String> {
        self.file("model.md")
    }

    /// model.json (the fit's report, the held-out table among it), when the folder has one.
    fn model_json(&self) -> Option<String> {
        self.file("model.json")
    }

    /// The blob (what `rollest_init_blob` and the firmware load).
    fn blob<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let blob = model_fit::model::encode(&self.set).map_err(|error| other_error(&error))?;
        Ok(PyBytes::new(py, &blob))
    }

    /// Replays every run of `dataset` (in parallel, without the GIL) as `host-tools replay`
    /// does, with the sensor `faults` of `--fault` when given; per run, the replay file's
    /// columns as arrays.
    #[pyo3(signature = (dataset, faults = Vec::new(), fault_seed = 1))]
    fn replay<'py>(
        &self,
        py: Python<'py>,
        dataset: &Dataset,
        faults: Vec<String>,
        fault_seed: u64,
    ) -> PyResult<Vec<Bound<'py, PyDict>>> {
        use rayon::prelude::*;
        let faults: Vec<FaultSpec> = faults
            .iter()
            .map(|spec| spec.parse().map_err(|error| PyValueError::new_err(format!("fault {spec:?}: {error}"))))
            .collect::<PyResult<_>>()?;
        let (set, data) = (&*self.set, &dataset.inner);
        let replayed: Vec<_> = py.detach(|| {
            data.runs
                .par_iter()
                .enumerate()
                .map(|(idx, run)| {
                    let run = if faults.is_empty() {
                        std::borrow::Cow::Borrowed(run)
                    } else {
                        std::borrow::Cow::Owned(apply_to_run(run, &faults, mix_seed(fault_seed, idx as u64)))
                    };
                    let outputs = model_fit::replay::replay_run(set, &run);
                    (run, outputs)
                })
                .collect()
        });
        replayed
            .iter()
            .map(|(run, outputs)| {
                let columns = outputs_dict(py, outputs)?;
                for (idx, name) in RECORDED_COLUMNS.iter().enumerate() {
                    let values: Vec<f64> = (0..run.channels.len()).map(|k| recorded_at(run, k)[idx]).collect();
                    columns.set_item(*name, PyArray1::from_vec(py, values))?;
                }
                Ok(columns)
            })
            .collect()
    }
}

//! Blind validation campaigns of the diagnosis whose cases are diagnosed elsewhere (other
//! processes or machines, `rollest.validate_diagnosis` over an `Executor`): the coordinating
//! process draws the cases (or opens another program's campaign), hands out only the blind
//! recordings and the models, keeps the truths sealed here, and scores every case only once
//! every diagnosis is back, with the command line's rules and report.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Mutex;

use diagnosis::validate::external::Campaign;
use diagnosis::validate::{CampaignConfig, CaseRecord, CleanModels, Diagnosed, DrawnCase, Sealed};
use pyo3::prelude::*;
use rayon::prelude::*;

use crate::dataset::Dataset;
use crate::error::{RollestError, other_error};
use crate::model::Model;

/// Per case: its id, its `diagnosis.json` as text, and the seconds the diagnosis took.
type Diagnoses = Vec<(usize, String, f64)>;

/// A campaign of this project's tunnel (`host-tools validate-diagnosis --cases --seed`), drawn
/// here case by case; the truths of the cases drawn stay in this object until [`Self::score`].
#[pyclass(module = "rollest._rollest", frozen)]
pub struct BlindCampaign {
    config: CampaignConfig,
    models: CleanModels,
    sealed: Mutex<BTreeMap<usize, Sealed>>,
}

#[pymethods]
impl BlindCampaign {
    /// The campaign of `cases` cases of `duration_s` s runs from the master `seed` (only the
    /// `classes` named, and only the cases `only`, when given), as the command line draws it.
    #[new]
    #[pyo3(signature = (cases = 140, seed = 1, duration_s = 30.0, classes = Vec::new(), only = Vec::new()))]
    fn new(cases: usize, seed: u64, duration_s: f64, classes: Vec<String>, only: Vec<usize>) -> PyResult<Self> {
        if let Some(id) = only.iter().find(|id| **id >= cases) {
            return Err(RollestError::new_err(format!("only: must name case ids below cases ({cases}), found {id}")));
        }
        let known: Vec<&str> =
            diagnosis::validate::classes().into_iter().map(diagnosis::validate::class_name).collect();
        if let Some(class) = classes.iter().find(|class| !known.contains(&class.as_str())) {
            return Err(RollestError::new_err(format!(
                "classes: expected some of {}, found {class:?}",
                known.join(", ")
            )));
        }
        let config = CampaignConfig { cases, seed, duration_s, classes, only, ..CampaignConfig::default() };
        Ok(Self { config, models: CleanModels::default(), sealed: Mutex::new(BTreeMap::new()) })
    }

    /// The ids of the campaign's cases.
    fn ids(&self) -> Vec<usize> {
        diagnosis::validate::case_ids(&self.config)
    }

    /// Draws the cases `ids` (in parallel, without the GIL): per case, its id, the blind
    /// recording and the model fitted on a clean recording (with its diagnosis signature). A
    /// case that cannot be drawn is left out, as the command line leaves it out. The truths stay
    /// here.
    fn draw(&self, py: Python<'_>, ids: Vec<usize>) -> PyResult<Vec<(usize, Dataset, Model)>> {
        if let Some(id) = ids.iter().find(|id| **id >= self.config.cases) {
            return Err(RollestError::new_err(format!("case {id}: expected an id below {}", self.config.cases)));
        }
        let (config, models) = (&self.config, &self.models);
        let drawn: Vec<DrawnCase> =
            py.detach(|| ids.par_iter().filter_map(|&id| diagnosis::validate::draw_case(config, id, models)).collect());
        let mut sealed = self.sealed.lock().map_err(|_| RollestError::new_err("the campaign's truths are poisoned"))?;
        drawn
            .into_iter()
            .map(|DrawnCase { real, set, signature, sealed: truth }| {
                let id = truth.id();
                sealed.insert(id, truth);
                let model = Model::from_set(set, &signature, "fitted on a clean recording".to_owned())?;
                Ok((id, Dataset::in_memory(real), model))
            })
            .collect()
    }

    /// Scores every drawn case from its diagnosis (id, `diagnosis.json` text, seconds), once
    /// every drawn case has one: `validation.json` as text, and the report folder written to
    /// `report` when given (its page returned).
    #[pyo3(signature = (diagnoses, described, report = None))]
    fn score(
        &self,
        py: Python<'_>,
        diagnoses: Diagnoses,
        described: String,
        report: Option<PathBuf>,
    ) -> PyResult<(String, Option<PathBuf>)> {
        let sealed = self.sealed.lock().map_err(|_| RollestError::new_err("the campaign's truths are poisoned"))?;
        let mut by_id = parse(diagnoses)?;
        if let Some(id) = sealed.keys().find(|id| !by_id.contains_key(id)) {
            return Err(RollestError::new_err(format!(
                "case {id} has no diagnosis: every drawn case is diagnosed before any truth is read"
            )));
        }
        if let Some(id) = by_id.keys().find(|id| !sealed.contains_key(id)) {
            return Err(RollestError::new_err(format!("case {id} was diagnosed but never drawn")));
        }
        let records: Vec<CaseRecord> =
            sealed.iter().filter_map(|(id, truth)| Some(truth.clone().score(by_id.remove(id)?))).collect();
        let config = format!("{:?}", self.config);
        written(py, &records, &described, &config, report)
    }
}

/// A campaign written by another program (`host-tools validate-diagnosis --campaign DIR`):
/// its index is read here; its truths only by [`Self::score`].
#[pyclass(module = "rollest._rollest", frozen)]
pub struct ForeignCampaign {
    campaign: Campaign,
}

#[pymethods]
impl ForeignCampaign {
    /// Opens the campaign in the folder `dir` (reads its index).
    #[new]
    fn new(dir: PathBuf) -> PyResult<Self> {
        Campaign::open(&dir).map(|campaign| Self { campaign }).map_err(|error| other_error(&error))
    }

    /// The campaign's master seed.
    #[getter]
    fn seed(&self) -> u64 {
        self.campaign.seed()
    }

    /// The model fitted on the campaign's clean recording, with its diagnosis signature.
    fn fit(&self, py: Python<'_>) -> PyResult<Model> {
        let (set, signature) = py.detach(|| self.campaign.fit_clean()).map_err(|error| other_error(&error))?;
        Model::from_set(set, &signature, "fitted on the clean recording".to_owned())
    }

    /// Every case's id and dataset folder.
    fn cases(&self) -> Vec<(usize, PathBuf)> {
        self.campaign.cases()
    }

    /// Scores every case from its diagnosis (id, `diagnosis.json` text, seconds), once every
    /// case has one; only then are the truth files read and checked against their hashes.
    #[pyo3(signature = (diagnoses, described, report = None))]
    fn score(
        &self,
        py: Python<'_>,
        diagnoses: Diagnoses,
        described: String,
        report: Option<PathBuf>,
    ) -> PyResult<(String, Option<PathBuf>)> {
        let mut by_id = parse(diagnoses)?;
        let mut ordered = Vec::new();
        for (id, _) in self.campaign.cases() {
            let diagnosed = by_id.remove(&id).ok_or_else(|| {
                RollestError::new_err(format!(
                    "case {id} has no diagnosis: every case is diagnosed before any truth is read"
                ))
            })?;
            ordered.push(diagnosed);
        }
        let records = self.campaign.score(ordered).map_err(|error| other_error(&error))?;
        let config = format!("campaign {}", self.campaign.dir().display());
        written(py, &records, &described, &config, report)
    }
}

/// The diagnoses by case id, read as the contract's `diagnosis.json`.
fn parse(diagnoses: Diagnoses) -> PyResult<BTreeMap<usize, Diagnosed>> {
    let mut by_id = BTreeMap::new();
    for (id, text, seconds) in diagnoses {
        let json: serde_json::Value = serde_json::from_str(&text)
            .map_err(|error| RollestError::new_err(format!("case {id}: expected diagnosis.json, found: {error}")))?;
        if by_id.insert(id, Diagnosed::from_contract(&json, seconds)).is_some() {
            return Err(RollestError::new_err(format!("case {id}: expected one diagnosis, found two")));
        }
    }
    Ok(by_id)
}

/// `validation.json` of the scored `records` as text, and the report folder written to `report`
/// when given (its page).
fn written(
    py: Python<'_>,
    records: &[CaseRecord],
    described: &str,
    config: &str,
    report: Option<PathBuf>,
) -> PyResult<(String, Option<PathBuf>)> {
    let scored = host_tools::command::diagnosis::validation_report(records, described, config);
    if let Some(folder) = &report {
        py.detach(|| reports::write_report(folder, &scored.report, "validation.json", &scored.json))
            .map_err(|error| other_error(&error))?;
    }
    let text = serde_json::to_string(&scored.json).map_err(|error| other_error(&error))?;
    Ok((text, report.map(|folder| folder.join("report.html"))))
}

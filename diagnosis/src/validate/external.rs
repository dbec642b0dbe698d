//! A blind campaign written by another program (`validate-diagnosis --campaign DIR`): the
//! second, independent tunnel's cases (tools/foreign-tunnel/campaign.py), each a dataset with
//! one withheld effect, a clean recording to fit the model on, and the truth of every case
//! sealed in its own file whose SHA-256 the campaign's index recorded when it was written.
//!
//! The model is fitted on the clean recording, every case is diagnosed, and only then is each
//! truth file read, checked against its hash and scored with the same rules and the same
//! table as the own tunnel's campaign ([`super::score`]).
//!
//! The layout (`format = "foreign-campaign/1"`):
//!
//! ```text
//! DIR/campaign.json        {"format", "seed", "clean": "clean",
//!                           "cases": [{"id", "data": "cases/case-000", "truth": "sealed/case-000.json", "truth_sha256"}]}
//! DIR/clean/               the clean recording (a dataset)
//! DIR/cases/case-NNN/      one dataset per case
//! DIR/sealed/case-NNN.json {"id", "class", "form", "params", "channels", "ratio", "stream", "alpha_deg", "seed", ...}
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::Deserialize;

use super::{CaseRecord, Diagnosed, Sealed};
use crate::diagnose::{DiagnoseConfig, diagnose};
use model_fit::fit::pipeline::{FitConfig, fit_dataset};

/// The format string of a campaign's index.
pub const FORMAT: &str = "foreign-campaign/1";

/// Why an external campaign could not be run or scored.
#[derive(Debug, thiserror::Error)]
pub enum ExternalError {
    /// The index could not be read.
    #[error("{path}: {message}")]
    Index {
        /// The index file.
        path: PathBuf,
        /// What was wrong.
        message: String,
    },
    /// A dataset could not be loaded.
    #[error(transparent)]
    Dataset(#[from] firmware_sim::dataset::DatasetError),
    /// The clean recording could not be fitted.
    #[error("fitting the clean recording {path}: {source}")]
    Fit {
        /// The clean recording.
        path: PathBuf,
        /// The fit's error.
        source: model_fit::fit::FitError,
    },
    /// The clean recording's signature could not be taken.
    #[error("the signature of the clean recording: {0}")]
    Signature(#[from] crate::diagnose::DiagnoseError),
    /// A truth file is missing, unreadable, altered since the campaign was written, or malformed.
    #[error("{path}: {message}")]
    Truth {
        /// The truth file.
        path: PathBuf,
        /// What was wrong.
        message: String,
    },
}

#[derive(Debug, Clone, Deserialize)]
struct Index {
    format: String,
    seed: u64,
    clean: String,
    cases: Vec<IndexCase>,
}

#[derive(Debug, Clone, Deserialize)]
struct IndexCase {
    id: usize,
    data: String,
    truth: String,
    truth_sha256: String,
}

/// A case's sealed truth (the fields the scorer needs; the rest is kept as written).
#[derive(Debug, Deserialize)]
struct Truth {
    id: usize,
    class: String,
    #[serde(default)]
    channels: Vec<String>,
    /// Each injected channel's own effect-to-noise ratio, where the campaign gives it (null for
    /// a dead channel's infinite one).
    #[serde(default)]
    channel_ratios: BTreeMap<String, Option<f64>>,
    ratio: Option<f64>,
    #[serde(default)]
    alpha_deg: Vec<f64>,
}

/// The result of an external campaign.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Every case, scored.
    pub records: Vec<CaseRecord>,
    /// The campaign's master seed.
    pub seed: u64,
    /// Seconds to fit the clean recording and take its signature.
    pub fit_s: f64,
}

/// Runs and scores the campaign in `dir`; `progress` is called once per diagnosed case.
///
/// # Errors
/// A malformed index, a dataset that does not load, a clean recording that does not fit, or a
/// truth file that is missing, malformed or does not match its recorded hash.
pub fn run(dir: &Path, progress: &(dyn Fn() + Sync)) -> Result<Outcome, ExternalError> {
    let campaign = Campaign::open(dir)?;
    let clock = Instant::now();
    let (set, signature) = campaign.fit_clean()?;
    let fit_s = clock.elapsed().as_secs_f64();

    // Every case is diagnosed before any truth is read.
    let diagnosed: Vec<Result<Diagnosed, ExternalError>> = campaign
        .cases()
        .par_iter()
        .map(|(_, data)| {
            let dataset = firmware_sim::dataset::load_dataset(data)?;
            let clock = Instant::now();
            let diagnose_config = DiagnoseConfig { signature: Some(signature.clone()), ..DiagnoseConfig::default() };
            let outcome =
                diagnose(&dataset, Some((&set, "fitted on the clean recording".into())), &diagnose_config, &|_| {});
            let diagnosis_s = clock.elapsed().as_secs_f64();
            progress();
            Ok(Diagnosed::of(outcome.as_ref().map(|(d, _)| d).map_err(ToString::to_string), diagnosis_s))
        })
        .collect();
    let diagnosed = diagnosed.into_iter().collect::<Result<Vec<_>, _>>()?;
    let records = campaign.score(diagnosed)?;
    Ok(Outcome { records, seed: campaign.seed(), fit_s })
}

/// A campaign folder written by another program, opened: its index read and checked, no truth
/// read. The steps of [`run`], for a caller that diagnoses the cases elsewhere (other processes
/// or machines): fit the clean recording, diagnose every case, then score them all at once.
#[derive(Debug, Clone)]
pub struct Campaign {
    dir: PathBuf,
    index: Index,
}

impl Campaign {
    /// Reads the index of the campaign in `dir`.
    ///
    /// # Errors
    /// A missing or malformed index, or one of another format.
    pub fn open(dir: &Path) -> Result<Self, ExternalError> {
        let index_path = dir.join("campaign.json");
        let index_error = |message: String| ExternalError::Index { path: index_path.clone(), message };
        let text = std::fs::read_to_string(&index_path).map_err(|e| index_error(e.to_string()))?;
        let index: Index = serde_json::from_str(&text).map_err(|e| index_error(e.to_string()))?;
        if index.format != FORMAT {
            return Err(index_error(format!("format is \"{}\", expected \"{FORMAT}\"", index.format)));
        }
        Ok(Self { dir: dir.to_path_buf(), index })
    }

    /// The campaign's folder.
    #[must_use]
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The campaign's master seed.
    #[must_use]
    pub fn seed(&self) -> u64 {
        self.index.seed
    }

    /// The model fitted on the clean recording, and its diagnosis signature.
    ///
    /// # Errors
    /// A clean recording that does not load or fit.
    pub fn fit_clean(&self) -> Result<(estimator_core::CoefficientSet, crate::diagnose::Signature), ExternalError> {
        let clean_path = self.dir.join(&self.index.clean);
        let clean = firmware_sim::dataset::load_dataset(&clean_path)?;
        let config = FitConfig::default();
        let set = fit_dataset(&clean, &config, &|_| {})
            .map_err(|source| ExternalError::Fit { path: clean_path.clone(), source })?
            .set;
        let signature = crate::diagnose::signature(&clean, &set, config.split)?;
        Ok((set, signature))
    }

    /// Every case's id and dataset folder, in the index's order.
    #[must_use]
    pub fn cases(&self) -> Vec<(usize, PathBuf)> {
        self.index.cases.iter().map(|case| (case.id, self.dir.join(&case.data))).collect()
    }

    /// Scores every case: `diagnosed` holds what each case's diagnosis said, in the order of
    /// [`Self::cases`]; only now is each truth file read and checked against its hash.
    ///
    /// # Errors
    /// A diagnosis missing for a case, or a truth file that is missing, malformed or does not
    /// match its recorded hash.
    pub fn score(&self, diagnosed: Vec<Diagnosed>) -> Result<Vec<CaseRecord>, ExternalError> {
        if diagnosed.len() != self.index.cases.len() {
            return Err(ExternalError::Index {
                path: self.dir.join("campaign.json"),
                message: format!(
                    "{} cases, but {} diagnoses to score: every case is diagnosed before any truth is read",
                    self.index.cases.len(),
                    diagnosed.len()
                ),
            });
        }
        self.index
            .cases
            .iter()
            .zip(diagnosed)
            .map(|(case, diagnosed)| Ok(sealed(&self.dir, case)?.score(diagnosed)))
            .collect()
    }
}

/// The truth of `case`, read and checked against the hash the index recorded.
fn sealed(dir: &Path, case: &IndexCase) -> Result<Sealed, ExternalError> {
    let truth_path = dir.join(&case.truth);
    let truth_error = |message: String| ExternalError::Truth { path: truth_path.clone(), message };
    let bytes = std::fs::read(&truth_path).map_err(|e| truth_error(e.to_string()))?;
    let hash = model_fit::digest::sha256_hex(&bytes);
    if hash != case.truth_sha256 {
        return Err(truth_error(format!(
            "its SHA-256 is {hash}, but the campaign recorded {} before the diagnosis",
            case.truth_sha256
        )));
    }
    let truth: Truth = serde_json::from_slice(&bytes).map_err(|e| truth_error(e.to_string()))?;
    if truth.id != case.id {
        return Err(truth_error(format!("holds case {}, expected case {}", truth.id, case.id)));
    }
    if truth.class.is_empty() || !truth.class.bytes().all(|b| b.is_ascii_lowercase() || b == b'_') {
        return Err(truth_error(format!(
            "class \"{}\" is not a name (none, an effect of the vocabulary, or one outside it in snake_case)",
            truth.class
        )));
    }
    Ok(Sealed {
        id: case.id,
        class: truth.class,
        alpha_deg: truth.alpha_deg.iter().copied().fold(0.0, f64::max),
        target_ratio: truth.ratio.unwrap_or(0.0),
        ratio: truth.ratio,
        truth: String::from_utf8_lossy(&bytes).into_owned(),
        truth_sha256: hash,
        required_channels: truth
            .channels
            .iter()
            .filter(|channel| {
                truth.channel_ratios.get(*channel).is_none_or(|ratio| ratio.is_none_or(|ratio| ratio >= 1.0))
            })
            .cloned()
            .collect(),
        truth_channels: truth.channels,
    })
}

//! The sim's own signature: what every candidate and the structure probe explain, and the gap
//! per kind of run, when the sim is diagnosed against the data it was fitted on. Evidence
//! counts only beyond it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use estimator_core::CoefficientSet;
use firmware_sim::dataset::Dataset;

use super::streams::{RunStreams, kind_alpha_key};
use super::{DiagnoseConfig, DiagnoseError, diagnose};
use model_fit::fit::split::Split;

/// What the candidates and the probe explain, and the gap per kind of run, in noise variances,
/// when the sim is compared with data it should match: the floor below which a gap is the
/// sim's own structural error, not an effect. `fit` writes it beside the model
/// ([`SIGNATURE_FILE`]).
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Signature {
    /// Per candidate (sensor candidates keyed `name:channel`), explained mean square over the
    /// noise variance.
    pub explained_to_noise: BTreeMap<String, f64>,
    /// What each group of the structure probe explains of the residual, over the noise
    /// variance.
    pub probe_to_noise: BTreeMap<String, f64>,
    /// Gap beyond noise per kind of run (mean square over the noise variance), keyed by the
    /// kind (`roll`) and by kind and angle of attack (`roll@20`).
    pub gap_to_noise_by_kind: BTreeMap<String, f64>,
    /// The time constant that best aligns the taps with the balance moment on data the sim
    /// matches, s (`diagnose::pressure_lag`): the rig's tubing and the sim's own map; a lag counts
    /// beyond it.
    #[serde(default)]
    pub pressure_alignment_s: Option<f64>,
    /// The standard error of [`Self::pressure_alignment_s`], s, from the scatter of its runs'
    /// own alignments (`pressure_lag::run_scatter_s`).
    #[serde(default)]
    pub pressure_alignment_scatter_s: Option<f64>,
    /// Per kind of run and angle of attack (`roll@20`), the alignment of the taps with the
    /// balance and its standard error on data the sim matches (`pressure_lag::by_kind`): a
    /// recording's common lag is its shift from these, pair by pair.
    #[serde(default)]
    pub pressure_alignment_by_kind: Option<BTreeMap<String, super::pressure_lag::KindAlignment>>,
    /// How each pressure channel's apparent lag differs from the others' on data the sim
    /// matches, and the standard errors ([`super::lag_set::identify`]): the pressure model's own
    /// error per channel; a channel's lag counts beyond it.
    #[serde(default)]
    pub pressure_channel_lags: Option<super::lag_set::ChannelLags>,
    /// Per kind of run and angle of attack (`roll@20`), each pressure channel's mean innovation
    /// from the filter run without it ([`super::streams::RunStreams::innovation_alone`]) on
    /// data the sim matches: the pressure model's own mean error there, where the run holds it
    /// throughout ([`super::streams::RunStreams::steady_mean_alone`]), which a fault from the
    /// start of a run is judged beyond ([`super::streams::RunStreams::departure_alone`]).
    #[serde(default)]
    pub pressure_alone_mean: Option<BTreeMap<String, Vec<f64>>>,
}

/// File name of a model's signature in its folder.
pub const SIGNATURE_FILE: &str = "diagnosis-signature.json";

/// The built-in model's signature on the default synthetic campaign (models/default, written by
/// `fit`): the floor used when a diagnosis has no signature of its own sim (nominal models
/// fitted on the data itself, or a model folder without one). It is the structural error of
/// this model family on a tunnel like the synthetic one, so on other rigs it is a guess; the
/// report says so.
pub const DEFAULT_SIGNATURE_JSON: &str = include_str!("../../../models/default/diagnosis-signature.json");

/// [`DEFAULT_SIGNATURE_JSON`], parsed (an empty signature if it ever fails to parse), without
/// the pressure channels' mean innovations: they are the built-in pressure map's own error on
/// its own tunnel, and a diagnosis takes this signature for other sims (nominal models fitted
/// on the recording itself, whose mean error there is nil).
#[must_use]
pub fn default_signature() -> Signature {
    let signature: Signature = serde_json::from_str(DEFAULT_SIGNATURE_JSON).unwrap_or_default();
    Signature { pressure_alone_mean: None, ..signature }
}

impl Signature {
    /// What a candidate removes out of sample on data the sim matches, in noise variances: the
    /// floor its evidence must clear (never below zero: a candidate that predicts worse than
    /// nothing there sets no floor).
    pub(super) fn of(&self, key: &str) -> f64 {
        self.explained_to_noise.get(key).copied().unwrap_or(0.0).max(0.0)
    }

    pub(super) fn probe_of(&self, group: &str) -> f64 {
        self.probe_to_noise.get(group).copied().unwrap_or(0.0).max(0.0)
    }

    /// The sim's own gap on runs of this kind at this angle of attack (the kind's mean when the
    /// angle is not in the signature).
    pub(super) fn gap_of(&self, kind: &str, alpha_deg: f64) -> f64 {
        self.gap_to_noise_by_kind
            .get(&kind_alpha_key(kind, alpha_deg))
            .or_else(|| self.gap_to_noise_by_kind.get(kind))
            .copied()
            .unwrap_or(0.0)
    }
}

/// Per kind of run and angle of attack, the mean over its runs of each channel's
/// [`RunStreams::steady_mean_alone`] (0 for a channel never read, or whose level the run does
/// not hold throughout; `None` without runs).
pub(super) fn pressure_alone_means(runs: &[RunStreams]) -> Option<BTreeMap<String, Vec<f64>>> {
    let mut sums: BTreeMap<String, (Vec<f64>, Vec<usize>)> = BTreeMap::new();
    for run in runs {
        let means = run.steady_mean_alone();
        let entry = sums.entry(run.kind_alpha_key()).or_insert_with(|| (vec![0.0; means.len()], vec![0; means.len()]));
        for (tap, mean) in means.iter().enumerate().filter(|(_, m)| m.is_finite()) {
            entry.0[tap] += mean;
            entry.1[tap] += 1;
        }
    }
    let out: BTreeMap<String, Vec<f64>> = sums
        .into_iter()
        .map(|(key, (sum, n))| {
            (key, sum.iter().zip(&n).map(|(s, &n)| if n == 0 { 0.0 } else { s / n as f64 }).collect())
        })
        .collect();
    (!out.is_empty()).then_some(out)
}

/// The signature of `set` on `dataset` (the data it was fitted on): the recording diagnosed
/// with the same split and the same parts as any other, so that every candidate's floor is
/// measured with the same amount of data its evidence will be (taken on the held-out part
/// alone, the candidates were fitted on a fifth of the samples and the floors came out low: the
/// fit's own recording then named a balance mode).
pub fn signature(dataset: &Dataset, set: &CoefficientSet, split: Split) -> Result<Signature, DiagnoseError> {
    let config = DiagnoseConfig { split, signature: None };
    let (diagnosis, _) = diagnose(dataset, Some((set, "signature".into())), &config, &|_| {})?;
    Ok(diagnosis.signature)
}

/// Why a model's signature file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum SignatureFileError {
    /// The file exists but could not be read.
    #[error("{file}: {source}")]
    Read {
        /// The signature file.
        file: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not a signature.
    #[error("{file}: not a diagnosis signature: {source}")]
    Parse {
        /// The signature file.
        file: PathBuf,
        /// What the parser found.
        source: serde_json::Error,
    },
}

/// The signature `fit` wrote beside a model (`model` is its folder or its `model.bin`);
/// `None` when there is none. Only a missing file is `None`: one that cannot be read or parsed
/// is an error, so a broken signature never silently becomes the built-in model's.
///
/// # Errors
///
/// [`SignatureFileError`] when the file exists but cannot be read or is not a signature.
pub fn signature_beside(model: &Path) -> Result<Option<Signature>, SignatureFileError> {
    let folder =
        if model.is_dir() { model.to_path_buf() } else { model.parent().map(PathBuf::from).unwrap_or_default() };
    let file = folder.join(SIGNATURE_FILE);
    let text = match std::fs::read_to_string(&file) {
        Ok(text) => text,
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(SignatureFileError::Read { file, source }),
    };
    serde_json::from_str(&text).map(Some).map_err(|source| SignatureFileError::Parse { file, source })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A folder without a signature has none; a signature beside `model.bin` is read; a
    /// malformed one and an unreadable one (a folder in its place) are errors naming the file.
    #[test]
    fn a_signature_beside_the_model_is_read_and_a_broken_one_refused() {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("model.bin");
        assert!(signature_beside(dir.path()).unwrap().is_none());
        let signature = default_signature();
        std::fs::write(dir.path().join(SIGNATURE_FILE), serde_json::to_string(&signature).unwrap()).unwrap();
        assert_eq!(signature_beside(&model).unwrap(), Some(signature.clone()));
        assert_eq!(signature_beside(dir.path()).unwrap(), Some(signature));
        std::fs::write(dir.path().join(SIGNATURE_FILE), "{ not json").unwrap();
        let error = signature_beside(dir.path()).unwrap_err();
        assert!(matches!(error, SignatureFileError::Parse { .. }) && error.to_string().contains(SIGNATURE_FILE));
        std::fs::remove_file(dir.path().join(SIGNATURE_FILE)).unwrap();
        std::fs::create_dir(dir.path().join(SIGNATURE_FILE)).unwrap();
        assert!(matches!(signature_beside(dir.path()), Err(SignatureFileError::Read { .. })));
    }

    /// The sim's own mean innovation is kept per kind of run and angle: two runs alike are
    /// averaged, a run at another angle has its own entry, and a channel never read counts 0.
    #[test]
    fn the_pressure_means_are_kept_per_kind_and_angle() {
        let run = |alpha_deg: f64, level: f64| {
            let mut run = crate::diagnose::streams::synthetic_run(
                100.0,
                vec![vec![0.0; 50], vec![f64::NAN; 50]],
                vec![vec![level; 50], vec![f64::NAN; 50]],
            );
            run.alpha_deg = alpha_deg;
            run
        };
        let means = pressure_alone_means(&[run(10.0, 0.01), run(10.0, 0.03), run(20.0, -0.02)]).expect("means");
        let close = |key: &str, want: [f64; 2]| {
            let got = &means[key];
            assert!(got.iter().zip(want).all(|(g, w)| (g - w).abs() < 1e-12), "{key}: {got:?}");
        };
        close(&kind_alpha_key("static", 10.0), [0.02, 0.0]);
        close(&kind_alpha_key("static", 20.0), [-0.02, 0.0]);
        assert_eq!(means.len(), 2);
        assert_eq!(default_signature().pressure_alone_mean, None, "the built-in map's own means stay its own");
    }

    /// A level the run holds throughout, under white noise of three times its size, is kept; the
    /// same mean reached by a transient in a tenth of the run (ten times the level there) is no
    /// level of that kind of run and is not.
    #[test]
    fn only_a_level_the_run_holds_throughout_is_kept() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let n = 20_000;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let noise = Normal::new(0.0, 0.03).expect("a valid deviation");
        let steady: Vec<f64> = (0..n).map(|_| 0.01 + noise.sample(&mut rng)).collect();
        let transient: Vec<f64> =
            (0..n).map(|i| if i >= 9 * n / 10 { 0.1 } else { 0.0 } + noise.sample(&mut rng)).collect();
        let run = crate::diagnose::streams::synthetic_run(1000.0, vec![vec![0.0; n]; 2], vec![steady, transient]);
        let kept = run.steady_mean_alone();
        assert!((kept[0] - 0.01).abs() < 0.002, "{kept:?}");
        assert!((run.mean_alone()[1] - 0.01).abs() < 0.002, "the transient's mean is as large");
        assert_eq!(kept[1], 0.0, "{kept:?}");
    }
}

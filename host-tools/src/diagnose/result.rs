//! The machine-readable result, `diagnosis.json` (shared/spec/diagnosis.md, "Machine-readable
//! result"), and the canonical correlation that tells which candidates this data cannot separate.

use std::collections::BTreeMap;

use nalgebra::DMatrix;
use serde::Serialize;

use super::attribution::Profiled;
use super::regression::Segment;
use super::sensor::{ParamValue, SensorFinding};

/// The verdict.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// A named effect explains the gap.
    Effect,
    /// The gap is at the noise floor.
    None,
    /// A real gap that no candidate explains.
    Unattributed,
}

impl Verdict {
    /// As written in the JSON.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Effect => "effect",
            Self::None => "none",
            Self::Unattributed => "unattributed",
        }
    }
}

/// The whole diagnosis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Diagnosis {
    /// `effect`, `none` or `unattributed`.
    pub verdict: Verdict,
    /// The gap before any effect is added.
    pub gap: Gap,
    /// Where the gap lies.
    #[serde(rename = "where")]
    pub where_: Where,
    /// Named effects, most responsible first; empty unless the verdict is `effect`.
    pub effects: Vec<EffectResult>,
    /// For `unattributed`: the structure of the gap.
    pub unexplained: Option<Unexplained>,
    /// Candidate pairs that cannot be told apart with this data, with the experiment that would.
    pub confounded: Vec<Confounding>,
    /// Every candidate's evidence, balance candidates best first, then the sensor candidates.
    pub candidates: Vec<CandidateSummary>,
    /// The sim the data was compared with.
    pub sim: String,
    /// The training/held-out split.
    pub split: String,
    /// Noise variance of the balance residual on the training part, C_l^2.
    pub noise_var_training: f64,
    /// Integrated autocorrelation time of the balance residual, samples.
    pub autocorrelation_time_samples: f64,
    /// This comparison's signature (what every candidate explains, in noise variances): the
    /// floor for later diagnoses when the data is the sim's own.
    pub signature: super::Signature,
    /// The gap ledger: residual tests by input, band, regime and pressure channel.
    pub ledger: super::gap_ledger::GapLedger,
    /// Wall time of the diagnosis, s.
    pub elapsed_s: f64,
}

/// The gap of the stream the verdict concerns, on the held-out part of every run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Gap {
    /// RMS of the residual beyond the noise floor, `sqrt(max(MSE - noise^2, 0))`.
    pub heldout_rms: f64,
    /// RMS of the white measurement noise (first-difference estimate).
    pub noise_rms: f64,
    /// RMS of the residual itself.
    pub heldout_raw_rms: f64,
    /// RMS of the sim's own structural gap on the data it was fitted on (its signature, mean
    /// over kinds of run; 0 without a signature). Named effects' gaps are counted beyond it.
    pub floor_rms: f64,
    /// `balance` (C_l units) or `pressure` (Cp units).
    pub stream: String,
}

/// Where the gap lies.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Where {
    /// Block of the sim (`disturbance`, `plant`, `coupling`, `sensor`, `balance`), or null.
    pub block: Option<String>,
    /// Angles of attack of the runs the gap lies in, deg.
    pub alpha_deg: Vec<f64>,
    /// Frequency band holding most of the gap's power, Hz.
    pub band_hz: Option<[f64; 2]>,
    /// The pressure channel, when the gap lies in one sensor.
    pub channel: Option<String>,
    /// Every pressure channel the gap lies in, for a sensor effect (one, some or all twelve).
    pub channels: Vec<String>,
    /// The runs the gap lies in.
    pub runs: Vec<String>,
    /// Regime shares of the residual energy (the gap ledger's summary).
    pub regimes: Vec<RegimeShareSummary>,
}

/// One regime bin of the gap ledger.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RegimeShareSummary {
    /// The bin.
    pub label: String,
    /// Share of the held-out residual energy.
    pub share: Option<f64>,
}

/// A named effect.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EffectResult {
    /// Name from the vocabulary.
    pub name: String,
    /// Block.
    pub block: String,
    /// Physical parameters fitted on the training part.
    pub params: BTreeMap<String, serde_json::Value>,
    /// Held-out gap RMS before the effect is added, beyond the noise and the sim's own floor.
    pub heldout_rms_before: f64,
    /// Held-out gap RMS with the effect added.
    pub heldout_rms_after: f64,
    /// `1 - after / before`.
    pub shrink: f64,
    /// The same with the gaps beyond the noise only (the sim's own floor left in both): the
    /// share of the whole held-out gap the effect removes.
    pub shrink_total: f64,
    /// False where the shrink is not measured but holds by definition: a dead channel has no
    /// reading left, so its 1 says nothing of the diagnosis (and stays out of a campaign's
    /// median).
    pub shrink_measured: bool,
    /// Complexity-penalised evidence on the training part (null where it is unbounded: a dead
    /// channel).
    pub delta_bic: Option<f64>,
    /// RMS of the fitted effect over the noise RMS, on the runs it touches (null for a dead
    /// channel).
    pub effect_to_noise: Option<f64>,
    /// One line of evidence.
    pub evidence: String,
}

/// The structure of an unattributed gap.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Unexplained {
    /// In words: where, which band and regime, what correlates.
    pub description: String,
    /// The best candidate, which was not enough.
    pub best_candidate: Option<String>,
    /// What it removes on the selection part beyond the sim's signature, in noise variances.
    pub best_candidate_explained_to_noise: Option<f64>,
    /// What the structure probe finds in the remainder, in noise variances.
    pub probe_explained_to_noise: f64,
}

/// Two candidates this data cannot separate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Confounding {
    /// One candidate.
    pub a: String,
    /// The other.
    pub b: String,
    /// Largest canonical correlation of their regressors.
    pub canonical_correlation: Option<f64>,
    /// The experiment that would separate them.
    pub experiment: String,
}

/// One candidate's evidence.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CandidateSummary {
    /// Name.
    pub name: String,
    /// Block.
    pub block: String,
    /// Profiled nonlinear parameters (or the channel).
    pub hyper: BTreeMap<String, serde_json::Value>,
    /// Explained mean square over the noise variance, training part.
    pub explained_to_noise: Option<f64>,
    /// Mean square it removes on the selection part over the noise variance (what decides).
    pub selected_to_noise: Option<f64>,
    /// Complexity-penalised evidence.
    pub delta_bic: Option<f64>,
    /// Held-out shrink if it were added.
    pub heldout_shrink: Option<f64>,
}

impl CandidateSummary {
    /// From a profiled balance candidate.
    pub fn from_profiled(noise_var: f64) -> impl Fn(&Profiled) -> Self {
        move |profiled| Self {
            name: profiled.candidate.name().into(),
            block: profiled.candidate.block().name().into(),
            hyper: profiled.form.entries().into_iter().map(|(k, v)| (k.to_owned(), v.to_json())).collect(),
            explained_to_noise: finite_or_null(profiled.explained() / noise_var.max(f64::MIN_POSITIVE)),
            selected_to_noise: finite_or_null(profiled.selected() / noise_var.max(f64::MIN_POSITIVE)),
            delta_bic: finite_or_null(profiled.delta_bic),
            heldout_shrink: finite_or_null(profiled.heldout.shrink()),
        }
    }

    /// From a sensor finding.
    #[must_use]
    pub fn from_sensor(finding: &SensorFinding) -> Self {
        let mut hyper = BTreeMap::new();
        for (key, value) in &finding.params {
            hyper.insert(
                key.clone(),
                match value {
                    ParamValue::Number(n) => serde_json::json!(finite_or_null(*n)),
                    ParamValue::Text(t) => serde_json::json!(t),
                },
            );
        }
        Self {
            name: finding.effect.name().into(),
            block: "sensor".into(),
            hyper,
            explained_to_noise: finite_or_null(finding.explained / finding.noise_var.max(f64::MIN_POSITIVE)),
            selected_to_noise: finite_or_null(finding.selection.removed() / finding.noise_var.max(f64::MIN_POSITIVE)),
            delta_bic: finite_or_null(finding.delta_bic),
            heldout_shrink: finite_or_null(finding.heldout.shrink()),
        }
    }
}

/// A figure for the JSON: `None` (written `null`) where it is not a finite number, never a
/// made-up zero.
#[must_use]
pub fn finite_or_null(value: f64) -> Option<f64> {
    value.is_finite().then_some(value)
}

/// Largest canonical correlation between the spans of two column sets over the training
/// samples (centred per run): `sqrt(lambda_max(S_aa^-1 S_ab S_bb^-1 S_ba))`.
#[must_use]
pub fn canonical_correlation(segments: &[Segment<'_>], a: &[Vec<Vec<f64>>], b: &[Vec<Vec<f64>>]) -> f64 {
    let (pa, pb) = (a.first().map_or(0, Vec::len), b.first().map_or(0, Vec::len));
    if pa == 0 || pb == 0 {
        return 0.0;
    }
    let p = pa + pb;
    let mut s = DMatrix::<f64>::zeros(p, p);
    for ((segment, ca), cb) in segments.iter().zip(a).zip(b) {
        let idx: Vec<usize> = segment.training.clone().collect();
        if idx.is_empty() {
            continue;
        }
        let cols: Vec<Vec<f64>> = ca
            .iter()
            .chain(cb)
            .map(|col| {
                let mean = idx.iter().map(|&i| col[i]).sum::<f64>() / idx.len() as f64;
                idx.iter().map(|&i| col[i] - mean).collect()
            })
            .collect();
        for i in 0..p {
            for j in i..p {
                let v: f64 = cols[i].iter().zip(&cols[j]).map(|(x, y)| x * y).sum();
                s[(i, j)] += v;
                if i != j {
                    s[(j, i)] += v;
                }
            }
        }
    }
    let saa = s.view((0, 0), (pa, pa)).into_owned();
    let sbb = s.view((pa, pa), (pb, pb)).into_owned();
    let sab = s.view((0, pa), (pa, pb)).into_owned();
    let (Ok(saa_inv), Ok(sbb_inv)) = (saa.pseudo_inverse(1e-12), sbb.pseudo_inverse(1e-12)) else {
        return 0.0;
    };
    let m = &saa_inv * &sab * &sbb_inv * sab.transpose();
    let largest = m.complex_eigenvalues().iter().map(|z| z.re).fold(0.0, f64::max);
    largest.clamp(0.0, 1.0).sqrt()
}

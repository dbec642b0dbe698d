//! The machine-readable result, `diagnosis.json` (docs/spec/diagnosis.md, "Machine-readable
//! result"), and the canonical correlation that tells which candidates this data cannot separate.

use std::collections::BTreeMap;

use nalgebra::DMatrix;
use serde::Serialize;

use super::attribution::Profiled;
use super::finding::{ParamValue, SensorFinding};
use super::regression::Segment;

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
    /// The size the selection part confirms, per sample where the effect acts, over the noise
    /// variance (what decides; [`crate::diagnose::attribution::Profiled::selected`]); for a
    /// sensor finding, the mean square it removes on the selection part.
    pub selected_to_noise: Option<f64>,
    /// Complexity-penalised evidence.
    pub delta_bic: Option<f64>,
    /// Held-out shrink if it were added.
    pub heldout_shrink: Option<f64>,
}

impl CandidateSummary {
    /// From a profiled balance candidate.
    pub fn from_profiled(noise_var: f64, alphas_deg: &[f64]) -> impl Fn(&Profiled) -> Self + '_ {
        move |profiled| Self {
            name: profiled.candidate.name().into(),
            block: profiled.candidate.block().name().into(),
            hyper: profiled.form.entries().into_iter().map(|(k, v)| (k.to_owned(), v.to_json(alphas_deg))).collect(),
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
            // A part with no samples measured nothing (a dead channel's): null, not a zero.
            selected_to_noise: (finding.selection.n > 0)
                .then(|| finite_or_null(finding.selection.removed() / finding.noise_var.max(f64::MIN_POSITIVE)))
                .flatten(),
            delta_bic: finite_or_null(finding.delta_bic),
            heldout_shrink: (finding.heldout.n > 0).then(|| finite_or_null(finding.heldout.shrink())).flatten(),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::candidates::{self, Form, Shape};
    use crate::diagnose::regression::{Fit, HeldoutGap, Interleave};
    use crate::diagnose::{DiagnoseError, Signature, gap_ledger::GapLedger, sensor_effect};
    use firmware_sim::effect::Effect;

    fn assert_close(actual: Option<f64>, expected: f64) {
        let value = actual.expect("a finite figure");
        assert!((value - expected).abs() <= 1e-12 * expected.abs().max(1.0), "{value} != {expected}");
    }

    /// The contract's example (docs/spec/diagnosis.md) as a typed result.
    fn example() -> Diagnosis {
        Diagnosis {
            verdict: Verdict::Effect,
            gap: Gap {
                heldout_rms: 0.0041,
                noise_rms: 0.0012,
                heldout_raw_rms: 0.0043,
                floor_rms: 0.0,
                stream: "balance".into(),
            },
            where_: Where {
                block: Some("balance".into()),
                alpha_deg: vec![20.0],
                band_hz: Some([2.0, 12.0]),
                ..Where::default()
            },
            effects: vec![EffectResult {
                name: "inertial_tare".into(),
                block: "balance".into(),
                params: BTreeMap::from([("ixx_kgm2".to_owned(), serde_json::json!(3.0e-4))]),
                heldout_rms_before: 0.0041,
                heldout_rms_after: 0.0013,
                shrink: 0.68,
                shrink_total: 0.68,
                shrink_measured: true,
                delta_bic: Some(120.0),
                effect_to_noise: Some(3.0),
                evidence: String::new(),
            }],
            unexplained: None,
            confounded: Vec::new(),
            candidates: Vec::new(),
            sim: String::new(),
            split: String::new(),
            noise_var_training: 1.44e-6,
            autocorrelation_time_samples: 1.0,
            signature: Signature::default(),
            ledger: GapLedger::default(),
            elapsed_s: 1.0,
        }
    }

    /// A sensor finding with round figures: explained 2, noise variance 0.5; selection part
    /// 3 -> 1 (removes 2); held-out part 5 -> 2 over noise 1 (gap 2 -> 1, shrink 0.5).
    fn finding() -> SensorFinding {
        SensorFinding {
            effect: Effect::PressureFault,
            params: vec![
                ("mode".into(), ParamValue::Text("bias".into())),
                ("value".into(), ParamValue::Number(0.02)),
                ("start_s".into(), ParamValue::Number(f64::NAN)),
            ],
            channel: Some("cp07".into()),
            channels: vec!["cp07".into()],
            explained: 2.0,
            noise_var: 0.5,
            delta_bic: 40.0,
            heldout: HeldoutGap { mse_before: 5.0, mse_after: 2.0, noise_var: 1.0, n: 100, floor_var: 0.0 },
            selection: HeldoutGap { mse_before: 3.0, mse_after: 1.0, noise_var: 1.0, n: 100, floor_var: 0.0 },
            evidence: "cp07 steps".into(),
        }
    }

    /// A dead channel as [`super::super::sensor`] reports it: unbounded evidence, no held-out
    /// or selection samples.
    fn dead_finding() -> SensorFinding {
        SensorFinding {
            params: vec![("mode".into(), ParamValue::Text("dead".into())), ("start_s".into(), ParamValue::Number(3.0))],
            explained: f64::INFINITY,
            delta_bic: f64::INFINITY,
            heldout: HeldoutGap::EMPTY,
            selection: HeldoutGap::EMPTY,
            ..finding()
        }
    }

    /// The verdict is written exactly as the contract spells it, by `as_str` and by serde.
    #[test]
    fn verdicts_are_written_as_the_contract_spells_them() {
        for (verdict, name) in
            [(Verdict::Effect, "effect"), (Verdict::None, "none"), (Verdict::Unattributed, "unattributed")]
        {
            assert_eq!(verdict.as_str(), name);
            assert_eq!(serde_json::to_value(verdict).unwrap(), serde_json::json!(name));
        }
    }

    /// Finite numbers (zero and the extremes included) pass; NaN and both infinities become
    /// `None`, never a number.
    #[test]
    fn finite_or_null_keeps_finite_numbers_and_nulls_the_rest() {
        for value in [0.0, -0.0, -3.5, f64::MIN_POSITIVE, f64::MAX, f64::MIN] {
            assert_eq!(finite_or_null(value), Some(value));
        }
        for value in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert_eq!(finite_or_null(value), None);
        }
    }

    /// `diagnosis.json` has the contract's field names: `where` (not the Rust `where_`),
    /// `gap.heldout_rms` and `noise_rms`, `where.channel` present as null when no channel is
    /// named, and the effect's `name`, `block`, `params` and held-out figures.
    #[test]
    fn the_json_has_the_contracts_field_names_and_values() {
        let json = serde_json::to_value(example()).unwrap();
        assert_eq!(json["verdict"], "effect");
        assert_eq!(json["gap"]["heldout_rms"], 0.0041);
        assert_eq!(json["gap"]["noise_rms"], 0.0012);
        assert!(json.get("where_").is_none());
        let where_ = &json["where"];
        assert_eq!(where_["block"], "balance");
        assert_eq!(where_["alpha_deg"], serde_json::json!([20.0]));
        assert_eq!(where_["band_hz"], serde_json::json!([2.0, 12.0]));
        assert!(where_.get("channel").is_some_and(serde_json::Value::is_null), "{where_}");
        let effect = &json["effects"][0];
        assert_eq!(effect["name"], "inertial_tare");
        assert_eq!(effect["block"], "balance");
        assert_eq!(effect["params"]["ixx_kgm2"], 3.0e-4);
        assert_eq!(effect["heldout_rms_before"], 0.0041);
        assert_eq!(effect["heldout_rms_after"], 0.0013);
        assert_eq!(effect["shrink"], 0.68);
    }

    /// Every number of the contract must be finite: a NaN gap or an infinite shrink is refused
    /// with the figure's name, not written (serde would write either as null or fail).
    #[test]
    fn a_non_finite_contract_figure_is_refused_by_name() {
        assert!(example().check_finite().is_ok());
        let mut nan_gap = example();
        nan_gap.gap.heldout_rms = f64::NAN;
        assert!(
            matches!(nan_gap.check_finite(), Err(DiagnoseError::NotFinite(name)) if name == "gap.heldout_rms"),
            "NaN gap"
        );
        let mut nan_noise = example();
        nan_noise.gap.noise_rms = f64::NEG_INFINITY;
        assert!(matches!(nan_noise.check_finite(), Err(DiagnoseError::NotFinite(name)) if name == "gap.noise_rms"));
        let mut infinite_shrink = example();
        infinite_shrink.effects[0].shrink = f64::INFINITY;
        assert!(matches!(
            infinite_shrink.check_finite(),
            Err(DiagnoseError::NotFinite(name)) if name == "effects[0].shrink"
        ));
        let mut nan_after = example();
        nan_after.effects[0].heldout_rms_after = f64::NAN;
        assert!(matches!(
            nan_after.check_finite(),
            Err(DiagnoseError::NotFinite(name)) if name == "effects[0].heldout_rms_after"
        ));
    }

    /// A sensor finding's summary in noise variances, by hand: explained 2 / 0.5 = 4; removed
    /// on the selection part (3 - 1) / 0.5 = 4; held-out shrink 1 - 1/2 = 0.5. Numbers stay
    /// numbers, words words, and a NaN parameter is null.
    #[test]
    fn a_sensor_candidate_is_summarised_in_noise_variances() {
        let summary = CandidateSummary::from_sensor(&finding());
        assert_eq!(summary.name, "pressure_fault");
        assert_eq!(summary.block, "sensor");
        assert_close(summary.explained_to_noise, 4.0);
        assert_close(summary.selected_to_noise, 4.0);
        assert_close(summary.delta_bic, 40.0);
        assert_close(summary.heldout_shrink, 0.5);
        assert_eq!(summary.hyper["mode"], serde_json::json!("bias"));
        assert_eq!(summary.hyper["value"], serde_json::json!(0.02));
        assert!(summary.hyper["start_s"].is_null());
    }

    /// A dead channel's evidence is unbounded: explained and delta BIC are written null, not
    /// as a number.
    #[test]
    fn a_dead_channels_unbounded_evidence_is_null() {
        let summary = CandidateSummary::from_sensor(&dead_finding());
        assert_eq!(summary.explained_to_noise, None);
        assert_eq!(summary.delta_bic, None);
    }

    /// A dead channel has no selection or held-out samples: what it removes there and its
    /// shrink are not measured, so they must not be written as a measured 0 (the same JSON
    /// gives the named effect a shrink of 1 by definition, and the decision counts its
    /// selection evidence as unbounded).
    #[test]
    fn a_dead_channels_unmeasured_figures_are_not_zero() {
        let summary = CandidateSummary::from_sensor(&dead_finding());
        assert_eq!(summary.selected_to_noise, None);
        assert_eq!(summary.heldout_shrink, None);
    }

    /// A dead channel named as the effect: its shrink of 1 holds by definition and is flagged
    /// unmeasured (so the campaign leaves it out of the median); its unbounded evidence is
    /// null; the channel is in the parameters. A measured finding keeps its held-out shrink.
    #[test]
    fn a_dead_channels_effect_is_flagged_unmeasured() {
        let dead = sensor_effect(&dead_finding(), f64::INFINITY);
        assert_eq!(dead.name, "pressure_fault");
        assert_eq!(dead.block, "sensor");
        assert_eq!(dead.shrink, 1.0);
        assert!(!dead.shrink_measured);
        assert_eq!(dead.delta_bic, None);
        assert_eq!(dead.effect_to_noise, None);
        assert_eq!(dead.params["channel"], serde_json::json!("cp07"));
        assert_eq!(dead.params["channels"], serde_json::json!(["cp07"]));
        assert_eq!(serde_json::to_value(&dead).unwrap()["shrink_measured"], serde_json::json!(false));
        let measured = sensor_effect(&finding(), 4.0);
        assert!(measured.shrink_measured);
        assert!((measured.shrink - 0.5).abs() < 1e-12);
        assert!((measured.heldout_rms_before - 2.0).abs() < 1e-12 && (measured.heldout_rms_after - 1.0).abs() < 1e-12);
        // The ratio reported is the one the decision named it on: sqrt(4) = 2.
        assert_close(measured.effect_to_noise, 2.0);
    }

    /// A finding that is not a dead channel but has no held-out samples claims no shrink: only
    /// a dead channel's shrink of 1 holds by definition.
    #[test]
    fn a_live_finding_without_held_out_samples_claims_no_shrink() {
        let mut live = finding();
        live.heldout = HeldoutGap::EMPTY;
        let effect = sensor_effect(&live, 1.0);
        assert!(!effect.shrink_measured);
        assert_eq!(effect.shrink, 0.0);
    }

    /// A profiled balance candidate's summary, by hand: explained (10 - 6) / 100 samples =
    /// 0.04, over a noise variance of 0.01 = 4; removed on the selection part (0.05 - 0.03) /
    /// 0.01 = 2; held-out gap sqrt(0.05 - 0.01) = 0.2 -> sqrt(0.02 - 0.01) = 0.1, shrink 0.5.
    /// A NaN delta BIC or form parameter is null.
    #[test]
    fn a_balance_candidate_is_summarised_in_noise_variances() {
        let profiled = Profiled {
            candidate: &candidates::ActuatorDelay,
            form: Form {
                shape: Shape::Delay { delay_s: 0.02, jets: candidates::Jets::Both, smoothing_s: 0.0 },
                per_alpha: false,
            },
            fit: Fit {
                beta: vec![0.5],
                ssr_base: 10.0,
                ssr: 6.0,
                n: 100,
                n_touched: 100,
                ssr_base_touched: 10.0,
                touched: vec![true],
            },
            delta_bic: 42.0,
            profile: Vec::new(),
            selection: HeldoutGap { mse_before: 0.05, mse_after: 0.03, noise_var: 0.01, n: 50, floor_var: 0.0 },
            heldout: HeldoutGap { mse_before: 0.05, mse_after: 0.02, noise_var: 0.01, n: 50, floor_var: 0.0 },
            selection_slope: crate::diagnose::attribution::Slope { value: 0.5, standard_error: 0.1 },
            active_share: 1.0,
            selection_active_share: 1.0,
            cross_validation: None,
            beyond_its_range: false,
            limit_margin: f64::INFINITY,
        };
        let summary = CandidateSummary::from_profiled(0.01, &[])(&profiled);
        assert_eq!(summary.name, "actuator_delay");
        assert_eq!(summary.block, "plant");
        assert_eq!(
            summary.hyper,
            BTreeMap::from([
                ("delay_s".to_owned(), serde_json::json!(0.02)),
                ("jets".to_owned(), serde_json::json!("both")),
                ("smoothing_s".to_owned(), serde_json::json!(0.0)),
            ])
        );
        assert!((summary.explained_to_noise.unwrap() - 4.0).abs() < 1e-9);
        assert!((summary.selected_to_noise.unwrap() - 2.0).abs() < 1e-9);
        assert_close(summary.delta_bic, 42.0);
        assert!((summary.heldout_shrink.unwrap() - 0.5).abs() < 1e-9);
        let degenerate = Profiled {
            delta_bic: f64::NAN,
            form: Form {
                shape: Shape::Delay { delay_s: f64::NAN, jets: candidates::Jets::Both, smoothing_s: 0.0 },
                per_alpha: false,
            },
            ..profiled
        };
        let summary = CandidateSummary::from_profiled(0.01, &[])(&degenerate);
        assert_eq!(summary.delta_bic, None);
        assert!(summary.hyper["delay_s"].is_null());
    }

    const N: usize = 1000;

    /// Five whole periods over `N` samples: sine and cosine are exactly orthogonal, mean zero,
    /// each of variance 1/2.
    fn sine() -> Vec<f64> {
        (0..N).map(|i| (std::f64::consts::TAU * 5.0 * i as f64 / N as f64).sin()).collect()
    }

    fn cosine() -> Vec<f64> {
        (0..N).map(|i| (std::f64::consts::TAU * 5.0 * i as f64 / N as f64).cos()).collect()
    }

    fn segment(residual: &[f64], training: std::ops::Range<usize>) -> Segment<'_> {
        Segment { residual, training, select: Interleave::default(), heldout: 0..0 }
    }

    /// The largest canonical correlation against values known in closed form: a set with itself
    /// and with an affine copy (per-run offsets, other scale) 1; sine against cosine 0; `x`
    /// against `x + y` with `x`, `y` orthogonal of equal variance `1/sqrt(2)`; a column inside
    /// the span of the other set 1.
    #[test]
    fn canonical_correlation_matches_closed_forms() {
        let (x, y) = (sine(), cosine());
        let residual = vec![0.0; N];
        let one = [segment(&residual, 0..N)];
        let two = [segment(&residual, 0..N), segment(&residual, 0..N)];
        let shift = |v: &[f64], scale: f64, offset: f64| v.iter().map(|a| scale * a + offset).collect::<Vec<f64>>();
        let same = canonical_correlation(&one, &[vec![x.clone()]], &[vec![x.clone()]]);
        assert!((same - 1.0).abs() < 1e-9, "{same}");
        let a = vec![vec![x.clone()], vec![shift(&x, 1.0, 5.0)]];
        let b = vec![vec![shift(&x, 3.0, 2.0)], vec![shift(&x, 3.0, -7.0)]];
        let affine = canonical_correlation(&two, &a, &b);
        assert!((affine - 1.0).abs() < 1e-9, "{affine}");
        let orthogonal = canonical_correlation(&one, &[vec![x.clone()]], &[vec![y.clone()]]);
        assert!(orthogonal.abs() < 1e-6, "{orthogonal}");
        let sum: Vec<f64> = x.iter().zip(&y).map(|(a, b)| a + b).collect();
        let half = canonical_correlation(&one, &[vec![x.clone()]], &[vec![sum]]);
        assert!((half - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-9, "{half}");
        let spanned = canonical_correlation(&one, &[vec![x.clone()]], &[vec![y, x]]);
        assert!((spanned - 1.0).abs() < 1e-9, "{spanned}");
    }

    /// Only the training samples count: two sets equal there and unrelated elsewhere are
    /// perfectly correlated.
    #[test]
    fn canonical_correlation_uses_the_training_samples_only() {
        let x = sine();
        let residual = vec![0.0; N];
        let mut b = x.clone();
        for (i, value) in b.iter_mut().enumerate().skip(N / 2) {
            *value = ((i * 7919) % 101) as f64;
        }
        let segments = [segment(&residual, 0..N / 2)];
        let correlation = canonical_correlation(&segments, &[vec![x]], &[vec![b]]);
        assert!((correlation - 1.0).abs() < 1e-9, "{correlation}");
    }

    /// Without columns or without training samples nothing can be confounded: the correlation
    /// stays below the threshold that would report a pair.
    #[test]
    fn canonical_correlation_claims_no_confounding_without_data() {
        let x = sine();
        let residual = vec![0.0; N];
        let full = [segment(&residual, 0..N)];
        let empty = [segment(&residual, 0..0)];
        let threshold = crate::diagnose::CONFOUNDED_CORRELATION;
        assert!(canonical_correlation(&full, &[vec![]], &[vec![x.clone()]]) < threshold);
        assert!(canonical_correlation(&full, &[vec![x.clone()]], &[vec![]]) < threshold);
        assert!(canonical_correlation(&empty, &[vec![x.clone()]], &[vec![x]]) < threshold);
    }
}

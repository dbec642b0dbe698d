//! Sim-to-real gap diagnosis (shared/spec/diagnosis.md): where the recording departs from the
//! sim, which unmodelled effect causes it, and how far the gap shrinks on held-out data once
//! that effect is added.
//!
//! The sim is a fitted coefficient set driven by the recorded inputs alone
//! ([`streams`]). Two residual streams are examined: the balance (roll moment) and the
//! pressure channels' Kalman innovations. Every effect of the vocabulary is a candidate with
//! physical parameters ([`candidates`], [`sensor`]), profiled over its grid on the training
//! part of every run and compared with the others by a complexity-penalised criterion
//! ([`attribution`]); recalibration of the existing blocks competes as one more candidate. An
//! effect is named only when it explains a gap that is both statistically decisive and at least
//! [`MIN_EFFECT_TO_NOISE`] of the noise RMS; what remains is probed for structure no candidate
//! spans. The named effects are then measured on the held-out part (`shrink`).
//!
//! Gap RMS values are beyond the noise floor: `sqrt(max(MSE - sigma^2, 0))` with `sigma^2` the
//! stream's white measurement noise (first-difference estimate), so that `shrink` measures the
//! part of the gap the effect removes, not the noise nothing can remove.

pub mod attribution;
pub mod candidates;
pub mod faults;
pub mod gap_ledger;
pub mod ledger;
pub mod pressure_lag;
pub mod regression;
pub mod report;
pub mod result;
pub mod sensor;
pub mod signature;
pub mod streams;

use std::collections::BTreeMap;
use std::time::Instant;

use estimator_core::CoefficientSet;
use firmware_sim::dataset::Dataset;

use crate::fit::pipeline::{FitConfig, fit_dataset};
use crate::fit::split::Split;
use attribution::Profiled;
use candidates::Context;
use result::{Confounding, Diagnosis, EffectResult, Gap, Unexplained, Verdict, Where, finite_or_null};
use sensor::{ParamValue, SensorFinding};
use signature::kind_alpha_key;
pub use signature::{
    DEFAULT_SIGNATURE_JSON, SIGNATURE_FILE, Signature, SignatureFileError, default_signature, signature,
    signature_beside,
};

/// Smallest effect the diagnosis names, as a ratio of its RMS to the stream's noise RMS: a
/// smaller one is at the noise floor by definition. Its square is the explained mean square a
/// candidate needs, in units of the noise variance.
pub const MIN_EFFECT_TO_NOISE: f64 = 0.5;

/// Evidence a named effect needs: a BIC difference of 10 is "very strong" (Kass & Raftery 1995).
pub const MIN_DELTA_BIC: f64 = 10.0;

/// Share of a named effect's explained mean square that the structure probe may still find in
/// the remainder before the gap counts as unattributed.
pub const MAX_REMAINDER_SHARE: f64 = 0.1;

/// Least structure (in noise variances, beyond the signature's floor) the probe must find in the
/// remainder before it counts: a twentieth of the noise variance, below which the probe's own
/// estimation scatter lies (scaled, like the naming threshold, by the sim's own gap).
pub const MIN_REMAINDER_TO_NOISE: f64 = 0.05;

/// How many standard errors a run's gap must exceed the sim's own floor by before it counts
/// as a real gap (one-sided, about 2.3 % false alarms per run for a Gaussian scatter).
pub const GAP_SIGNIFICANCE_Z: f64 = 2.0;

/// Canonical correlation above which two candidates cannot be told apart with this data.
pub const CONFOUNDED_CORRELATION: f64 = 0.9;

/// Settings of a diagnosis.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DiagnoseConfig {
    /// Training/held-out split of every run (the same as `fit`'s).
    pub split: Split,
    /// The sim's own signature: what each candidate explains when the sim is compared with the
    /// data it was fitted on, diagnosed as any recording is. The sim's structural error is part
    /// of every comparison, so evidence counts only beyond it. `None`: no signature (every
    /// candidate starts from zero).
    pub signature: Option<Signature>,
}

/// Why a diagnosis failed.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    /// Fitting the nominal models on the training part failed.
    #[error("fitting the nominal models on the training part: {0}")]
    Fit(#[from] crate::fit::FitError),
    /// The dataset has no samples to diagnose.
    #[error("the dataset has no runs with samples")]
    Empty,
    /// A figure of the contract came out non-finite (degenerate data): refused rather than
    /// written as a made-up number.
    #[error("the diagnosis computed a non-finite {0}; nothing is written")]
    NotFinite(String),
    /// A run's sample rate is not the sim's fixed step.
    #[error("{file}: sampled at {sample_hz} Hz, but the sim steps at {model_hz} Hz (fit a model on data at this rate)")]
    Rate {
        /// The run.
        file: String,
        /// Its sample rate, Hz.
        sample_hz: f64,
        /// The sim's rate, Hz.
        model_hz: f64,
    },
}

/// The sim used, for the report.
#[derive(Debug, Clone, PartialEq)]
pub enum SimSource {
    /// A given coefficient set.
    Given(String),
    /// Nominal models fitted on the training part of the data itself.
    FittedOnTraining,
}

/// Diagnoses `dataset` against `model` (or against nominal models fitted on its training part).
/// `progress` is called with the name of each stage.
///
/// The stages, each with a typed result: the sim on the recorded inputs ([`Streams`]); the
/// balance candidates, profiled on the training part and chosen on the selection part
/// ([`BalanceAttribution`]); the structure probe ([`ProbeResult`]); the sensor candidates
/// ([`SensorAttribution`]); the gap per run ([`GapSummary`]); the verdict; and the report of the
/// named effects on the held-out part, which chooses nothing.
pub fn diagnose(
    dataset: &Dataset,
    model: Option<(&CoefficientSet, String)>,
    config: &DiagnoseConfig,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<(Diagnosis, Evidence), DiagnoseError> {
    let clock = Instant::now();
    let (set, source) = sim_of(dataset, model, config, progress)?;
    progress("running the sim on the recorded inputs");
    let streams = Streams::build(dataset, &set, config);
    let floor = config.signature.clone().unwrap_or_default();

    progress("profiling the balance candidates");
    let balance = BalanceAttribution::run(&streams, &floor);
    progress("probing the remainder and the pressure channels");
    let probe = ProbeResult::run(&streams, &balance, &floor);
    let sensor = SensorAttribution::run(&streams, &floor);
    let gaps = GapSummary::run(&streams, &floor);
    let decision = Decision::make(&streams, &balance, &probe, &sensor, &gaps, &floor);

    let context = streams.context();
    let own_signature = Signature {
        explained_to_noise: balance
            .first_round
            .iter()
            .map(|p| (p.candidate.name().to_owned(), streams.to_noise(p.selected())))
            .chain(sensor.findings.iter().map(|f| (f.floor_key(), sensor_selected_to_noise(f))))
            .filter(|(_, value)| value.is_finite())
            .collect(),
        probe_to_noise: probe.base.clone(),
        gap_to_noise_by_kind: gaps.by_kind.clone(),
        pressure_alignment_s: pressure_lag::Alignment::new(&streams.runs, |run| run.fit_samples().collect())
            .map(|alignment| alignment.shared()),
    };

    let mut effects = Vec::new();
    let mut where_ = Where::default();
    let mut unexplained = None;
    let runs = &streams.runs;
    match &decision {
        Decision::Sensor(finding) => {
            effects.push(sensor_effect(finding));
            where_.block = Some("sensor".into());
            where_.channel = finding.channel.clone();
            where_.channels = finding.channels.clone();
            where_.alpha_deg = alphas(runs, &vec![true; runs.len()]);
        }
        Decision::Balance => {
            let mut cumulative = streams.residuals.clone();
            for profiled in &balance.named {
                effects.push(balance_effect(profiled, runs, &cumulative, &context, &floor));
                cumulative = attribution::subtract(profiled, runs, &cumulative, &context);
            }
            let top = &balance.named[0];
            where_.block = Some(top.candidate.block().name().into());
            where_.alpha_deg = alphas(runs, &top.fit.touched);
            where_.runs =
                runs.iter().zip(&top.fit.touched).filter(|(_, t)| **t).map(|(run, _)| run.file.clone()).collect();
        }
        Decision::Unattributed => {
            let touched: Vec<bool> = (0..runs.len()).map(|idx| gaps.excess_runs.contains(&idx)).collect();
            where_.alpha_deg = alphas(runs, &touched);
            where_.runs = gaps.excess_runs.iter().map(|&idx| runs[idx].file.clone()).collect();
            let best = balance.first_round.first();
            unexplained = Some(Unexplained {
                description: describe_structure(
                    runs,
                    &gaps.excess_runs,
                    probe.structure,
                    best.map(|p| (p.candidate.name(), balance.excess(p, &streams, &floor))),
                ),
                best_candidate: best.map(|p| p.candidate.name().to_owned()),
                best_candidate_explained_to_noise: best
                    .and_then(|p| finite_or_null(balance.excess(p, &streams, &floor))),
                probe_explained_to_noise: probe.structure,
            });
        }
        Decision::None => {}
    }
    let verdict = decision.verdict();

    let confounded = confounding(&balance.first_round, runs, &streams.residuals, &context);
    progress("the gap ledger");
    let ledger = gap_ledger::build(runs, &balance.remainder, streams.noise_var, 1);
    let sensor_verdict = matches!(decision, Decision::Sensor(_));
    if verdict != Verdict::None && !sensor_verdict {
        where_.band_hz = ledger.dominant_band_hz;
    }
    // For a sensor verdict the gap is the channel's innovation (or the lag's deviation), in Cp.
    let stream_gap = match &decision {
        Decision::Sensor(finding) if finding.heldout.n > 0 => finding.heldout,
        _ => gaps.heldout,
    };
    where_.regimes = ledger
        .regimes
        .iter()
        .map(|r| result::RegimeShareSummary { label: r.label.clone(), share: finite_or_null(r.share) })
        .collect();
    let floor_kinds: Vec<f64> =
        floor.gap_to_noise_by_kind.iter().filter(|(k, _)| !k.contains('@')).map(|(_, v)| *v).collect();
    let diagnosis = Diagnosis {
        verdict,
        gap: Gap {
            heldout_rms: stream_gap.gap_before(),
            noise_rms: stream_gap.noise_var.sqrt(),
            heldout_raw_rms: stream_gap.mse_before.sqrt(),
            floor_rms: (floor_kinds.iter().sum::<f64>().max(0.0) / floor_kinds.len().max(1) as f64
                * gaps.heldout.noise_var)
                .sqrt(),
            stream: if sensor_verdict { "pressure" } else { "balance" }.into(),
        },
        where_,
        effects,
        unexplained,
        confounded,
        candidates: balance
            .first_round
            .iter()
            .map(result::CandidateSummary::from_profiled(streams.noise_var))
            .chain(sensor.findings.iter().map(result::CandidateSummary::from_sensor))
            .collect(),
        sim: match &source {
            SimSource::Given(name) => format!("the given coefficient set ({name})"),
            SimSource::FittedOnTraining => "nominal models fitted on the training part of this dataset".into(),
        },
        split: format!(
            "{}; the diagnosis fits candidates on the training part less its validation part, chooses on the validation part and reports on the held-out part",
            config.split.describe()
        ),
        noise_var_training: streams.noise_var,
        autocorrelation_time_samples: streams.autocorrelation_time,
        signature: own_signature,
        ledger,
        elapsed_s: clock.elapsed().as_secs_f64(),
    };
    diagnosis.check_finite()?;
    let families = streams.families();
    let Streams { runs, .. } = streams;
    Ok((
        diagnosis,
        Evidence {
            runs,
            first_round: balance.first_round,
            named: balance.named,
            remainder: balance.remainder,
            families,
        },
    ))
}

impl Diagnosis {
    /// Every number the contract requires is finite (shared/spec/diagnosis.md).
    fn check_finite(&self) -> Result<(), DiagnoseError> {
        let mut figures =
            vec![("gap.heldout_rms".to_owned(), self.gap.heldout_rms), ("gap.noise_rms".into(), self.gap.noise_rms)];
        for (idx, effect) in self.effects.iter().enumerate() {
            for (name, value) in [
                ("heldout_rms_before", effect.heldout_rms_before),
                ("heldout_rms_after", effect.heldout_rms_after),
                ("shrink", effect.shrink),
            ] {
                figures.push((format!("effects[{idx}].{name}"), value));
            }
        }
        match figures.into_iter().find(|(_, value)| !value.is_finite()) {
            Some((name, _)) => Err(DiagnoseError::NotFinite(name)),
            None => Ok(()),
        }
    }
}

/// The sim: the given coefficient set, or nominal models fitted on the training part; checked
/// against the recording's sample rate.
fn sim_of(
    dataset: &Dataset,
    model: Option<(&CoefficientSet, String)>,
    config: &DiagnoseConfig,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<(CoefficientSet, SimSource), DiagnoseError> {
    if dataset.runs.iter().all(|run| run.channels.is_empty()) {
        return Err(DiagnoseError::Empty);
    }
    let (set, source) = match model {
        Some((set, name)) => (*set, SimSource::Given(name)),
        None => {
            progress("fitting the nominal models on the training part");
            let fit_config = FitConfig { split: config.split, ..FitConfig::default() };
            (fit_dataset(dataset, &fit_config, &|_| {})?.set, SimSource::FittedOnTraining)
        }
    };
    // The step is stored in f32: round its rate to a millihertz for the comparison and the message.
    let model_hz = (1e3 / f64::from(set.dt_s)).round() / 1e3;
    if let Some(run) = dataset.runs.iter().find(|run| (run.meta.sample_hz / model_hz - 1.0).abs() > 0.01) {
        return Err(DiagnoseError::Rate {
            file: run.meta.file.display().to_string(),
            sample_hz: run.meta.sample_hz,
            model_hz,
        });
    }
    Ok((set, source))
}

/// Stage 1: the sim driven by the recorded inputs, and the balance residual's noise.
pub struct Streams {
    /// Every run's streams.
    pub runs: Vec<streams::RunStreams>,
    /// The balance residual of every run.
    pub residuals: Vec<Vec<f64>>,
    /// The balance residual's white-noise variance on the training part, C_l^2.
    pub noise_var: f64,
    /// Integrated autocorrelation time of the balance residual, samples.
    pub autocorrelation_time: f64,
    set: CoefficientSet,
    moment_scale_nm: f64,
    half_span_time_s: f64,
    resonance_min_hz: f64,
}

impl Streams {
    fn build(dataset: &Dataset, set: &CoefficientSet, config: &DiagnoseConfig) -> Self {
        let runs = streams::build(dataset, set, &config.split);
        let residuals: Vec<Vec<f64>> = runs.iter().map(|run| run.residual.clone()).collect();
        let segments = attribution::segments(&runs, &residuals);
        let noise_var = regression::difference_noise_var(&segments, None);
        let autocorrelation_time = regression::integrated_autocorrelation(&segments, 200);
        let resonance_min_hz = candidates::resonance_min_hz(&runs);
        Self {
            noise_var,
            autocorrelation_time,
            residuals,
            set: *set,
            moment_scale_nm: dataset.tunnel.dynamic_pressure_pa() * dataset.wing.area_m2 * dataset.wing.span_m,
            half_span_time_s: dataset.wing.span_m / (2.0 * dataset.tunnel.u_inf_mps),
            resonance_min_hz,
            runs,
        }
    }

    /// What every candidate family searches on these runs.
    fn families(&self) -> Vec<Family> {
        let sample_hz = self.runs.first().map_or(1.0, |run| run.sample_hz);
        let context = self.context();
        candidates::ALL
            .iter()
            .map(|&candidate| {
                let (forms, searched) = candidates::family_summary(candidate, sample_hz, &context);
                Family { name: candidate.name(), forms: Some(forms), searched }
            })
            .chain(sensor::family_summaries(sample_hz).into_iter().map(|(effect, searched)| Family {
                name: effect.name(),
                forms: None,
                searched,
            }))
            .collect()
    }

    /// What the candidates' regressors need besides the runs.
    fn context(&self) -> Context<'_> {
        Context {
            set: &self.set,
            moment_scale_nm: self.moment_scale_nm,
            half_span_time_s: self.half_span_time_s,
            cmu_ref: self.runs.iter().flat_map(|run| run.cmu.iter().flatten()).copied().fold(0.0, f64::max),
            n_runs: self.runs.len(),
            slow_tau_min_s: self
                .runs
                .iter()
                .map(|run| 2.0 * f64::from(estimator_core::egk::params_at(&self.set, run.alpha_deg as f32).tau1_s))
                .fold(0.05, f64::max),
            resonance_min_hz: self.resonance_min_hz,
            alphas_deg: {
                let mut alphas: Vec<f64> = self.runs.iter().map(|run| run.alpha_deg).collect();
                alphas.sort_by(f64::total_cmp);
                alphas.dedup();
                alphas
            },
            longest_run_s: self.runs.iter().map(|run| run.t_s.last().copied().unwrap_or(0.0)).fold(0.0, f64::max),
        }
    }

    /// A mean square in units of the balance noise variance.
    fn to_noise(&self, value: f64) -> f64 {
        value / self.noise_var.max(f64::MIN_POSITIVE)
    }
}

/// Stage 2: the balance candidates, profiled on the training part, ranked by their evidence,
/// and named by forward selection when they qualify on the selection part.
pub struct BalanceAttribution {
    /// Every candidate on the original residual, best first.
    pub first_round: Vec<Profiled>,
    /// The named effects, in the order they were selected.
    pub named: Vec<Profiled>,
    /// The balance residual after the named effects.
    pub remainder: Vec<Vec<f64>>,
}

impl BalanceAttribution {
    fn run(streams: &Streams, floor: &Signature) -> Self {
        let context = streams.context();
        let runs = &streams.runs;
        let first_round = profile_all(runs, &streams.residuals, &context, streams.autocorrelation_time);
        let mut named: Vec<Profiled> = Vec::new();
        let mut remainder = streams.residuals.clone();
        let mut round = first_round.clone();
        let this = Self { first_round: Vec::new(), named: Vec::new(), remainder: Vec::new() };
        while named.len() < 3 {
            let Some(best) =
                round.iter().find(|p| !named.iter().any(|n| n.candidate.name() == p.candidate.name())).cloned()
            else {
                break;
            };
            if !this.qualifies(&best, streams, floor) {
                break;
            }
            remainder = attribution::subtract(&best, runs, &remainder, &context);
            named.push(best);
            round = profile_all(runs, &remainder, &context, streams.autocorrelation_time);
        }
        Self { first_round, named, remainder }
    }

    /// What a candidate removes on the selection part beyond the sim's own signature, in noise
    /// variances.
    fn excess(&self, profiled: &Profiled, streams: &Streams, floor: &Signature) -> f64 {
        streams.to_noise(profiled.selected()) - floor.of(profiled.candidate.name())
    }

    /// Decisive evidence on the training part and at least an effect of
    /// [`MIN_EFFECT_TO_NOISE`] of the noise, out of sample, beyond the signature.
    fn qualifies(&self, profiled: &Profiled, streams: &Streams, floor: &Signature) -> bool {
        profiled.delta_bic >= MIN_DELTA_BIC
            && self.excess(profiled, streams, floor) >= naming_threshold(streams, &profiled.fit.touched, floor)
    }

    /// The strength of the leading named effect (0 without one).
    fn strength(&self, streams: &Streams, floor: &Signature) -> f64 {
        self.named.first().map_or(0.0, |p| self.excess(p, streams, floor))
    }
}

/// The least a balance effect must explain beyond the signature to be named, in noise
/// variances: an effect of [`MIN_EFFECT_TO_NOISE`] of what the stream shows where nothing is
/// wrong, on the runs it acts on. That is the white noise plus the sim's own gap on data it
/// matches (the signature's, per kind of run and angle of attack): a balance's coloured noise
/// (vibration, drift of the electronics) and the model's own structural error are noise to
/// this question as much as the white part is, and a candidate fitted on a new recording
/// picks up part of them (on another excitation the structural error no longer lies outside
/// the fitted terms, as it does on the fit's own recording).
fn naming_threshold(streams: &Streams, touched: &[bool], floor: &Signature) -> f64 {
    MIN_EFFECT_TO_NOISE * MIN_EFFECT_TO_NOISE * noise_with_own_gap(streams, touched, floor)
}

/// The noise of the touched runs in units of the white noise variance: one plus the sim's own
/// gap there (the signature's per kind of run and angle of attack, weighted by samples).
fn noise_with_own_gap(streams: &Streams, touched: &[bool], floor: &Signature) -> f64 {
    let (mut sum, mut n) = (0.0, 0.0);
    for (run, _) in streams.runs.iter().zip(touched).filter(|(_, touched)| **touched) {
        let weight = run.len() as f64;
        sum += weight * floor.gap_of(run.kind.as_str(), run.alpha_deg).max(0.0);
        n += weight;
    }
    1.0 + if n > 0.0 { sum / n } else { 0.0 }
}

/// Stage 3: the structure probe, fitted on the training part and measured on the selection
/// part, on the original residual and on the remainder after the named effects.
pub struct ProbeResult {
    /// Per probe group, what it removes of the original residual out of sample, in noise
    /// variances.
    pub base: BTreeMap<String, f64>,
    /// Structure beyond the signature in the remainder (the group that finds most), in noise
    /// variances.
    pub structure: f64,
    /// The remainder holds structure beyond what the named effect may leave.
    pub remainder_structured: bool,
}

impl ProbeResult {
    fn run(streams: &Streams, balance: &BalanceAttribution, floor: &Signature) -> Self {
        let runs = &streams.runs;
        let probe_of = |residuals: &[Vec<f64>], groups: &[&str]| -> BTreeMap<String, f64> {
            let segments = attribution::segments(runs, residuals);
            groups
                .iter()
                .map(|group| {
                    let columns = attribution::probe_columns(runs, group);
                    let removed = regression::fit_through_origin(&segments, &columns).map_or(0.0, |fit| {
                        regression::selection_gap(&segments, &columns, &fit.beta, &fit.touched).removed()
                    });
                    ((*group).to_owned(), streams.to_noise(removed))
                })
                .collect()
        };
        let base = probe_of(&streams.residuals, &attribution::PROBE_GROUPS);
        let now = if balance.named.is_empty() {
            base.clone()
        } else {
            probe_of(&balance.remainder, &attribution::REMAINDER_PROBE_GROUPS)
        };
        let structure = now.iter().map(|(group, value)| value - floor.probe_of(group)).fold(0.0, f64::max);
        // The probe's own scatter grows with everything the residual holds, not only its white
        // part: the least structure that counts is scaled by the noise as the naming threshold
        // counts it (white plus the sim's own gap).
        let noise_scale = noise_with_own_gap(streams, &vec![true; runs.len()], floor);
        let remainder_structured = balance.named.first().is_some_and(|top| {
            structure
                >= (MIN_REMAINDER_TO_NOISE * noise_scale).max(MAX_REMAINDER_SHARE * balance.excess(top, streams, floor))
        });
        Self { base, structure, remainder_structured }
    }
}

/// Stage 4: the sensor candidates on the pressure channels, and the one named if it qualifies.
pub struct SensorAttribution {
    /// Every finding, strongest first.
    pub findings: Vec<SensorFinding>,
    /// The qualifying finding with the most excess, if any.
    pub named: Option<SensorFinding>,
}

/// What a sensor finding removes on the selection part over its noise variance (infinite for a
/// dead channel, whose whole signal is the gap).
fn sensor_selected_to_noise(finding: &SensorFinding) -> f64 {
    if finding.explained.is_infinite() {
        return f64::INFINITY;
    }
    finding.selection.removed() / finding.noise_var.max(f64::MIN_POSITIVE)
}

impl SensorAttribution {
    fn run(streams: &Streams, floor: &Signature) -> Self {
        let findings = sensor::findings(&streams.runs, floor.pressure_alignment_s.unwrap_or(0.0));
        let min_ratio = MIN_EFFECT_TO_NOISE * MIN_EFFECT_TO_NOISE;
        let named = findings
            .iter()
            .filter(|f| Self::excess_of(f, floor) >= min_ratio && f.delta_bic >= MIN_DELTA_BIC)
            .filter(|f| Self::stands_out(f, &findings, floor))
            .max_by(|a, b| Self::excess_of(a, floor).total_cmp(&Self::excess_of(b, floor)))
            .cloned();
        Self { findings, named }
    }

    /// Whether a fault of one channel stands out from the other channels (any other finding
    /// passes). The strongest finding on channels without this one measures what a channel
    /// shows without a fault of its own here: a deviation common to the taps (a
    /// dynamic-pressure fluctuation scales every Cp), the pressure model's own error from
    /// recording to recording, or the footprint of other channels' effect (the filter's modes
    /// follow lagged channels, and a healthy channel's innovation then shows their error). The
    /// contract's fault is of one channel, so the named one must lead that by at least as much
    /// again, and by the naming threshold; a deviation several taps share alike is not one
    /// channel's fault.
    fn stands_out(finding: &SensorFinding, findings: &[SensorFinding], floor: &Signature) -> bool {
        if finding.effect != firmware_sim::effect::Effect::PressureFault {
            return true;
        }
        let runner_up = findings
            .iter()
            .filter(|other| {
                !other.channels.is_empty() && other.channels.iter().all(|channel| !finding.channels.contains(channel))
            })
            .map(|other| Self::excess_of(other, floor).max(0.0))
            .fold(0.0, f64::max);
        let lead = Self::excess_of(finding, floor) - runner_up;
        lead >= (MIN_EFFECT_TO_NOISE * MIN_EFFECT_TO_NOISE).max(runner_up)
    }

    fn excess_of(finding: &SensorFinding, floor: &Signature) -> f64 {
        sensor_selected_to_noise(finding) - floor.of(&finding.floor_key())
    }

    fn strength(&self, floor: &Signature) -> f64 {
        self.named.as_ref().map_or(0.0, |f| Self::excess_of(f, floor))
    }
}

/// Stage 5: the balance gap of every run on the selection part against the sim's own, and on
/// the held-out part for the report.
pub struct GapSummary {
    /// The gap on every run's held-out part (for the report).
    pub heldout: regression::HeldoutGap,
    /// Gap beyond noise per kind of run (and kind at alpha) on the selection part, in noise
    /// variances.
    pub by_kind: BTreeMap<String, f64>,
    /// Runs whose selection-part gap exceeds the sim's own by a significant margin.
    pub excess_runs: Vec<usize>,
    /// The selection-part gap of all runs together lies beyond the sim's own scatter from
    /// recording to recording ([`GapSummary::beyond_scatter`]).
    pub beyond_scatter: bool,
}

impl GapSummary {
    fn run(streams: &Streams, floor: &Signature) -> Self {
        let runs = &streams.runs;
        let segments = attribution::segments(runs, &streams.residuals);
        let all_touched = vec![true; runs.len()];
        let no_columns = vec![Vec::new(); runs.len()];
        let heldout = regression::heldout_gap(&segments, &no_columns, &[], &all_touched);
        let run_gaps: Vec<(f64, usize)> = segments
            .iter()
            .map(|segment| {
                let g = regression::selection_gap(std::slice::from_ref(segment), &[Vec::new()], &[], &[true]);
                (streams.to_noise(g.mse_before - g.noise_var), g.n)
            })
            .collect();
        let mut by_kind: BTreeMap<String, (f64, usize)> = BTreeMap::new();
        for (run, &(gap_to_noise, n)) in runs.iter().zip(&run_gaps) {
            for key in [run.kind.as_str().to_owned(), kind_alpha_key(run.kind.as_str(), run.alpha_deg)] {
                let slot = by_kind.entry(key).or_default();
                slot.0 += gap_to_noise * n as f64;
                slot.1 += n;
            }
        }
        let by_kind =
            by_kind.into_iter().map(|(kind, (sum, n))| (kind, if n == 0 { 0.0 } else { sum / n as f64 })).collect();
        // A run's gap counts beyond the floor by at least an effect of half the noise RMS and
        // outside the scatter of both mean squares (the floor's taken as equally uncertain
        // relative to its size).
        let min_ratio = MIN_EFFECT_TO_NOISE * MIN_EFFECT_TO_NOISE;
        let mut pooled = PooledGap::default();
        let excess_runs = (0..runs.len())
            .filter(|&idx| {
                let floor_gap = floor.gap_of(runs[idx].kind.as_str(), runs[idx].alpha_deg);
                let excess = run_gaps[idx].0 - floor_gap;
                let values: Vec<f64> = segments[idx].select.samples().map(|i| segments[idx].residual[i]).collect();
                let select = regression::Segment {
                    residual: &values,
                    training: 0..0,
                    select: regression::Interleave::default(),
                    heldout: 0..values.len(),
                };
                let standard_error = streams.to_noise(regression::mean_square_standard_error(&select));
                let relative_floor = (floor_gap + 1.0) / (run_gaps[idx].0 + 1.0).max(f64::MIN_POSITIVE);
                let scatter = standard_error * (1.0 + relative_floor * relative_floor).sqrt();
                pooled.add(run_gaps[idx].0, floor_gap, scatter, run_gaps[idx].1);
                excess >= min_ratio && excess >= GAP_SIGNIFICANCE_Z * scatter
            })
            .collect();
        Self { heldout, by_kind, excess_runs, beyond_scatter: pooled.beyond_scatter() }
    }
}

/// The selection-part gap of all runs together against the sim's own, weighted by samples.
#[derive(Debug, Default, Clone, Copy)]
struct PooledGap {
    /// Sum of samples times the gap, in noise variances.
    gap: f64,
    /// Sum of samples times the sim's own gap.
    floor: f64,
    /// Sum of the squares of samples times the scatter of the excess.
    scatter_sq: f64,
    /// Samples.
    n: f64,
}

impl PooledGap {
    fn add(&mut self, gap_to_noise: f64, floor_to_noise: f64, scatter: f64, n: usize) {
        if !(gap_to_noise.is_finite() && floor_to_noise.is_finite() && scatter.is_finite()) || n == 0 {
            return;
        }
        let n = n as f64;
        self.gap += n * gap_to_noise;
        self.floor += n * floor_to_noise;
        self.scatter_sq += (n * scatter).powi(2);
        self.n += n;
    }

    /// Whether the gap is a real gap even though nothing predicts it. The sim's own structural
    /// error is measured on one recording, the fit's; on other inputs (another excitation,
    /// another rate of roll) its mean square is not bounded by that, and may well be as large
    /// again. So the excess over the sim's own gap must be at least the sim's own gap (the
    /// floor taken as known within a factor of two) and the naming threshold, and significant
    /// by [`GAP_SIGNIFICANCE_Z`] standard errors. A gap this far beyond the sim is not its
    /// scatter from recording to recording, whether or not any candidate or probe predicts it
    /// (a random modulation, such as a fluctuating dynamic pressure, predicts nothing out of
    /// sample).
    fn beyond_scatter(&self) -> bool {
        if self.n <= 0.0 {
            return false;
        }
        let excess = (self.gap - self.floor) / self.n;
        let floor = self.floor / self.n;
        let scatter = self.scatter_sq.sqrt() / self.n;
        excess >= (MIN_EFFECT_TO_NOISE * MIN_EFFECT_TO_NOISE).max(floor) && excess >= GAP_SIGNIFICANCE_Z * scatter
    }
}

/// Stage 6: the verdict.
enum Decision {
    /// A sensor effect explains the gap.
    Sensor(Box<SensorFinding>),
    /// The named balance effects explain the gap.
    Balance,
    /// A real gap with structure that no candidate explains.
    Unattributed,
    /// The gap is at the noise floor, or holds no structure beyond the sim's own scatter.
    None,
}

impl Decision {
    /// A sensor effect stronger than any balance effect wins; named balance effects win unless
    /// the probe still finds structure after them; a gap beyond the sim's own, or structure in
    /// the remainder, is unattributed only when something predicts part of it out of sample
    /// (a bigger but unpredictable gap is the sim's own scatter from recording to recording,
    /// not an effect).
    fn make(
        streams: &Streams,
        balance: &BalanceAttribution,
        probe: &ProbeResult,
        sensor: &SensorAttribution,
        gaps: &GapSummary,
        floor: &Signature,
    ) -> Self {
        let balance_strength = balance.strength(streams, floor);
        if let Some(finding) = &sensor.named
            && sensor.strength(floor) > balance_strength
        {
            return Self::Sensor(Box::new(finding.clone()));
        }
        if !balance.named.is_empty() {
            return if probe.remainder_structured { Self::Unattributed } else { Self::Balance };
        }
        // Nothing named: a gap is unattributed only where something predicts at least an effect
        // of half the noise RMS of it out of sample (the noise as the naming threshold counts it:
        // white, plus the sim's own gap on the runs concerned), or where it lies beyond the sim's
        // own scatter; a smaller gap than that which nothing predicts is the sim's scatter from
        // recording to recording (the runs are still listed).
        let all_runs = vec![true; streams.runs.len()];
        let predicted = probe.structure >= naming_threshold(streams, &all_runs, floor)
            || balance
                .first_round
                .first()
                .is_some_and(|p| balance.excess(p, streams, floor) >= naming_threshold(streams, &p.fit.touched, floor));
        if predicted || gaps.beyond_scatter { Self::Unattributed } else { Self::None }
    }

    fn verdict(&self) -> Verdict {
        match self {
            Self::Sensor(_) | Self::Balance => Verdict::Effect,
            Self::Unattributed => Verdict::Unattributed,
            Self::None => Verdict::None,
        }
    }
}

/// The working data behind a diagnosis, for the report's plots.
#[derive(Debug, Clone)]
pub struct Evidence {
    /// Streams of every run.
    pub runs: Vec<streams::RunStreams>,
    /// Every balance candidate profiled on the original residual, best first.
    pub first_round: Vec<Profiled>,
    /// The named balance effects, in the order they were selected.
    pub named: Vec<Profiled>,
    /// The balance residual after the named effects.
    pub remainder: Vec<Vec<f64>>,
    /// What every candidate family searched on this recording.
    pub families: Vec<Family>,
}

/// What one candidate family searched on a recording (the report's statement of its grids).
#[derive(Debug, Clone, PartialEq)]
pub struct Family {
    /// The effect's name (`recalibration` for G0).
    pub name: &'static str,
    /// Number of forms profiled (`None` for the sensor families, searched by their own scans).
    pub forms: Option<usize>,
    /// The parameters with their ranges or choices.
    pub searched: String,
}

/// Every balance candidate profiled on `residuals`, ranked by its complexity-penalised evidence.
fn profile_all(
    runs: &[streams::RunStreams],
    residuals: &[Vec<f64>],
    context: &Context<'_>,
    autocorrelation_time: f64,
) -> Vec<Profiled> {
    let mut all: Vec<Profiled> = candidates::ALL
        .iter()
        .filter_map(|&candidate| attribution::profile(candidate, runs, residuals, context, autocorrelation_time))
        .collect();
    // Ranked by the evidence itself; the signature's floor decides only whether the leader
    // qualifies (subtracting floors measured on other data would add their noise to the ranking).
    all.sort_by(|a, b| b.delta_bic.total_cmp(&a.delta_bic));
    // Candidates the evidence cannot tell apart from the leader (within MIN_DELTA_BIC): the one
    // with the fewest parameters leads (the pair is reported as confounded).
    if let Some(best) = all.first().map(|p| p.delta_bic) {
        let k = |p: &Profiled| p.fit.beta.len() + p.form.n_profiled();
        if let Some((idx, _)) = all
            .iter()
            .enumerate()
            .filter(|(_, p)| p.delta_bic >= best - MIN_DELTA_BIC)
            .min_by(|a, b| k(a.1).cmp(&k(b.1)).then(b.1.delta_bic.total_cmp(&a.1.delta_bic)))
        {
            let simplest = all.remove(idx);
            all.insert(0, simplest);
        }
    }
    all
}

fn alphas(runs: &[streams::RunStreams], touched: &[bool]) -> Vec<f64> {
    let mut out: Vec<f64> = runs.iter().zip(touched).filter(|(_, t)| **t).map(|(run, _)| run.alpha_deg).collect();
    out.sort_by(f64::total_cmp);
    out.dedup();
    out
}

fn balance_effect(
    profiled: &Profiled,
    runs: &[streams::RunStreams],
    residuals: &[Vec<f64>],
    context: &Context<'_>,
    floor: &Signature,
) -> EffectResult {
    let segments = attribution::segments(runs, residuals);
    let columns = attribution::all_columns(profiled.candidate, &profiled.form, runs, context);
    let mut gap = regression::heldout_gap(&segments, &columns, &profiled.fit.beta, &profiled.fit.touched);
    // The sim's own floor over the touched runs' held-out samples, by kind of run.
    let (mut floor_sum, mut count) = (0.0, 0usize);
    for (run, touched) in runs.iter().zip(&profiled.fit.touched) {
        if *touched {
            floor_sum += floor.gap_of(run.kind.as_str(), run.alpha_deg).max(0.0) * run.heldout.len() as f64;
            count += run.heldout.len();
        }
    }
    gap.floor_var = if count == 0 { 0.0 } else { floor_sum / count as f64 * gap.noise_var };
    EffectResult {
        name: profiled.candidate.name().into(),
        block: profiled.candidate.block().name().into(),
        params: candidates::physical_params(profiled.candidate, &profiled.form, &profiled.fit.beta, context, &columns),
        heldout_rms_before: gap.gap_before(),
        heldout_rms_after: gap.gap_after(),
        shrink: gap.shrink(),
        shrink_total: regression::HeldoutGap { floor_var: 0.0, ..gap }.shrink(),
        shrink_measured: true,
        delta_bic: finite_or_null(profiled.delta_bic),
        effect_to_noise: finite_or_null((profiled.explained() / gap.noise_var.max(f64::MIN_POSITIVE)).sqrt()),
        evidence: format!(
            "explains {:.3e} of C_l RMS on the training part of {} run(s) (noise {:.3e}); delta BIC {:.0}",
            profiled.explained().sqrt(),
            profiled.fit.touched.iter().filter(|t| **t).count(),
            gap.noise_var.sqrt(),
            profiled.delta_bic
        ),
    }
}

fn sensor_effect(finding: &SensorFinding) -> EffectResult {
    let mut params = BTreeMap::new();
    for (key, value) in &finding.params {
        let json = match value {
            ParamValue::Number(number) => serde_json::json!(finite_or_null(*number)),
            ParamValue::Text(text) => serde_json::json!(text),
        };
        params.insert(key.clone(), json);
    }
    if let Some(channel) = &finding.channel {
        params.insert("channel".into(), serde_json::json!(channel));
    }
    params.insert("channels".into(), serde_json::json!(finding.channels));
    let dead = finding.heldout.n == 0;
    EffectResult {
        name: finding.effect.name().into(),
        block: "sensor".into(),
        params,
        heldout_rms_before: finding.heldout.gap_before(),
        heldout_rms_after: finding.heldout.gap_after(),
        shrink: if dead { 1.0 } else { finding.heldout.shrink() },
        shrink_total: if dead { 1.0 } else { finding.heldout.shrink() },
        shrink_measured: !dead,
        delta_bic: finite_or_null(finding.delta_bic),
        effect_to_noise: finite_or_null((finding.explained / finding.noise_var.max(f64::MIN_POSITIVE)).sqrt()),
        evidence: finding.evidence.clone(),
    }
}

fn describe_structure(
    runs: &[streams::RunStreams],
    excess_runs: &[usize],
    probe_share: f64,
    best: Option<(&str, f64)>,
) -> String {
    let kinds: Vec<String> = excess_runs
        .iter()
        .map(|&idx| format!("{} ({} at {} deg)", runs[idx].file, runs[idx].kind.as_str(), runs[idx].alpha_deg))
        .collect();
    let best = best
        .map(|(name, excess)| {
            format!("; the best candidate, {name}, explains {excess:.2} noise variances beyond the sim's signature")
        })
        .unwrap_or_default();
    format!(
        "a gap above the noise floor in {} with no candidate that explains it{best}; a generic probe (odd powers of the roll angle, rate nonlinearity, powers of the moment, slowly varying gain on the moment, lagged inputs) finds {:.2} noise variances of structure",
        if kinds.is_empty() { "the remainder".to_owned() } else { kinds.join(", ") },
        probe_share
    )
}

/// Pairs among the leading candidates whose column spans are nearly the same (largest
/// canonical correlation above [`CONFOUNDED_CORRELATION`]) and whose evidence is close: they
/// cannot be told apart with this data (gap-diagnosis.md section 4.3 step 7).
fn confounding(
    ranked: &[Profiled],
    runs: &[streams::RunStreams],
    residuals: &[Vec<f64>],
    context: &Context<'_>,
) -> Vec<Confounding> {
    let segments = attribution::segments(runs, residuals);
    let lead: Vec<&Profiled> = ranked.iter().filter(|p| p.delta_bic > 0.0).take(3).collect();
    let mut out = Vec::new();
    for (i, a) in lead.iter().enumerate() {
        for b in &lead[i + 1..] {
            if (a.delta_bic - b.delta_bic).abs() >= MIN_DELTA_BIC {
                continue;
            }
            let cols_a = attribution::all_columns(a.candidate, &a.form, runs, context);
            let cols_b = attribution::all_columns(b.candidate, &b.form, runs, context);
            let correlation = result::canonical_correlation(&segments, &cols_a, &cols_b);
            if correlation > CONFOUNDED_CORRELATION {
                out.push(Confounding {
                    a: a.candidate.name().into(),
                    b: b.candidate.name().into(),
                    canonical_correlation: finite_or_null(correlation),
                    experiment: format!(
                        "{}; {}",
                        a.candidate.separating_experiment(),
                        b.candidate.separating_experiment()
                    ),
                });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::{MIN_EFFECT_TO_NOISE, PooledGap};

    fn pooled(runs: &[(f64, f64, f64)]) -> bool {
        let mut pooled = PooledGap::default();
        for &(gap, floor, scatter) in runs {
            pooled.add(gap, floor, scatter, 1000);
        }
        pooled.beyond_scatter()
    }

    /// The excess must reach the sim's own gap (or the naming threshold, when that is larger)
    /// and two standard errors, pooled over the runs by samples; non-finite runs are left out.
    #[test]
    fn a_gap_is_beyond_the_sims_scatter_at_twice_its_own_gap_and_two_standard_errors() {
        let min = MIN_EFFECT_TO_NOISE * MIN_EFFECT_TO_NOISE;
        // Twice the sim's own gap, tiny scatter: beyond; a hair less: not.
        assert!(pooled(&[(2.0, 1.0, 0.01), (2.0, 1.0, 0.01)]));
        assert!(!pooled(&[(2.0 - 1e-9, 1.0, 0.01), (2.0, 1.0, 0.01)]));
        // A small floor: the naming threshold decides.
        assert!(pooled(&[(0.1 + min, 0.1, 0.01)]));
        assert!(!pooled(&[(0.1 + min - 1e-9, 0.1, 0.01)]));
        // Large enough but not significant: two runs of scatter s pool to s / sqrt(2).
        assert!(!pooled(&[(3.0, 1.0, 1.5), (3.0, 1.0, 1.5)]));
        assert!(pooled(&[(3.0, 1.0, 1.4), (3.0, 1.0, 1.4)]));
        // A run without a figure counts for nothing; no runs at all is no gap.
        assert!(pooled(&[(3.0, 1.0, 0.1), (f64::NAN, 1.0, 0.1)]));
        assert!(!pooled(&[]));
    }
}

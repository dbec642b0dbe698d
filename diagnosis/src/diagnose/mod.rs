//! Sim-to-real gap diagnosis (docs/spec/diagnosis.md): where the recording departs from the
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
mod decision;
pub mod encoder;
pub mod faults;
pub mod finding;
pub mod gap_ledger;
pub mod lag_set;
pub mod ledger;
mod pressure_lag;
pub mod regression;
pub mod report;
pub mod result;
pub mod sensor;
pub mod signature;
mod stages;
pub mod streams;

use std::collections::BTreeMap;
use std::time::Instant;

use estimator_core::CoefficientSet;
use firmware_sim::dataset::Dataset;

use attribution::Profiled;
use candidates::Context;
use decision::*;
use finding::{ParamValue, SensorFinding};
use model_fit::fit::pipeline::{FitConfig, fit_dataset};
use model_fit::fit::split::Split;
use result::{Confounding, Diagnosis, EffectResult, Gap, Unexplained, Verdict, Where, finite_or_null};
pub use signature::{
    DEFAULT_SIGNATURE_JSON, SIGNATURE_FILE, Signature, SignatureFileError, default_signature, signature,
    signature_beside,
};
use stages::*;
pub use stages::{BalanceAttribution, GapSummary, LeftGap, ProbeResult, SensorAttribution, Streams};

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
/// estimation scatter lies (scaled, like the naming threshold, by the sim's own gap). The noise
/// variance itself, as for the gap the named effects leave, was measured and not kept
/// (docs/results.md): it named a cubic stiffness of the mount `gravity_tare` on 6 of 20 outside
/// cases of the own tunnel.
pub const MIN_REMAINDER_TO_NOISE: f64 = 0.05;

/// Largest gap the named balance effects may leave on the runs they act on, as a ratio of its
/// RMS to the noise RMS (beyond the sim's own gap there), before the gap counts as
/// unattributed. The contract lets an effect whose effect-to-noise ratio is below one be
/// missed, and no more (docs/spec/diagnosis.md, "The verdict `none`"): a gap of at least
/// the noise RMS that the named effects leave is a real gap that they do not explain, and
/// "unattributed" is for a real gap "no candidate explains" (the same contract, the
/// three questions). An effect in a form its family spans leaves its noise; one that leaves
/// the noise RMS again is some other effect that a candidate partly fits (a clipped balance
/// taken for a slow flow state, an encoder's backlash for a resonance). A strong effect leaves
/// more than the noise through the candidate's own imprecision (an inertial reaction of 18
/// noise RMS, through the estimated acceleration, left 6), so the remainder must also be a
/// share of the gap ([`MAX_REMAINDER_GAP_SHARE`]).
pub const MAX_REMAINDER_GAP_TO_NOISE: f64 = 1.0;

/// Least gap that nothing predicts and that still counts as real, as a ratio of its RMS (beyond
/// the sim's own gap) to the noise RMS: one, the level below which the contract lets an effect
/// be missed and at which it calls the gap the noise floor (docs/spec/diagnosis.md, "The
/// verdict `none`"). A gap that a candidate or the structure probe predicts out of sample is
/// real from the naming threshold ([`MIN_EFFECT_TO_NOISE`]) up; a gap that nothing predicts has
/// only its size as evidence, against a floor measured on one other recording, so it must not
/// be significantly below the contract's level ([`GAP_SIGNIFICANCE_Z`] standard errors). A
/// smaller one is the sim's scatter from recording to recording, or an effect the contract lets
/// be missed.
pub const MIN_UNPREDICTED_GAP_TO_NOISE: f64 = 1.0;

/// Largest share of the gap's RMS (beyond noise and the sim's own gap) that the named balance
/// effects may leave and still explain it: half. Effects that remove less than half of a gap
/// (a shrink below 0.5, in the contract's measure of how far the gap shrinks) do not explain
/// it; they fit part of something else.
pub const MAX_REMAINDER_GAP_SHARE: f64 = 0.5;

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
    Fit(#[from] model_fit::fit::FitError),
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
    // A roll angle recorded in steps coarser than its motion spikes the rate every balance
    // candidate is driven by: what they explain is the encoder's, outside the vocabulary.
    let coarse_encoder = encoder::quantisation(&streams.runs);
    // A play in the encoder's drive kinks the rate at every reversal: the same holds.
    let encoder_play = encoder::play(&streams.runs);
    let decision = match decision {
        Decision::Balance if coarse_encoder.is_some() || encoder_play.is_some() => Decision::Unattributed,
        other => other,
    };

    let context = streams.context();
    let own_signature = Signature {
        explained_to_noise: balance
            .first_round
            .iter()
            .map(|p| (p.candidate.name().to_owned(), streams.to_noise(p.selected())))
            .chain(sensor.findings.iter().map(|f| (f.floor_key(), sensor_selected_to_noise(f))))
            .chain(sensor.channel_lags.iter().map(|f| {
                (sensor::channel_lag_key(f.channels.first().map_or("", String::as_str)), sensor_selected_to_noise(f))
            }))
            .filter(|(_, value)| value.is_finite())
            .collect(),
        probe_to_noise: probe.base.clone(),
        gap_to_noise_by_kind: gaps.by_kind.clone(),
        pressure_alignment_s: pressure_lag::Alignment::new(&streams.runs, |run| run.fit_samples().collect())
            .and_then(|alignment| alignment.reference()),
        pressure_alignment_scatter_s: pressure_lag::run_scatter_s(&streams.runs, pressure_lag::REFERENCE_RANGE_S),
        pressure_alignment_by_kind: config
            .signature
            .is_none()
            .then(|| pressure_lag::by_kind(&streams.runs))
            .filter(|by_kind| !by_kind.is_empty()),
        // Only a signature needs it (a diagnosis without one is the sim on its own data).
        pressure_channel_lags: config.signature.is_none().then(|| lag_set::identify(&streams.runs)).flatten(),
        pressure_alone_mean: config
            .signature
            .is_none()
            .then(|| signature::pressure_alone_means(&streams.runs))
            .flatten(),
    };

    let mut effects = Vec::new();
    let mut where_ = Where::default();
    let mut unexplained = None;
    let runs = &streams.runs;
    match &decision {
        Decision::Sensor(finding) => {
            effects.push(sensor_effect(finding, SensorAttribution::excess_of(finding, &floor)));
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
            let encoder_note = coarse_encoder
                .map(|q| {
                    format!(
                        "the recorded roll angle moves in steps of {:.3} deg, {:.0} times its motion per sample (a coarse encoder: the rate and acceleration from it come in spikes); ",
                        q.quantum_deg,
                        q.quantum_deg / q.motion_per_sample_deg
                    )
                })
                .unwrap_or_default()
                + &encoder_play
                    .map(|play| {
                        format!(
                            "the recorded roll angle holds {:.3} s at each reversal and leaves it {:.1} times faster than it arrived, with {:.0} % of that rate at once (a play in the encoder of about {:.2} deg: the rate from it kinks there); ",
                            play.hold_s,
                            play.exit_to_entry,
                            100.0 * play.release_share,
                            play.width_deg
                        )
                    })
                    .unwrap_or_default();
            let gain_note = gain_note(&balance, runs, &context);
            // A best fit the data cannot tell from its own limits is said to be one.
            let limit_note = best
                .filter(|p| p.limit_margin < MIN_DELTA_BIC)
                .map(|p| {
                    format!(
                        "{}'s best form fits no better than the forms it tends to at the ends of its time constant (its drive, or the drive's static term; {:.1} of BIC), so the data do not resolve it; ",
                        p.candidate.name(),
                        p.limit_margin
                    )
                })
                .unwrap_or_default();
            unexplained = Some(Unexplained {
                description: encoder_note
                    + &gain_note
                    + &limit_note
                    + &describe_structure(
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
            .map(result::CandidateSummary::from_profiled(streams.noise_var, &context.alphas_deg))
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
    /// Every number the contract requires is finite (docs/spec/diagnosis.md).
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

#[cfg(test)]
mod tests {
    use super::{MIN_EFFECT_TO_NOISE, MIN_UNPREDICTED_GAP_TO_NOISE, PooledGap};

    fn pooled(runs: &[(f64, f64, f64)]) -> bool {
        let mut pooled = PooledGap::default();
        for &(gap, floor, scatter) in runs {
            pooled.add(gap, floor, scatter, 1000);
        }
        pooled.beyond_scatter()
    }

    /// The excess must reach the sim's own gap and two standard errors, pooled over the runs by
    /// samples.
    #[test]
    fn a_gap_is_beyond_the_sims_scatter_at_twice_its_own_gap_and_two_standard_errors() {
        // Twice the sim's own gap, tiny scatter: beyond; a hair less: not.
        assert!(pooled(&[(2.0, 1.0, 0.01), (2.0, 1.0, 0.01)]));
        assert!(!pooled(&[(2.0 - 1e-9, 1.0, 0.01), (2.0, 1.0, 0.01)]));
    }

    /// A gap nothing predicts counts only where it is not significantly below the noise RMS:
    /// with a tight scatter, a gap of half the noise RMS beyond the sim's own is its floor, and
    /// never does one below the naming threshold count.
    #[test]
    fn an_unpredicted_gap_below_the_noise_rms_is_the_floor() {
        let level = MIN_UNPREDICTED_GAP_TO_NOISE * MIN_UNPREDICTED_GAP_TO_NOISE;
        assert!(!pooled(&[(0.1 + 0.28, 0.1, 0.03)]));
        // Two standard errors below the level still count; a hair further does not.
        assert!(pooled(&[(0.1 + level - 0.2, 0.1, 0.1)]));
        assert!(!pooled(&[(0.1 + level - 0.2 - 1e-9, 0.1, 0.1)]));
        let naming = MIN_EFFECT_TO_NOISE * MIN_EFFECT_TO_NOISE;
        for scatter in [0.01, 0.1, 0.2, 0.3, 0.5, 1.0] {
            assert!(!pooled(&[(0.1 + naming, 0.1, scatter)]), "{scatter}");
        }
    }

    /// Large enough is not enough without significance; non-finite runs are left out.
    #[test]
    fn a_gap_needs_significance_and_runs_with_figures() {
        // Large enough but not significant: two runs of scatter s pool to s / sqrt(2).
        assert!(!pooled(&[(3.0, 1.0, 1.5), (3.0, 1.0, 1.5)]));
        assert!(pooled(&[(3.0, 1.0, 1.4), (3.0, 1.0, 1.4)]));
        // A run without a figure counts for nothing; no runs at all is no gap.
        assert!(pooled(&[(3.0, 1.0, 0.1), (f64::NAN, 1.0, 0.1)]));
        assert!(!pooled(&[]));
    }
}

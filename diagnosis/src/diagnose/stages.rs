//! The diagnosis's stages and their typed results: the sim on the recorded inputs
//! ([`Streams`]), the balance candidates ([`BalanceAttribution`]), the structure probe
//! ([`ProbeResult`]), the sensor candidates ([`SensorAttribution`]) and the gap per run
//! ([`GapSummary`]).

use super::*;

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
    pub(super) set: CoefficientSet,
    pub(super) moment_scale_nm: f64,
    pub(super) half_span_time_s: f64,
    pub(super) resonance_min_hz: f64,
    pub(super) resonance_seeds_hz: Vec<f64>,
}

impl Streams {
    pub(super) fn build(dataset: &Dataset, set: &CoefficientSet, config: &DiagnoseConfig) -> Self {
        let mut runs = streams::build(dataset, set, &config.split);
        if let Some(means) = config.signature.as_ref().and_then(|s| s.pressure_alone_mean.as_ref()) {
            for run in &mut runs {
                if let Some(own) = means.get(&run.kind_alpha_key()) {
                    run.remove_own_mean(own);
                }
            }
        }
        let residuals: Vec<Vec<f64>> = runs.iter().map(|run| run.residual.clone()).collect();
        let segments = attribution::segments(&runs, &residuals);
        let noise_var = regression::difference_noise_var(&segments, None);
        let autocorrelation_time = regression::integrated_autocorrelation(&segments, 200);
        let resonance_min_hz = candidates::resonance_min_hz(&runs);
        let resonance_seeds_hz = runs.first().map_or_else(Vec::new, |run| {
            let band_hz = candidates::BalanceResonance::band_hz(run.sample_hz, resonance_min_hz);
            candidates::resonance_seeds_hz(&runs, &residuals, band_hz)
        });
        Self {
            noise_var,
            autocorrelation_time,
            residuals,
            set: *set,
            moment_scale_nm: dataset.tunnel.dynamic_pressure_pa() * dataset.wing.area_m2 * dataset.wing.span_m,
            half_span_time_s: dataset.wing.span_m / (2.0 * dataset.tunnel.u_inf_mps),
            resonance_min_hz,
            resonance_seeds_hz,
            runs,
        }
    }

    /// What every candidate family searches on these runs.
    pub(super) fn families(&self) -> Vec<Family> {
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
    pub(super) fn context(&self) -> Context<'_> {
        Context {
            set: &self.set,
            moment_scale_nm: self.moment_scale_nm,
            half_span_time_s: self.half_span_time_s,
            cmu_ref: self.runs.iter().flat_map(|run| run.cmu.iter().flatten()).copied().fold(0.0, f64::max),
            n_runs: self.runs.len(),
            slow_tau_min_s: candidates::slow_tau_min_s(&self.set, self.runs.iter().map(|run| run.alpha_deg)),
            resonance_min_hz: self.resonance_min_hz,
            resonance_seeds_hz: self.resonance_seeds_hz.clone(),
            alphas_deg: {
                let mut alphas: Vec<f64> = self.runs.iter().map(|run| run.alpha_deg).collect();
                alphas.sort_by(f64::total_cmp);
                alphas.dedup();
                alphas
            },
            longest_run_s: self.runs.iter().map(|run| run.t_s.last().copied().unwrap_or(0.0)).fold(0.0, f64::max),
            two_jets: [0, 1].iter().all(|&side| self.runs.iter().any(|run| run.cmu[side].iter().any(|c| *c > 0.0))),
        }
    }

    /// A mean square in units of the balance noise variance.
    pub(super) fn to_noise(&self, value: f64) -> f64 {
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
    pub(super) fn run(streams: &Streams, floor: &Signature) -> Self {
        let context = streams.context();
        let runs = &streams.runs;
        let first_round = profile_all(runs, &streams.residuals, &context, streams.autocorrelation_time);
        let mut named: Vec<Profiled> = Vec::new();
        let mut remainder = streams.residuals.clone();
        let mut round = first_round.clone();
        let this = Self { first_round: Vec::new(), named: Vec::new(), remainder: Vec::new() };
        while named.len() < 3 {
            let Some(best) = round
                .iter()
                .filter(|p| p.plausible())
                .find(|p| p.candidate.repeatable() || !named.iter().any(|n| n.candidate.name() == p.candidate.name()))
                .cloned()
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
    pub(super) fn excess(&self, profiled: &Profiled, streams: &Streams, floor: &Signature) -> f64 {
        streams.to_noise(profiled.selected()) - floor.of(profiled.candidate.name())
    }

    /// Decisive evidence on the training part and at least an effect of
    /// [`MIN_EFFECT_TO_NOISE`] of the noise, out of sample, beyond the signature. The
    /// signature's floor of a candidate is what it took of the sim's own error on the fit's
    /// recording; on another recording it may take as much again ([`OWN_GAP_UNCERTAINTY`], as
    /// the sim's own gap and a sensor finding's floor are taken), so the excess must also reach
    /// the floor's uncertainty.
    ///
    /// The noise the effect is measured against is at least what the sim leaves beside it on
    /// this recording ([`left_beside`]): on another excitation the sim's structural error can
    /// exceed the signature's, and a candidate fitted there takes part of it whatever the
    /// recording holds.
    pub(super) fn qualifies(&self, profiled: &Profiled, streams: &Streams, floor: &Signature) -> bool {
        let own = (OWN_GAP_UNCERTAINTY - 1.0) * floor.of(profiled.candidate.name()).max(0.0);
        let beside = MIN_EFFECT_TO_NOISE * MIN_EFFECT_TO_NOISE * left_beside(profiled, streams);
        profiled.delta_bic >= MIN_DELTA_BIC
            && self.excess(profiled, streams, floor)
                >= naming_threshold(streams, &profiled.fit.touched, floor).max(own).max(beside)
    }

    /// The strength of the leading named effect (0 without one).
    pub(super) fn strength(&self, streams: &Streams, floor: &Signature) -> f64 {
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
pub(super) fn naming_threshold(streams: &Streams, touched: &[bool], floor: &Signature) -> f64 {
    MIN_EFFECT_TO_NOISE * MIN_EFFECT_TO_NOISE * noise_with_own_gap(streams, touched, floor)
}

/// What the sim leaves beside `profiled` on the selection part of the runs it touches, in noise
/// variances: the white noise and whatever gap the effect, fitted on the training part, does
/// not explain there. Where the effect is the gap, that is the noise and the sim's own gap on
/// this recording, the naming threshold's noise on the fit's recording
/// ([`noise_with_own_gap`]); where the sim's own error is larger on this excitation, it counts
/// that, and an effect must explain [`MIN_EFFECT_TO_NOISE`] squared of it. On a clean recording
/// of the second tunnel, where the sim's gap at 17 deg was 7.8 noise variances against 1.0 on the
/// fit's recording, a weight was named at an excess of 0.67 noise variances, with 3.1 left
/// beside it.
pub(super) fn left_beside(profiled: &Profiled, streams: &Streams) -> f64 {
    streams.to_noise(profiled.selection.mse_after)
}

/// The noise of the touched runs in units of the white noise variance: one plus the sim's own
/// gap there (the signature's per kind of run and angle of attack, weighted by samples).
pub(super) fn noise_with_own_gap(streams: &Streams, touched: &[bool], floor: &Signature) -> f64 {
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
    /// The gap on the selection part of the runs the named effects act on, beyond the white
    /// noise and the sim's own gap there, in noise variances: before them and after them (both 0
    /// without a named effect).
    pub remainder_gap: LeftGap,
}

impl ProbeResult {
    pub(super) fn run(streams: &Streams, balance: &BalanceAttribution, floor: &Signature) -> Self {
        let runs = &streams.runs;
        let probe_of = |residuals: &[Vec<f64>], groups: &[&str]| -> BTreeMap<String, f64> {
            let segments = attribution::segments(runs, residuals);
            groups
                .iter()
                .map(|group| {
                    let columns = if *group == attribution::SPECTRAL_LINE {
                        attribution::line_columns(runs, residuals, &streams.resonance_seeds_hz)
                    } else {
                        attribution::probe_columns(runs, group)
                    };
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
        let remainder_structured = balance
            .named
            .first()
            .is_some_and(|top| Self::structure_counts(structure, noise_scale, balance.excess(top, streams, floor)));
        let remainder_gap = LeftGap::of(streams, balance, floor);
        Self { base, structure, remainder_structured, remainder_gap }
    }

    /// Whether `structure` in the remainder, in noise variances beyond the signature, is another
    /// effect beside the named ones and not what they may leave: at least
    /// [`MIN_REMAINDER_TO_NOISE`] times `noise_scale` (the noise as the naming threshold counts
    /// it) and [`MAX_REMAINDER_SHARE`] of the leading named effect's `excess`.
    pub(super) fn structure_counts(structure: f64, noise_scale: f64, excess: f64) -> bool {
        structure >= (MIN_REMAINDER_TO_NOISE * noise_scale).max(MAX_REMAINDER_SHARE * excess)
    }

    /// The named effects do not explain the gap: they leave at least the noise RMS and at
    /// least half the gap's RMS ([`MAX_REMAINDER_GAP_TO_NOISE`], [`MAX_REMAINDER_GAP_SHARE`]).
    pub(super) fn gap_left(&self) -> bool {
        let LeftGap { before, after } = self.remainder_gap;
        after >= MAX_REMAINDER_GAP_TO_NOISE * MAX_REMAINDER_GAP_TO_NOISE
            && after >= MAX_REMAINDER_GAP_SHARE * MAX_REMAINDER_GAP_SHARE * before
    }
}

/// How far the sim's own gap on a recording may exceed the signature's, measured on the fit's
/// recording: a factor of two, for the gap named effects leave and for the gap beyond the
/// sim's scatter ([`PooledGap::beyond_scatter`]) alike. On other inputs the
/// sim's structural error is not bounded by what it was on the fit's, and a remainder that is
/// the sim's own error is no gap the named effects leave.
const OWN_GAP_UNCERTAINTY: f64 = 2.0;

/// The gap on the selection part of the runs the named balance effects act on, beyond the
/// white noise and twice the sim's own gap (the signature's, per kind of run and angle of
/// attack; the factor is its uncertainty on other inputs), in noise variances weighted by
/// samples, before and after the named effects.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LeftGap {
    /// Before the named effects.
    pub before: f64,
    /// After them.
    pub after: f64,
}

impl LeftGap {
    fn of(streams: &Streams, balance: &BalanceAttribution, floor: &Signature) -> Self {
        let runs = &streams.runs;
        let touched: Vec<bool> =
            (0..runs.len()).map(|idx| balance.named.iter().any(|p| p.fit.touched.get(idx) == Some(&true))).collect();
        let beyond = |residuals: &[Vec<f64>]| -> f64 {
            let segments = attribution::segments(runs, residuals);
            let (mut sum, mut n) = (0.0, 0usize);
            for ((segment, run), _) in segments.iter().zip(runs).zip(&touched).filter(|(_, touched)| **touched) {
                let gap = regression::selection_gap(std::slice::from_ref(segment), &[Vec::new()], &[], &[true]);
                if gap.n == 0 || !gap.mse_before.is_finite() {
                    continue;
                }
                let own = OWN_GAP_UNCERTAINTY * floor.gap_of(run.kind.as_str(), run.alpha_deg).max(0.0);
                sum += (streams.to_noise(gap.mse_before) - 1.0 - own) * gap.n as f64;
                n += gap.n;
            }
            if n == 0 { 0.0 } else { (sum / n as f64).max(0.0) }
        };
        if balance.named.is_empty() {
            return Self::default();
        }
        Self { before: beyond(&streams.residuals), after: beyond(&balance.remainder) }
    }
}

/// Least share of its channels' gap beyond the noise that a sensor effect must remove to be
/// named: at least half as much as everything else there together (the pressure model's own
/// error on those channels), so one third. The diagnosis names the effect that causes the gap;
/// on a rig the pressure model was not built on, that model's error is most of a channel's gap,
/// and a lag or fault fitted to it removes a sliver (a tenth to a sixth on clean recordings of
/// the second tunnel, where injected lags and faults removed from 0.45 to all of it).
pub(super) const MIN_SENSOR_GAP_SHARE: f64 = 1.0 / 3.0;

/// Stage 4: the sensor candidates on the pressure channels, and the one named if it qualifies.
pub struct SensorAttribution {
    /// Every finding, strongest first.
    pub findings: Vec<SensorFinding>,
    /// A lag of each channel alone, at its best time constant: not named, the floors of a lag
    /// of any set of channels in the sim's signature.
    pub channel_lags: Vec<SensorFinding>,
    /// The qualifying finding with the most excess, if any.
    pub named: Option<SensorFinding>,
}

/// What a sensor finding removes on the selection part over its noise variance (infinite for a
/// dead channel, whose whole signal is the gap).
pub(super) fn sensor_selected_to_noise(finding: &SensorFinding) -> f64 {
    if finding.explained.is_infinite() {
        return f64::INFINITY;
    }
    finding.selection.removed() / finding.noise_var.max(f64::MIN_POSITIVE)
}

impl SensorAttribution {
    pub(super) fn run(streams: &Streams, floor: &Signature) -> Self {
        let sensor::Findings { ranked: findings, channel_lags } = sensor::scan(
            &streams.runs,
            pressure_lag::Reference {
                tau_s: floor.pressure_alignment_s.unwrap_or(0.0),
                scatter_s: floor.pressure_alignment_scatter_s.unwrap_or(0.0),
                by_kind: floor.pressure_alignment_by_kind.as_ref(),
            },
            floor.pressure_channel_lags.as_ref(),
        );
        let qualifying: Vec<&SensorFinding> = findings
            .iter()
            .filter(|f| Self::qualifies(f, floor))
            .filter(|f| Self::stands_out(f, &findings, floor))
            .collect();
        // A whole set that qualifies names its channels: a group the innovations found within it
        // is part of the same lag (what the filter without the group sees of a large set).
        let confirmed_set = qualifying.iter().find(|f| finding::is_set_lag(f)).map(|f| f.channels.clone());
        let named = qualifying
            .into_iter()
            .filter(|f| {
                confirmed_set.as_ref().is_none_or(|set| {
                    finding::is_set_lag(f)
                        || f.effect != firmware_sim::effect::Effect::PressureLag
                        || !f.channels.iter().all(|channel| set.contains(channel))
                })
            })
            .max_by(|a, b| Self::excess_of(a, floor).total_cmp(&Self::excess_of(b, floor)))
            .cloned();
        Self { findings, channel_lags, named }
    }

    /// Whether a finding clears its floor: it removes at least the least effect to name beyond
    /// the floor, and at least the floor again, with the evidence of [`MIN_DELTA_BIC`]. The
    /// floor is measured once, on one recording, and the pressure model's error on a channel
    /// changes with the excitation from recording to recording, so the floor is taken as known
    /// within a factor of two, as the gap per run takes its own ([`PooledGap::beyond`]).
    ///
    /// And a finding on the innovations alone must be a cause of its channels' gap, not a
    /// sliver of it: on the selection part it removes at least [`MIN_SENSOR_GAP_SHARE`] of the
    /// mean square its channels hold beyond the noise ([`Self::gap_share`]). A lag of a whole
    /// set ([`finding::is_set_lag`]) is measured beyond the sim's own lags: each channel's
    /// beyond what the sim shows on the data it was fitted on (the signature's
    /// `pressure_channel_lags`), the shared part beyond its own alignment. So the lag-like part
    /// of the pressure model's own error is already taken out of it, and the rest of that error
    /// (most of a channel's gap on a rig the model fits poorly) is no measure of it.
    pub(super) fn qualifies(finding: &SensorFinding, floor: &Signature) -> bool {
        let min_ratio = MIN_EFFECT_TO_NOISE * MIN_EFFECT_TO_NOISE;
        Self::excess_of(finding, floor) >= min_ratio.max(Self::floor_of(finding, floor))
            && finding.delta_bic >= MIN_DELTA_BIC
            && (finding::is_set_lag(finding) || Self::gap_share(finding) >= MIN_SENSOR_GAP_SHARE)
    }

    /// The share of its channels' mean square beyond the noise on the selection part that a
    /// finding removes (1 for a dead channel, whose whole signal is the gap; 0 without a gap).
    pub(super) fn gap_share(finding: &SensorFinding) -> f64 {
        if finding.explained.is_infinite() {
            return 1.0;
        }
        let gap = finding.selection.mse_before - finding.selection.noise_var;
        if gap > 0.0 { finding.selection.removed() / gap } else { 0.0 }
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
    pub(super) fn stands_out(finding: &SensorFinding, findings: &[SensorFinding], floor: &Signature) -> bool {
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

    pub(super) fn excess_of(finding: &SensorFinding, floor: &Signature) -> f64 {
        sensor_selected_to_noise(finding) - Self::floor_of(finding, floor)
    }

    /// The floor of a finding: what the same finding removed on the sim's own data. A lag of
    /// some channels is a choice among 4095 sets, and the signature holds the one its own data
    /// chose; what a lag of each channel alone removed there ([`sensor::Findings::channel_lags`]) is the
    /// floor of any set, as the mean over its channels (a set's strength is its mean per
    /// sample over its channels).
    pub(super) fn floor_of(finding: &SensorFinding, floor: &Signature) -> f64 {
        let own = floor.of(&finding.floor_key());
        let is_some_channels_lag = finding.effect == firmware_sim::effect::Effect::PressureLag
            && !finding.params.iter().any(|(key, value)| key == "channels" && *value == ParamValue::Text("all".into()));
        if !is_some_channels_lag || finding.channels.is_empty() {
            return own;
        }
        let per_channel =
            finding.channels.iter().map(|channel| floor.of(&sensor::channel_lag_key(channel))).sum::<f64>()
                / finding.channels.len() as f64;
        own.max(per_channel)
    }

    pub(super) fn strength(&self, floor: &Signature) -> f64 {
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
    pub(super) fn run(streams: &Streams, floor: &Signature) -> Self {
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
            for key in [run.kind.as_str().to_owned(), run.kind_alpha_key()] {
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
pub(super) struct PooledGap {
    /// Sum of samples times the gap, in noise variances.
    pub(super) gap: f64,
    /// Sum of samples times the sim's own gap.
    pub(super) floor: f64,
    /// Sum of the squares of samples times the scatter of the excess.
    pub(super) scatter_sq: f64,
    /// Samples.
    pub(super) n: f64,
}

impl PooledGap {
    pub(super) fn add(&mut self, gap_to_noise: f64, floor_to_noise: f64, scatter: f64, n: usize) {
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
    /// floor taken as known within [`OWN_GAP_UNCERTAINTY`]), and significant by
    /// [`GAP_SIGNIFICANCE_Z`] standard errors. A gap this far beyond the sim is not its
    /// scatter from recording to recording. The decision is read where nothing predicts the gap
    /// (a random modulation, such as a fluctuating dynamic pressure, predicts nothing out of
    /// sample), so its size is its only evidence: it must also not lie significantly below the
    /// contract's level for a gap that may be missed ([`MIN_UNPREDICTED_GAP_TO_NOISE`]). Both
    /// bounds on the scatter together ask for at least half that level, above the naming
    /// threshold ([`MIN_EFFECT_TO_NOISE`]).
    pub(super) fn beyond_scatter(&self) -> bool {
        if self.n <= 0.0 {
            return false;
        }
        let excess = (self.gap - self.floor) / self.n;
        let floor = self.floor / self.n;
        let scatter = self.scatter_sq.sqrt() / self.n;
        excess >= (OWN_GAP_UNCERTAINTY - 1.0) * floor
            && excess >= GAP_SIGNIFICANCE_Z * scatter
            && excess + GAP_SIGNIFICANCE_Z * scatter >= MIN_UNPREDICTED_GAP_TO_NOISE * MIN_UNPREDICTED_GAP_TO_NOISE
    }
}

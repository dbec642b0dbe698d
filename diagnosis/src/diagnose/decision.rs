//! The verdict and the named effects: which candidates clear their floors ([`Decision`]), and
//! each named effect as the contract reports it, with its confounders.

use super::*;

/// Stage 6: the verdict.
pub(super) enum Decision {
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
    /// A sensor effect stronger than any balance effect wins; named balance effects win when one
    /// of them is an effect of the vocabulary (not recalibration alone), unless the probe still
    /// finds structure after them or they leave a gap the contract does not let pass
    /// ([`ProbeResult::gap_left`]); a gap beyond the sim's own, or structure in
    /// the remainder, is unattributed only when something predicts part of it out of sample
    /// (a bigger but unpredictable gap is the sim's own scatter from recording to recording,
    /// not an effect).
    pub(super) fn make(
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
            // Recalibration names no effect: a gap a gain of the sim's blocks spans, with nothing
            // of the vocabulary beside it, is real and unattributed (the contract's balance
            // saturation or a stiffening mount look like a gain on most motions).
            let names_an_effect = balance.named.iter().any(|p| p.candidate.effect().is_some());
            return if !names_an_effect || probe.remainder_structured || probe.gap_left() {
                Self::Unattributed
            } else {
                Self::Balance
            };
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

    pub(super) fn verdict(&self) -> Verdict {
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
pub(super) fn profile_all(
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

pub(super) fn alphas(runs: &[streams::RunStreams], touched: &[bool]) -> Vec<f64> {
    let mut out: Vec<f64> = runs.iter().zip(touched).filter(|(_, t)| **t).map(|(run, _)| run.alpha_deg).collect();
    out.sort_by(f64::total_cmp);
    out.dedup();
    out
}

pub(super) fn balance_effect(
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

/// The result of a named sensor finding. `excess_to_noise` is what the decision named it on:
/// what it removes on the selection part beyond its floor, in noise variances
/// ([`super::stages::SensorAttribution::excess_of`]); its square root is the effect-to-noise
/// ratio reported, so that the number a reader sees is the one the threshold was applied to.
pub(super) fn sensor_effect(finding: &SensorFinding, excess_to_noise: f64) -> EffectResult {
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
    // A dead channel carries no reading: its shrink of 1 holds by definition. Any other finding
    // without held-out samples has no measured shrink either, and none is claimed.
    let dead = finding.explained.is_infinite();
    let measured = !dead && finding.heldout.n > 0;
    let by_definition = if dead { 1.0 } else { 0.0 };
    EffectResult {
        name: finding.effect.name().into(),
        block: "sensor".into(),
        params,
        heldout_rms_before: finding.heldout.gap_before(),
        heldout_rms_after: finding.heldout.gap_after(),
        shrink: if measured { finding.heldout.shrink() } else { by_definition },
        shrink_total: if measured { finding.heldout.shrink() } else { by_definition },
        shrink_measured: measured,
        delta_bic: finite_or_null(finding.delta_bic),
        effect_to_noise: finite_or_null(excess_to_noise.max(0.0).sqrt()),
        evidence: finding.evidence.clone(),
    }
}

pub(super) fn describe_structure(
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

/// When recalibration alone spans the gap: its gains in words, for the structure of an
/// unattributed gap (empty otherwise). A gain of the sim's blocks is no effect of the
/// vocabulary: the sim's coefficients are off, or the balance reads the moment through a
/// calibration, a saturation or a stiffening mount that a gain matches on most motions.
pub(super) fn gain_note(balance: &BalanceAttribution, runs: &[streams::RunStreams], context: &Context<'_>) -> String {
    let Some(top) = balance.named.first().filter(|_| balance.named.iter().all(|p| p.candidate.effect().is_none()))
    else {
        return String::new();
    };
    let columns = attribution::all_columns(top.candidate, &top.form, runs, context);
    let gains: Vec<String> = candidates::physical_params(top.candidate, &top.form, &top.fit.beta, context, &columns)
        .iter()
        .filter_map(|(name, value)| value.as_f64().map(|gain| format!("{name} = {gain:.3}")))
        .collect();
    format!(
        "a gain of the sim's blocks spans it ({}): the sim's coefficients are off, or the balance reads the moment through a wrong calibration, a saturation or a stiffening mount, none of them an effect of the vocabulary; ",
        gains.join(", ")
    )
}

/// Pairs among the leading candidates whose column spans are nearly the same (largest
/// canonical correlation above [`CONFOUNDED_CORRELATION`]) and whose evidence is close: they
/// cannot be told apart with this data (docs/diagnosis.md, Confounded candidates).
pub(super) fn confounding(
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

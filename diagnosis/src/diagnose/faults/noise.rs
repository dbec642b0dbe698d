//! Extra noise on a channel: a variance ratio test with one added variance, from an onset per
//! run ([`fit_noise`]).

use super::*;

/// The effective share of first differences in a variance estimate: squared differences of
/// white Gaussian noise correlate by 1/4 with their neighbours (sharing a sample), so their
/// mean carries the information of `n / 1.5` independent squares.
const DIFFERENCE_TAU: f64 = 1.5;

/// Extra noise fitted on the training part: the channel's noise variance rises from an onset
/// per run to the run's end, by one added variance for every run (docs/spec/diagnosis.md: a
/// channel "with extra noise ... from the start of a run or from any moment in it").
#[derive(Debug, Clone, PartialEq)]
pub struct Noise {
    /// The channel's own noise variance, Cp^2: the median over the runs of the variance before
    /// the onset (the whole run without one).
    pub base_var: f64,
    /// The added noise variance, shared by every run, Cp^2 (`noise_rms` is its root).
    pub added_var: f64,
    /// Per run, the onset time found on the training part, s.
    pub onset_s: Vec<Option<f64>>,
    /// Evidence: the variance-change tests' BIC over the runs with the fault.
    pub delta_bic: f64,
}

/// Per run, the squared first differences of the innovation over consecutive usable samples of
/// `candidates`, with the time of the later sample. Differencing removes the slow part of the
/// innovation (the model's error follows the flow, a few hertz), leaving twice the noise
/// variance.
fn squared_differences(run: &RunStreams, tap: usize, candidates: impl Iterator<Item = usize>) -> Vec<(f64, f64)> {
    let nu = &run.innovation[tap];
    let mut out = Vec::new();
    let mut last: Option<usize> = None;
    for i in candidates {
        if !nu[i].is_finite() {
            last = None;
            continue;
        }
        if let Some(j) = last
            && j + 1 == i
        {
            out.push((run.t_s[i], (nu[i] - nu[j]).powi(2)));
        }
        last = Some(i);
    }
    out
}

/// A variance step in squared differences `d`: the best split with a larger variance after it,
/// `(position, evidence)` with the split's choice and the new variance paid for, if decisive.
fn variance_step(d: &[(f64, f64)]) -> Option<(usize, f64)> {
    let m = d.len();
    if m < 4 * MIN_FAULTY_SAMPLES {
        return None;
    }
    let mut prefix = vec![0.0; m + 1];
    for (p, (_, v)) in d.iter().enumerate() {
        prefix[p + 1] = prefix[p] + v;
    }
    let n_eff = |n: usize| n as f64 / DIFFERENCE_TAU;
    let total = prefix[m] / m as f64;
    if total <= 0.0 {
        return None;
    }
    let (p, lr) = (MIN_FAULTY_SAMPLES..=m - MIN_FAULTY_SAMPLES)
        .filter_map(|p| {
            let before = prefix[p] / p as f64;
            let after = (prefix[m] - prefix[p]) / (m - p) as f64;
            (after > before && before > 0.0)
                .then(|| (p, n_eff(m) * total.ln() - n_eff(p) * before.ln() - n_eff(m - p) * after.ln()))
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    let evidence = lr - n_eff(m).ln() - (m as f64).ln();
    (evidence >= MIN_RUN_DELTA_BIC).then_some((p, evidence))
}

/// The evidence that squared differences `d` have variance `var` rather than `base` (both
/// known): `n_eff (ratio - 1 - ln ratio)`.
fn known_variance_evidence(d: &[(f64, f64)], base: f64) -> f64 {
    let mean = d.iter().map(|(_, v)| v).sum::<f64>() / d.len().max(1) as f64;
    let ratio = mean / base;
    d.len() as f64 / DIFFERENCE_TAU * (ratio - 1.0 - ratio.ln())
}

/// Mean of the squared differences at or after `t0` (`None` without any).
fn mean_after(d: &[(f64, f64)], t0: f64) -> Option<(f64, usize)> {
    let after: Vec<f64> = d.iter().filter(|(t, _)| *t >= t0).map(|(_, v)| *v).collect();
    (!after.is_empty()).then(|| (after.iter().sum::<f64>() / after.len() as f64, after.len()))
}

/// Fits extra noise of channel `tap` on the training part: a variance ratio test, not a
/// regression (added noise has no shape to fit).
///
/// In each run the squared first differences of the innovation are scanned for a rise of
/// their variance at one moment (decisive by BIC, the moment's choice paid for). The channel's
/// own variance is the median over the runs of the variance before the onset; a run without a
/// rise inside it has the fault from its start when its whole variance exceeds that
/// decisively. The added variance is one value for every run (pooled over the faulty samples);
/// as for the shared forms (`AGREEMENT_FACTOR`) every faulty run's own added variance must
/// agree with it. A channel noisier from the start of every run has no clean run of its own
/// to compare with: it is judged against the other channels (`noisier_than_the_others`).
/// `n_taps` is the number of channels.
#[must_use]
pub fn fit_noise(runs: &[RunStreams], tap: usize, n_taps: usize) -> Option<Noise> {
    let diffs: Vec<Vec<(f64, f64)>> = runs.iter().map(|run| squared_differences(run, tap, run.fit_samples())).collect();
    let steps: Vec<Option<(usize, f64)>> = diffs.iter().map(|d| variance_step(d)).collect();
    let mut before: Vec<f64> = diffs
        .iter()
        .zip(&steps)
        .filter_map(|(d, step)| {
            let part = &d[..step.map_or(d.len(), |(p, _)| p)];
            (!part.is_empty()).then(|| part.iter().map(|(_, v)| v).sum::<f64>() / part.len() as f64)
        })
        .collect();
    before.sort_by(f64::total_cmp);
    let base = *before.get(before.len() / 2)?;
    if base <= 0.0 {
        return None;
    }
    let (mut onset_s, mut delta_bic): (Vec<Option<f64>>, f64) = (Vec::with_capacity(runs.len()), 0.0);
    for (d, step) in diffs.iter().zip(&steps) {
        match step {
            Some((p, evidence)) => {
                onset_s.push(Some(d[*p].0));
                delta_bic += evidence;
            }
            None => {
                let mean = d.iter().map(|(_, v)| v).sum::<f64>() / d.len().max(1) as f64;
                let evidence = known_variance_evidence(d, base) - (d.len() as f64 / DIFFERENCE_TAU).max(1.0).ln();
                if mean > base && evidence >= MIN_RUN_DELTA_BIC {
                    onset_s.push(d.first().map(|(t, _)| *t));
                    delta_bic += evidence;
                } else {
                    onset_s.push(None);
                }
            }
        }
    }
    let mut base = base;
    if onset_s.iter().all(Option::is_none)
        && let Some((reference, evidence)) = noisier_than_the_others(runs, tap, n_taps, &diffs, base)
    {
        // Noisier from the start of every run: the others' typical variance is the channel's
        // own.
        base = reference;
        delta_bic = evidence;
        onset_s = diffs.iter().map(|d| d.first().map(|(t, _)| *t)).collect();
    }
    let added: Vec<(f64, usize)> = diffs
        .iter()
        .zip(&onset_s)
        .filter_map(|(d, onset)| mean_after(d, (*onset)?).map(|(mean, n)| (mean - base, n)))
        .collect();
    let count: usize = added.iter().map(|(_, n)| n).sum();
    if count == 0 {
        return None;
    }
    let pooled = added.iter().map(|(a, n)| a * *n as f64).sum::<f64>() / count as f64;
    let agrees = |a: f64| (1.0 / AGREEMENT_FACTOR..=AGREEMENT_FACTOR).contains(&(a / pooled));
    if pooled <= 0.0 || added.iter().any(|(a, _)| !agrees(*a)) {
        return None;
    }
    // Differences carry twice the noise variance.
    Some(Noise { base_var: base / 2.0, added_var: pooled / 2.0, onset_s, delta_bic })
}

/// A channel noisier than the other channels of the scanner from the start of every run: its
/// variance (`own`, of squared differences `diffs` per run) against the median of the others'
/// (each the median over the runs), `(reference, evidence)` if it exceeds
/// `AGREEMENT_FACTOR` times the reference decisively. Channels of one scanner agree on their
/// noise within that factor (transducers of one kind); a channel beyond it has noise added.
/// The evidence is against the most a healthy channel may have, the factor times the
/// reference, less the cost of the added variance.
fn noisier_than_the_others(
    runs: &[RunStreams],
    tap: usize,
    n_taps: usize,
    diffs: &[Vec<(f64, f64)>],
    own: f64,
) -> Option<(f64, f64)> {
    let mut others: Vec<f64> = (0..n_taps)
        .filter(|&other| other != tap)
        .filter_map(|other| {
            let mut per_run: Vec<f64> = runs
                .iter()
                .map(|run| squared_differences(run, other, run.fit_samples()))
                .filter(|d| !d.is_empty())
                .map(|d| d.iter().map(|(_, v)| v).sum::<f64>() / d.len() as f64)
                .collect();
            per_run.sort_by(f64::total_cmp);
            per_run.get(per_run.len() / 2).copied()
        })
        .collect();
    others.sort_by(f64::total_cmp);
    let reference = *others.get(others.len() / 2)?;
    if reference <= 0.0 || own <= AGREEMENT_FACTOR * reference {
        return None;
    }
    let n: usize = diffs.iter().map(Vec::len).sum();
    let evidence = diffs.iter().map(|d| known_variance_evidence(d, AGREEMENT_FACTOR * reference)).sum::<f64>()
        - (n as f64 / DIFFERENCE_TAU).max(1.0).ln();
    (evidence >= MIN_RUN_DELTA_BIC).then_some((reference, evidence))
}

/// The extra-noise fault's gap over a part of every run, with nothing fitted on the part: the
/// added variance and the channel's own are the training ones; a run keeps its training onset,
/// and in a run without one the same variance-step detector looks for one in the part. On the
/// faulty samples the part's measured added variance `v` (its squared differences over two,
/// less the channel's own variance) is what the plain sim leaves unexplained (`before`), and
/// `|v - added|` what the sim with the training's added noise leaves (`after`): a part whose
/// noise did not rise makes the finding worse by the added variance.
#[must_use]
pub fn noise_part_gap(runs: &[RunStreams], tap: usize, noise: &Noise, heldout: bool) -> regression::HeldoutGap {
    let (mut n_all, mut before, mut after) = (0usize, 0.0, 0.0);
    for (run_idx, run) in runs.iter().enumerate() {
        let samples: Vec<usize> = if heldout { run.heldout.clone().collect() } else { run.select.samples().collect() };
        let d = squared_differences(run, tap, samples.into_iter());
        n_all += d.len();
        let onset = noise.onset_s.get(run_idx).copied().flatten().or_else(|| variance_step(&d).map(|(p, _)| d[p].0));
        if let Some((mean, n)) = onset.and_then(|t0| mean_after(&d, t0)) {
            let measured = mean / 2.0 - noise.base_var;
            before += n as f64 * measured;
            after += n as f64 * (measured - noise.added_var).abs();
        }
    }
    if n_all == 0 {
        return regression::HeldoutGap::EMPTY;
    }
    let share = |sum: f64| sum / n_all as f64;
    regression::HeldoutGap {
        mse_before: noise.base_var + share(before),
        mse_after: noise.base_var + share(after),
        noise_var: noise.base_var,
        n: n_all,
        floor_var: 0.0,
    }
}

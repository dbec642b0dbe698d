//! The `pressure_lag` family: a first-order lag of the pressure channels (tubing, transducer),
//! on every channel, on a group of them or on one, each with its own or a shared time constant
//! (docs/diagnosis.md, Pressure lag; docs/spec/diagnosis.md).
//!
//! Why the balance is the reference: a lagged channel reads `y` with `tau y' + y = p`, the
//! true pressure `p`; the pressure filter's one-step innovations hide such a lag, because the
//! filter follows the lagged readings (on the default campaign with every channel lagged by
//! 50 ms the innovations held 0.015 noise variances of it). The roll moment the balance reads
//! is the integral of the surface pressures at the same instant, so the taps map to the
//! balance moment without delay: a lag shows as the time constant that best re-aligns them.
//! The inverse of the lag is exact, `p = y + tau y'`, so for every choice of time constants
//! the balance is regressed on the de-lagged taps, and the residual sum of squares is profiled
//! over them.
//!
//! The derivative of every channel is taken once (zero-phase smoothed, [`RunStreams::cp_dot`]);
//! the de-lagged taps are then linear in the time constants, so the Gram matrix of taps,
//! derivatives and nuisance columns, accumulated once per angle of attack, gives the residual
//! sum of squares for any vector of time constants in microseconds. That makes the per-channel
//! search (coordinate descent over twelve time constants) and the comparison of hypotheses
//! (all channels with one time constant, some channels, one channel) cheap.

use std::borrow::Borrow;
use std::collections::BTreeMap;

use nalgebra::{DMatrix, DVector};

use super::finding::{ParamValue, SensorFinding, channel_name};
use super::regression::{self, Interleave, Segment};
use super::streams::RunStreams;

/// Shortest and longest time constant searched for a lag beyond the sim's own alignment, s:
/// from a lead well below any alignment the sim can have to beyond the contract's longest lag
/// (half a second, docs/spec/diagnosis.md, What each name covers). A best fit at either end
/// is no lag: the profile then has no minimum inside, and the end only says where the search
/// stopped.
pub const TAU_RANGE_S: (f64, f64) = (-0.2, 0.6);

/// Range of the sim's own alignment on the data it was fitted on (its signature), s: symmetric
/// about zero, so that a clean recording's optimum (a few milliseconds either side: the rig's
/// tubing and the sim's map) is inside it. With the range starting at -20 ms, a clean optimum
/// below it was clamped to the end, and every clean recording then showed a "lag" of the
/// distance between its own optimum and the end.
pub const REFERENCE_RANGE_S: (f64, f64) = (-0.2, 0.2);

/// Standard errors a common lag must lie beyond the sim's own alignment: the alignment of the
/// sim's data and that of the recording each scatter with the excitation (the pressure model's
/// error moves the best time constant by several milliseconds from recording to recording on a
/// rig the model was not built on), and a lag counts only beyond that scatter.
const LAG_SIGNIFICANCE_Z: f64 = 3.0;

/// The sim's own alignment of the taps with the balance on the data it was fitted on (its
/// signature), and the standard error of that estimate ([`run_scatter_s`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Reference<'a> {
    /// The alignment, s.
    pub tau_s: f64,
    /// Its standard error, s (0 when unknown).
    pub scatter_s: f64,
    /// The alignment per kind of run and angle of attack ([`by_kind`]), when the signature
    /// holds it: a lag is then judged on the paired shifts ([`paired_shift`]).
    pub by_kind: Option<&'a BTreeMap<String, KindAlignment>>,
}

impl From<f64> for Reference<'static> {
    fn from(tau_s: f64) -> Self {
        Self { tau_s, scatter_s: 0.0, by_kind: None }
    }
}

/// The alignment of the runs of one kind at one angle of attack, and its standard error.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct KindAlignment {
    /// The time constant that best aligns the taps with the balance on those runs, s.
    pub tau_s: f64,
    /// Its standard error, s, from the curvature of the residual sum of squares
    /// ([`Alignment::standard_error_s`]).
    pub standard_error_s: f64,
}

/// Per kind of run and angle of attack (`roll@20`, [`RunStreams::kind_alpha_key`]), the
/// alignment of its runs within [`TAU_RANGE_S`] and its standard error; a kind whose alignment
/// is at a range end, or whose residual has no minimum there, is left out.
#[must_use]
pub fn by_kind(runs: &[RunStreams]) -> BTreeMap<String, KindAlignment> {
    let mut groups: BTreeMap<String, Vec<&RunStreams>> = BTreeMap::new();
    for run in runs {
        groups.entry(run.kind_alpha_key()).or_default().push(run);
    }
    groups
        .into_iter()
        .filter_map(|(key, group)| {
            let alignment = Alignment::new(&group, |run| run.fit_samples().collect())?;
            let tau_s = alignment.shared_in(TAU_RANGE_S)?;
            let standard_error_s = alignment.standard_error_s(&group, tau_s)?;
            Some((key, KindAlignment { tau_s, standard_error_s }))
        })
        .collect()
}

/// Fewest kinds of run a paired shift is judged on (a standard error and the spread of the
/// pairs about their mean need three).
const MIN_PAIRS: usize = 3;

/// The shift of the recording's alignment from the sim's own, paired by kind of run and angle
/// of attack, and its standard error, s: the inverse-variance weighted mean of the differences
/// of the pairs, its standard error inflated by the Birge ratio where the pairs scatter beyond
/// their own errors (Birge, Phys. Rev. 40, 1932, 207; Particle Data Group, Review of Particle
/// Physics, Introduction, "unconstrained averaging"). `None` with fewer than [`MIN_PAIRS`].
///
/// Why paired: on a rig the sim's pressure map fits poorly, the alignment of each kind of run
/// at each angle carries that map's own error (on the second tunnel's development rig, from -96
/// to +31 ms across the rolling runs of the sim's own data), so the pooled alignment's scatter
/// over the runs, 30 ms and more, hid lags of a hundred milliseconds. The map's error is the
/// same for a kind of run at an angle on every recording of the rig, and the difference of the
/// pair removes it.
#[must_use]
pub fn paired_shift(runs: &[RunStreams], own: &BTreeMap<String, KindAlignment>) -> Option<(f64, f64)> {
    let pairs: Vec<(f64, f64)> = by_kind(runs)
        .into_iter()
        .filter_map(|(key, recorded)| {
            let sim = own.get(&key)?;
            let variance = recorded.standard_error_s.powi(2) + sim.standard_error_s.powi(2);
            (variance > 0.0 && variance.is_finite()).then_some((recorded.tau_s - sim.tau_s, variance))
        })
        .collect();
    if pairs.len() < MIN_PAIRS {
        return None;
    }
    let weight_sum: f64 = pairs.iter().map(|(_, variance)| 1.0 / variance).sum();
    let mean = pairs.iter().map(|(shift, variance)| shift / variance).sum::<f64>() / weight_sum;
    let chi2: f64 = pairs.iter().map(|(shift, variance)| (shift - mean).powi(2) / variance).sum();
    let birge = (chi2 / (pairs.len() - 1) as f64).sqrt().max(1.0);
    Some((mean, birge / weight_sum.sqrt()))
}

/// The standard error of the alignment of every channel, s: the jackknife over the runs, each
/// run left out in turn and the others aligned together within `range` (Efron & Tibshirani,
/// An Introduction to the Bootstrap, 1993, ch. 11: `sqrt((n - 1) / n sum (a_i - a_mean)^2)`).
/// `None` with fewer than three runs, or when a channel takes part in some runs only. The runs
/// differ in their excitation as recordings do, so the spread of the pooled alignment without
/// each is the scatter that the excitation gives it through the pressure model's error; a
/// run that cannot fix the alignment on its own (one held at a still roll angle) moves the
/// pooled estimate little and counts little, where the spread of the runs' own alignments
/// counted it fully.
#[must_use]
pub fn run_scatter_s(runs: &[RunStreams], range: (f64, f64)) -> Option<f64> {
    use rayon::prelude::*;
    let per_run: Vec<Alignment> = runs
        .par_iter()
        .filter_map(|run| Alignment::new(std::slice::from_ref(run), |r| r.fit_samples().collect()))
        .collect();
    if per_run.len() < 3 || per_run.iter().any(|part| part.taps != per_run[0].taps) {
        return None;
    }
    let left_out: Vec<f64> = (0..per_run.len())
        .into_par_iter()
        .filter_map(|out| {
            let others: Vec<&Alignment> =
                per_run.iter().enumerate().filter(|(idx, _)| *idx != out).map(|(_, part)| part).collect();
            Alignment::merged(&others).shared_in(range)
        })
        .collect();
    if left_out.len() < 3 {
        return None;
    }
    let n = left_out.len() as f64;
    let mean = left_out.iter().sum::<f64>() / n;
    Some(((n - 1.0) / n * left_out.iter().map(|v| (v - mean).powi(2)).sum::<f64>()).sqrt())
}

/// A channel with fewer finite samples than this share of its training part takes no part in
/// the alignment (a dead channel is the fault candidate's).
const MIN_FINITE_SHARE: f64 = 0.5;

/// Per angle of attack: the Gram matrix of `[cp_1..cp_T, cp_dot_1..cp_dot_T, nuisance]` and
/// its products with the balance moment, over the samples of one part of every run, centred
/// per run.
#[derive(Debug, Clone)]
pub struct Alignment {
    taps: Vec<usize>,
    groups: Vec<Group>,
}

#[derive(Debug, Clone)]
struct Group {
    alpha_key: i64,
    gram: DMatrix<f64>,
    cross: DVector<f64>,
    yy: f64,
    n: usize,
}

/// The nuisance columns besides the taps: the sim's plant moment (the jets move the balance
/// and the taps in their own way).
const N_NUISANCE: usize = 1;

impl Alignment {
    /// Accumulates the Gram matrices over the samples `part(run)` of every run, per angle of
    /// attack; `None` without two usable channels or samples. The runs are owned or borrowed
    /// (a group of a recording's runs, [`by_kind`]).
    #[must_use]
    pub fn new<R: Borrow<RunStreams>>(runs: &[R], part: impl Fn(&RunStreams) -> Vec<usize>) -> Option<Self> {
        let runs = || runs.iter().map(Borrow::borrow);
        let n_taps = runs().next()?.cp.len();
        let taps: Vec<usize> = (0..n_taps)
            .filter(|&tap| {
                let (mut finite, mut total) = (0usize, 0usize);
                for run in runs() {
                    for idx in part(run) {
                        total += 1;
                        finite += usize::from(run.cp[tap][idx].is_finite());
                    }
                }
                total > 0 && finite as f64 >= MIN_FINITE_SHARE * total as f64
            })
            .collect();
        if taps.len() < 2 {
            return None;
        }
        let width = 2 * taps.len() + N_NUISANCE;
        let mut by_alpha: BTreeMap<i64, Group> = BTreeMap::new();
        for run in runs() {
            let afc = run.cl_afc();
            let rows: Vec<usize> = part(run)
                .into_iter()
                .filter(|&idx| {
                    run.cl_measured[idx].is_finite()
                        && taps.iter().all(|&tap| run.cp[tap][idx].is_finite() && run.cp_dot[tap][idx].is_finite())
                })
                .collect();
            if rows.len() < 2 {
                continue;
            }
            let column = |col: usize, idx: usize| -> f64 {
                if col < taps.len() {
                    run.cp[taps[col]][idx]
                } else if col < 2 * taps.len() {
                    run.cp_dot[taps[col - taps.len()]][idx]
                } else {
                    afc[idx]
                }
            };
            let count = rows.len() as f64;
            let means: Vec<f64> =
                (0..width).map(|col| rows.iter().map(|&i| column(col, i)).sum::<f64>() / count).collect();
            let y_mean = rows.iter().map(|&i| run.cl_measured[i]).sum::<f64>() / count;
            let alpha_key = alpha_key(run.alpha_deg);
            let group = by_alpha.entry(alpha_key).or_insert_with(|| Group {
                alpha_key,
                gram: DMatrix::zeros(width, width),
                cross: DVector::zeros(width),
                yy: 0.0,
                n: 0,
            });
            let mut row = vec![0.0; width];
            for &idx in &rows {
                for (col, slot) in row.iter_mut().enumerate() {
                    *slot = column(col, idx) - means[col];
                }
                let y = run.cl_measured[idx] - y_mean;
                for a in 0..width {
                    group.cross[a] += row[a] * y;
                    for b in a..width {
                        group.gram[(a, b)] += row[a] * row[b];
                    }
                }
                group.yy += y * y;
            }
            group.n += rows.len();
        }
        let mut groups: Vec<Group> = by_alpha.into_values().collect();
        for group in &mut groups {
            for a in 0..width {
                for b in 0..a {
                    group.gram[(a, b)] = group.gram[(b, a)];
                }
            }
        }
        (!groups.is_empty()).then_some(Self { taps, groups })
    }

    /// The alignment of the samples of several alignments with the same channels: their sums
    /// per angle of attack added (each run is centred on its own, so the sums add exactly).
    fn merged(parts: &[&Self]) -> Self {
        let mut by_alpha: BTreeMap<i64, Group> = BTreeMap::new();
        for group in parts.iter().flat_map(|part| &part.groups) {
            match by_alpha.get_mut(&group.alpha_key) {
                Some(sum) => {
                    sum.gram += &group.gram;
                    sum.cross += &group.cross;
                    sum.yy += group.yy;
                    sum.n += group.n;
                }
                None => {
                    by_alpha.insert(group.alpha_key, group.clone());
                }
            }
        }
        Self {
            taps: parts.first().map(|part| part.taps.clone()).unwrap_or_default(),
            groups: by_alpha.into_values().collect(),
        }
    }

    /// The channels that take part (0-based taps).
    #[must_use]
    pub fn taps(&self) -> &[usize] {
        &self.taps
    }

    /// Samples.
    #[must_use]
    pub fn n(&self) -> usize {
        self.groups.iter().map(|g| g.n).sum()
    }

    /// Residual sum of squares of the balance on the de-lagged taps `cp + tau cp_dot` (one time
    /// constant per channel of [`Self::taps`]) and the nuisance columns, each angle of attack
    /// with its own weights.
    #[must_use]
    pub fn ssr(&self, tau_s: &[f64]) -> f64 {
        self.groups.iter().map(|group| self.solve(group, tau_s).1).sum()
    }

    /// Weights of `[cp + tau cp_dot, nuisance]` and the residual sum of squares of one group.
    fn solve(&self, group: &Group, tau_s: &[f64]) -> (DVector<f64>, f64) {
        let n_taps = self.taps.len();
        let width = n_taps + N_NUISANCE;
        // X = Z M^T with M mapping [cp, cp_dot, nuisance] to [cp + tau cp_dot, nuisance].
        let m = DMatrix::from_fn(width, 2 * n_taps + N_NUISANCE, |row, col| {
            if row < n_taps {
                if col == row {
                    1.0
                } else if col == row + n_taps {
                    tau_s[row]
                } else {
                    0.0
                }
            } else {
                f64::from(u8::from(col == row + n_taps))
            }
        });
        let xtx = &m * &group.gram * m.transpose();
        let xty = &m * &group.cross;
        // A whisper of ridge keeps collinear taps solvable without moving the fit.
        let ridge = 1e-12 * xtx.trace().max(f64::MIN_POSITIVE) / width as f64;
        let regularised = xtx + DMatrix::identity(width, width) * ridge;
        let weights = regularised.cholesky().map_or_else(|| DVector::zeros(width), |chol| chol.solve(&xty));
        let ssr = (group.yy - xty.dot(&weights)).max(0.0);
        (weights, ssr)
    }

    /// The residual of the balance on the de-lagged taps over `part(run)` of every run (NaN
    /// where a sample is unusable), each run centred: for the effective number of samples.
    #[must_use]
    pub fn residuals<R: Borrow<RunStreams>>(
        &self,
        runs: &[R],
        part: impl Fn(&RunStreams) -> Vec<usize>,
        tau_s: &[f64],
    ) -> Vec<Vec<f64>> {
        let n_taps = self.taps.len();
        runs.iter()
            .map(Borrow::borrow)
            .map(|run: &RunStreams| {
                let Some(group) = self.groups.iter().find(|g| g.alpha_key == alpha_key(run.alpha_deg)) else {
                    return Vec::new();
                };
                let (weights, _) = self.solve(group, tau_s);
                let afc = run.cl_afc();
                let raw: Vec<f64> = part(run)
                    .into_iter()
                    .map(|idx| {
                        let mut predicted = weights[n_taps] * afc[idx];
                        for (col, &tap) in self.taps.iter().enumerate() {
                            predicted += weights[col] * (run.cp[tap][idx] + tau_s[col] * run.cp_dot[tap][idx]);
                        }
                        run.cl_measured[idx] - predicted
                    })
                    .collect();
                let finite: Vec<f64> = raw.iter().copied().filter(|v| v.is_finite()).collect();
                let mean = finite.iter().sum::<f64>() / finite.len().max(1) as f64;
                raw.into_iter().map(|v| v - mean).collect()
            })
            .collect()
    }

    /// Effective samples of the balance's residual on the fitted samples with the taps de-lagged
    /// by `taus_s`: their number over the residual's integrated autocorrelation time.
    fn effective_samples<R: Borrow<RunStreams>>(&self, runs: &[R], taus_s: &[f64]) -> f64 {
        let residuals = self.residuals(runs, |run| run.fit_samples().collect(), taus_s);
        let segments: Vec<Segment<'_>> = residuals
            .iter()
            .map(|r| Segment { residual: r, training: 0..r.len(), select: Interleave::default(), heldout: 0..0 })
            .collect();
        self.n() as f64 / regression::integrated_autocorrelation(&segments, 200)
    }

    /// The one time constant for every channel that re-aligns the taps with the balance best
    /// over `range` (grid, then golden-section refinement); `None` when the best fit is at an
    /// end of the range (no minimum inside it).
    #[must_use]
    pub fn shared_in(&self, range: (f64, f64)) -> Option<f64> {
        let n = self.taps.len();
        minimise_interior(|tau| self.ssr(&vec![tau; n]), range)
    }

    /// The standard error of the alignment `tau_s` of `runs` (the runs this alignment was
    /// accumulated on), s: from the curvature of the residual sum of squares there, `var =
    /// 2 SSR / (n_eff SSR'')` (the profile likelihood of a least-squares fit, Seber & Wild,
    /// Nonlinear Regression, 1989, ch. 5), with the effective samples of the residual. `None`
    /// without a minimum there.
    fn standard_error_s<R: Borrow<RunStreams>>(&self, runs: &[R], tau_s: f64) -> Option<f64> {
        const STEP_S: f64 = 5e-3;
        let n = self.taps.len();
        let at = |t: f64| self.ssr(&vec![t; n]);
        let (centre, up, down) = (at(tau_s), at(tau_s + STEP_S), at(tau_s - STEP_S));
        let curvature = (up + down - 2.0 * centre) / (STEP_S * STEP_S);
        let n_eff = self.effective_samples(runs, &vec![tau_s; n]);
        let variance = 2.0 * centre / (n_eff * curvature);
        (curvature > 0.0 && n_eff >= 2.0 && variance.is_finite()).then(|| variance.sqrt())
    }

    /// The sim's own alignment ([`REFERENCE_RANGE_S`]), for its signature; `None` at a range
    /// end.
    #[must_use]
    pub fn reference(&self) -> Option<f64> {
        self.shared_in(REFERENCE_RANGE_S)
    }

    /// The weights fitted on this alignment's samples, applied to `part(run)` of every run:
    /// the balance residual with the taps de-lagged by `tau_s` ([`Self::residuals`]) at two
    /// sets of time constants, flattened over the finite samples of both.
    fn paired_residuals(
        &self,
        runs: &[RunStreams],
        part: &dyn Fn(&RunStreams) -> Vec<usize>,
        before_s: &[f64],
        after_s: &[f64],
    ) -> (Vec<f64>, Vec<f64>) {
        let before = self.residuals(runs, part, before_s);
        let after = self.residuals(runs, part, after_s);
        before
            .iter()
            .flatten()
            .zip(after.iter().flatten())
            .filter(|(b, a)| b.is_finite() && a.is_finite())
            .map(|(b, a)| (*b, *a))
            .unzip()
    }
}

fn alpha_key(alpha_deg: f64) -> i64 {
    (alpha_deg * 1e3).round() as i64
}

/// [`minimise`], or `None` when the minimum is at an end of `range` (within half a grid step).
fn minimise_interior(f: impl FnMut(f64) -> f64, range: (f64, f64)) -> Option<f64> {
    let found = minimise(f, range);
    let margin = 0.5 * (range.1 - range.0) / (MINIMISE_GRID - 1) as f64;
    (found > range.0 + margin && found < range.1 - margin).then_some(found)
}

/// Points of [`minimise`]'s grid.
const MINIMISE_GRID: usize = 48;

/// Minimises `f` over `range`: a grid of 48 points, then golden-section search in the bracket
/// around the best.
fn minimise(mut f: impl FnMut(f64) -> f64, range: (f64, f64)) -> f64 {
    const GRID: usize = MINIMISE_GRID;
    let (low, high) = range;
    let step = (high - low) / (GRID - 1) as f64;
    let values: Vec<f64> = (0..GRID).map(|i| f(low + step * i as f64)).collect();
    let best = values.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1)).map_or(0, |(i, _)| i);
    let (mut a, mut b) = (low + step * best.saturating_sub(1) as f64, low + step * (best + 1).min(GRID - 1) as f64);
    let ratio = 0.5 * (5f64.sqrt() - 1.0);
    let (mut c, mut d) = (b - ratio * (b - a), a + ratio * (b - a));
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..30 {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - ratio * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + ratio * (b - a);
            fd = f(d);
        }
    }
    let refined = 0.5 * (a + b);
    if f(refined) <= values[best] { refined } else { low + step * best as f64 }
}

/// The `pressure_lag` finding of the alignment: every channel lagged by one time constant, or
/// `None` when the taps cannot be aligned with the balance, when the best alignment is at an end
/// of [`TAU_RANGE_S`] (no lag), or when it is not beyond `reference_tau_s`, the sim's own
/// alignment on the data it was fitted on (its signature: a rig's tubing and the sim's map sit a
/// few milliseconds from zero).
///
/// Only the common lag is taken from the balance: one time constant per channel is not
/// identifiable this way (twelve correlated taps trade their lags against each other: on a
/// clean recording single channels came out 10 to 15 ms off, on a 50 ms lag of every channel
/// from 40 to 136 ms). A lag of one channel is the innovations' ([`super::sensor`]), where the
/// other channels hold the filter.
///
/// The time constant and the balance's weights on the taps are fitted on the training part
/// only; the selection and held-out parts are judged with both fixed (`part_check`).
#[must_use]
pub fn finding<'a>(runs: &[RunStreams], reference: impl Into<Reference<'a>>) -> Option<SensorFinding> {
    let reference = reference.into();
    let reference_tau_s = reference.tau_s;
    let alignment = Alignment::new(runs, |run| run.fit_samples().collect())?;
    let n_taps = alignment.taps().len();
    let ssr_reference = alignment.ssr(&vec![reference_tau_s; n_taps]);
    let shared = alignment.shared_in((TAU_RANGE_S.0.min(reference_tau_s - 0.1), TAU_RANGE_S.1))?;
    if shared <= reference_tau_s {
        return None;
    }
    let taus = vec![shared; n_taps];
    let n_eff = alignment.effective_samples(runs, &taus);
    if n_eff < 2.0 || ssr_reference <= 0.0 {
        return None;
    }
    let delta_bic = n_eff * (ssr_reference / alignment.ssr(&taus).max(f64::MIN_POSITIVE)).ln() - n_eff.ln();
    let lag_s = shared - reference_tau_s;
    // Beyond the scatter of both alignments: paired by kind of run and angle of attack where the
    // signature holds the sim's own per kind ([`paired_shift`]); otherwise the recording's
    // scatter from its runs (a run that cannot be aligned inside the range adds nothing) and the
    // sim's from its signature.
    match reference.by_kind.and_then(|own| paired_shift(runs, own)) {
        Some((shift_s, standard_error_s)) => {
            if shift_s < MIN_CHANNEL_LAG_S.max(LAG_SIGNIFICANCE_Z * standard_error_s) {
                return None;
            }
        }
        None => {
            let range = (TAU_RANGE_S.0.min(reference_tau_s - 0.1), TAU_RANGE_S.1);
            let scatter_s = run_scatter_s(runs, range).unwrap_or(0.0);
            if lag_s < LAG_SIGNIFICANCE_Z * scatter_s.hypot(reference.scatter_s) {
                return None;
            }
        }
    }
    let (explained, _) = lag_deviation(runs, alignment.taps(), &|run| run.fit_samples().collect(), lag_s);
    let noise_var = {
        let mut differences = Vec::new();
        for run in runs {
            for &tap in alignment.taps() {
                let cp = &run.cp[tap];
                differences.extend(run.training.clone().skip(1).map(|i| cp[i] - cp[i - 1]).filter(|d| d.is_finite()));
            }
        }
        regression::robust_difference_var(&mut differences)
    };
    let check = |part: &dyn Fn(&RunStreams) -> Vec<usize>| part_check(&alignment, runs, part, reference_tau_s, shared);
    let selection = confirmed(check(&|run| run.select.samples().collect()), explained);
    let heldout = check(&|run| run.heldout.clone().collect()).gap;
    let names: Vec<String> = alignment.taps().iter().map(|&tap| channel_name(tap)).collect();
    Some(SensorFinding {
        effect: firmware_sim::effect::Effect::PressureLag,
        params: vec![
            ("tau_s".to_owned(), ParamValue::Number(lag_s)),
            ("channels".to_owned(), ParamValue::Text("all".into())),
            ("reference_tau_s".to_owned(), ParamValue::Number(reference_tau_s)),
        ],
        channel: None,
        channels: names,
        explained,
        noise_var,
        delta_bic,
        heldout,
        selection,
        evidence: format!(
            "the taps align with the balance moment once every channel is de-lagged by {:.1} ms beyond the sim's own {:.1} ms",
            1e3 * lag_s,
            1e3 * reference_tau_s
        ),
    })
}

/// The least lag of a channel in a set, s: half the contract's shortest lag (5 ms,
/// docs/spec/diagnosis.md, What each name covers), the midpoint between no lag and the
/// shortest one. Below it a channel's apparent lag is the pressure model's error, which moves a
/// channel's relative lag by a millisecond or two from recording to recording.
pub const MIN_CHANNEL_LAG_S: f64 = 2.5e-3;

/// Share of the largest lag of a set that a healthy channel can show: a lag left in what the
/// others expect of a channel (a de-lag that is not exact: a second-order lag, a time constant
/// a few per cent off) moves its apparent lag with the size of the lags around it. On the
/// development rig of the second tunnel, healthy channels beside a lagged set showed 10 to 29 %
/// of the set's largest lag (five recordings, sets of two to seven channels, 17 to 75 ms).
const FOOTPRINT_SHARE: f64 = 0.3;

/// Standard errors a channel's lag must stand above zero to count as lagged.
const CHANNEL_LAG_Z: f64 = 3.0;

/// The lagged channels of a set and each one's lag beyond the sim's own, s (0-based taps): how
/// the channels' lags differ is the innovations' (`lags`, [`super::lag_set::identify`], less
/// the sim's own differences on the data it was fitted on, `own`); the lag they share is taken
/// from the least lagged channel, as healthy, unless the balance, which reads the pressures
/// without lag, found a common lag (`common_lag`: [`finding`] named one, beyond the scatter of
/// both alignments) that places even that channel beyond the least lag. A
/// channel is in the set when its lag stands above zero ([`MIN_CHANNEL_LAG_S`],
/// [`CHANNEL_LAG_Z`] standard errors, [`FOOTPRINT_SHARE`] of the largest). `None` without a set.
/// Fitted on the training part only; the set's evidence is the innovations'
/// ([`super::sensor`]).
#[must_use]
pub fn channel_set<'a>(
    runs: &[RunStreams],
    reference: impl Into<Reference<'a>>,
    lags: &super::lag_set::ChannelLags,
    own: Option<&super::lag_set::ChannelLags>,
    common_lag: bool,
) -> Option<Vec<(usize, f64)>> {
    let reference = reference.into();
    let reference_tau_s = reference.tau_s;
    let alignment = Alignment::new(runs, |run| run.fit_samples().collect())?;
    let taps = alignment.taps().to_vec();
    let own_of = |tap: usize| own.and_then(|own| own.relative_s.get(tap).copied()).unwrap_or(0.0);
    let own_se_of = |tap: usize| own.and_then(|own| own.standard_error_s.get(tap).copied()).unwrap_or(0.0);
    let contrast: Vec<f64> =
        taps.iter().map(|&tap| lags.relative_s.get(tap).copied().unwrap_or(0.0) - own_of(tap)).collect();
    let range = (TAU_RANGE_S.0.min(reference_tau_s - 0.1), TAU_RANGE_S.1);
    let shifted = |shift_s: f64, member: &dyn Fn(usize) -> bool| -> Vec<f64> {
        contrast.iter().enumerate().map(|(col, c)| if member(col) { shift_s + c } else { reference_tau_s }).collect()
    };
    // The least lagged channel is taken as healthy (a lag is never negative), unless the
    // balance shows a lag common to every channel beyond the scatter of both alignments
    // (`common_lag`, [`finding`]) and places even the least lagged channel beyond the least lag.
    let least = contrast.iter().copied().fold(f64::INFINITY, f64::min);
    let anchored_s = reference_tau_s - least;
    let balance_s = minimise(|shift_s| alignment.ssr(&shifted(shift_s, &|_| true)), range);
    let every_lagged = common_lag && balance_s - anchored_s >= MIN_CHANNEL_LAG_S;
    let common_s = if every_lagged { balance_s } else { anchored_s };
    let lag_at = |col: usize| common_s + contrast[col] - reference_tau_s;
    let largest_s = (0..taps.len()).map(lag_at).fold(0.0, f64::max);
    let members: Vec<usize> = (0..taps.len())
        .filter(|&col| {
            let se_s =
                lags.standard_error_s.get(taps[col]).copied().unwrap_or(f64::INFINITY).hypot(own_se_of(taps[col]));
            lag_at(col) >= MIN_CHANNEL_LAG_S.max(CHANNEL_LAG_Z * se_s).max(FOOTPRINT_SHARE * largest_s)
        })
        .collect();
    if members.is_empty() {
        return None;
    }
    let is_member = |col: usize| members.contains(&col);
    // With every channel lagged, the balance fixes the shift the lags share; otherwise the
    // healthy channels do.
    let set_s =
        if every_lagged { minimise(|shift_s| alignment.ssr(&shifted(shift_s, &is_member)), range) } else { common_s };
    let taus = shifted(set_s, &is_member);
    let lag_of = |col: usize| taus[col] - reference_tau_s;
    members.iter().all(|&col| lag_of(col) > 0.0).then(|| members.iter().map(|&col| (taps[col], lag_of(col))).collect())
}

/// Mean square of a lag's deviation from the true pressure, `-tau y'` (exact for a first-order
/// lag), over the channels `taps` and the samples `part(run)` of every run, and their number.
fn lag_deviation(
    runs: &[RunStreams],
    taps: &[usize],
    part: &dyn Fn(&RunStreams) -> Vec<usize>,
    tau_s: f64,
) -> (f64, usize) {
    let (mut sum, mut n) = (0.0, 0usize);
    for run in runs {
        let samples = part(run);
        for &tap in taps {
            for &idx in &samples {
                let value = tau_s * run.cp_dot[tap][idx];
                if value.is_finite() {
                    sum += value * value;
                    n += 1;
                }
            }
        }
    }
    (if n == 0 { 0.0 } else { sum / n as f64 }, n)
}

/// The common lag's gap on one part (selection or held out), in Cp, with nothing fitted there.
///
/// The true pressure is not measured, so the lag's size in a part is read off the balance: the
/// balance residual with the taps at the sim's own alignment, `r0`, and with them de-lagged by
/// the training lag, `r1`, both with the weights fitted on the training part. Their difference
/// `d = r0 - r1` is what the training lag predicts; the slope `s = <r0, d> / <d, d>` is the share
/// of it the part shows (1 when the part holds the training lag, 0 when it holds none: on a
/// clean recording the de-lagged taps predict nothing the balance holds). In Cp, with `D` the
/// mean square of the training lag's deviation `-tau y'` over the part, the gap before is the
/// part's own lag, `s^2 D`, and after removing the training lag `(s - 1)^2 D`: what is removed,
/// `(2 s - 1) D`, is positive only when the part confirms more than half of the lag, and is `-D`
/// on a recording without one. No time constant, weight or level is fitted on the part (an
/// earlier form re-fitted the time constant there, so the part confirmed whatever it found).
fn part_check(
    alignment: &Alignment,
    runs: &[RunStreams],
    part: &dyn Fn(&RunStreams) -> Vec<usize>,
    reference_tau_s: f64,
    shared_s: f64,
) -> PartCheck {
    let n_taps = alignment.taps().len();
    let (r0, r1) = alignment.paired_residuals(runs, part, &vec![reference_tau_s; n_taps], &vec![shared_s; n_taps]);
    let (deviation, n) = lag_deviation(runs, alignment.taps(), part, shared_s - reference_tau_s);
    share_check(&r0, &r1, deviation, n)
}

/// The share of the training lag a part shows, from the balance residuals before (`r0`) and
/// after (`r1`) the de-lag, and the gap it implies in Cp with `deviation`, the mean square of
/// the training lag's deviation over the part's `n` samples ([`part_check`]).
fn share_check(r0: &[f64], r1: &[f64], deviation: f64, n: usize) -> PartCheck {
    let (mut rd, mut dd) = (0.0, 0.0);
    for (before, after) in r0.iter().zip(r1) {
        let d = before - after;
        rd += before * d;
        dd += d * d;
    }
    if dd <= 0.0 || n == 0 {
        return PartCheck { gap: regression::HeldoutGap::EMPTY, share: f64::NAN, standard_error: f64::NAN };
    }
    let share = rd / dd;
    // The share's standard error: the variance of what the share leaves of `r0`, times its
    // integrated autocorrelation time, over `<d, d>` (as a balance candidate's calibration
    // slope, [`super::attribution::Slope`]).
    let left: Vec<f64> = r0.iter().zip(r1).map(|(before, after)| before - share * (before - after)).collect();
    let segment = Segment { residual: &left, training: 0..left.len(), select: Interleave::default(), heldout: 0..0 };
    let left_var = left.iter().map(|v| v * v).sum::<f64>() / left.len().max(1) as f64;
    let autocorrelation = regression::integrated_autocorrelation(std::slice::from_ref(&segment), 200);
    PartCheck {
        gap: regression::HeldoutGap {
            mse_before: share * share * deviation,
            mse_after: (share - 1.0) * (share - 1.0) * deviation,
            noise_var: 0.0,
            n,
            floor_var: 0.0,
        },
        share,
        standard_error: (left_var * autocorrelation.max(1.0) / dd).sqrt(),
    }
}

/// A part's check of the common lag: its gap in Cp, and the share of the training lag it shows
/// with its standard error.
struct PartCheck {
    gap: regression::HeldoutGap,
    share: f64,
    standard_error: f64,
}

/// The selection part's confirmation of the common lag, as a balance candidate's
/// ([`super::attribution::Profiled::selected`]): the larger of what it removes on the part and
/// what the lag explains on the training part (`explained`, Cp^2 per sample) times the part's
/// share (at most 1), when the share stands [`super::attribution::CONFIRM_Z`] standard errors
/// above zero. Why both: the selection blocks are short, and the share, a ratio of two small
/// sums there, swings widely (a 70 ms lag of every channel showed 0.57 of itself on the blocks
/// and 0.95 on the held-out part); the share asks whether the lag is there, the training part
/// says how large it is. Expressed as a gap whose removal is that size.
fn confirmed(check: PartCheck, explained: f64) -> regression::HeldoutGap {
    let PartCheck { gap, share, standard_error } = check;
    let by_share =
        if share.is_finite() && standard_error.is_finite() && share >= super::attribution::CONFIRM_Z * standard_error {
            explained * share.min(1.0)
        } else {
            0.0
        };
    let removed = gap.removed().max(by_share);
    if gap.n == 0 || removed <= gap.removed() {
        return gap;
    }
    let before = gap.mse_before.max(removed);
    regression::HeldoutGap { mse_before: before, mse_after: before - removed, ..gap }
}

/// Whether the lag found on the channels `group` is common to every channel: one time constant
/// on every channel aligns the taps with the balance better than one on the group alone (the
/// others at the sim's own alignment), by more than the Bayesian information criterion's
/// penalty of one parameter (effective samples from the residual's autocorrelation). The
/// innovations alone cannot tell: a lag of every channel leaves some standing out there, and a
/// lag of some shifts the alignment of all twelve. One time constant per hypothesis: the taps
/// are correlated, and per-channel lags on the balance trade against each other (a lag of every
/// channel by 20 ms was fitted as 58 ms on one channel and none on the rest). The innovations'
/// own time constants are not used (part of a group's lag hides in what the other channels
/// expect). `false` when the taps cannot be aligned.
#[must_use]
pub fn lag_is_common(runs: &[RunStreams], group: &[usize], reference_tau_s: f64) -> bool {
    let Some(alignment) = Alignment::new(runs, |run| run.fit_samples().collect()) else { return false };
    let Some(common_s) = alignment.shared_in((TAU_RANGE_S.0.min(reference_tau_s - 0.1), TAU_RANGE_S.1)) else {
        return false;
    };
    let every = vec![common_s; alignment.taps().len()];
    let group_taus = |tau_s: f64| -> Vec<f64> {
        alignment.taps().iter().map(|tap| if group.contains(tap) { tau_s } else { reference_tau_s }).collect()
    };
    let group_tau_s = minimise(|tau_s| alignment.ssr(&group_taus(tau_s)), TAU_RANGE_S);
    let (group_only, common) = (alignment.ssr(&group_taus(group_tau_s)), alignment.ssr(&every));
    let n_eff = alignment.effective_samples(runs, &every);
    n_eff >= 2.0 && common > 0.0 && n_eff * (group_only / common).ln() > n_eff.ln()
}

#[cfg(test)]
pub(super) mod tests;

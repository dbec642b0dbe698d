//! Attribution on the balance stream: every candidate profiled over its grid on the training
//! part, compared by a complexity-penalised criterion (BIC on the effective number of samples;
//! docs/diagnosis.md, Attribution), forward selection of further effects on the
//! remainder, a structure probe of what no candidate explains, and the held-out gap with each
//! effect added.

use rayon::prelude::*;

use super::candidates::{self, Candidate, Context, Form};
use super::regression::delta_bic;
use super::regression::{self, Fit, HeldoutGap, Interleave, Segment};
use super::streams::RunStreams;

/// A candidate profiled over its grid.
#[derive(Debug, Clone)]
pub struct Profiled {
    /// The candidate.
    pub candidate: Candidate,
    /// The form with the most evidence.
    pub form: Form,
    /// The fit at that point.
    pub fit: Fit,
    /// Complexity-penalised evidence against no effect.
    pub delta_bic: f64,
    /// Profile: the criterion's residual sum of squares at each grid point (for the report).
    pub profile: Vec<(f64, f64)>,
    /// Gap on the selection part before and after the effect (with the training part's fit).
    pub selection: HeldoutGap,
    /// Held-out gap before and after the effect.
    pub heldout: HeldoutGap,
    /// The selection part's residual regressed on the effect's prediction there (its
    /// calibration slope): about 1 where the fitted effect is real, about 0 where the fit was
    /// noise.
    pub selection_slope: Slope,
    /// Share of the training part's fit samples (of the touched runs) where the effect acts (a
    /// column is not zero there): an effect of the blowing acts only while the jets blow.
    pub active_share: f64,
    /// The same over the selection part's samples.
    pub selection_active_share: f64,
    /// Where the selection part holds too little of the effect to confirm even the fitted
    /// effect itself: the training part cross-validated instead.
    pub cross_validation: Option<CrossValidation>,
    /// The best form lies at an end of what the family profiles beyond the effect's range
    /// ([`super::candidates::BalanceCandidate::beyond_its_range`]): the fit is another effect's.
    pub beyond_its_range: bool,
    /// The evidence of the best form over that of the best of the forms it tends to at the ends
    /// of its profiled time constant ([`super::candidates::BalanceCandidate::limits`]), each
    /// with one profiled parameter fewer; infinite for a family without limits.
    pub limit_margin: f64,
}

impl Profiled {
    /// Whether the fit is the effect its name stands for.
    ///
    /// - Its best form lies inside what the family profiles ([`Self::beyond_its_range`]): a slow
    ///   state at the longest time constant searched is the static term of its drive (of the
    ///   roll rate, a linear roll damping).
    /// - It beats the forms it tends to at the ends of its time constant by decisive evidence
    ///   ([`Self::limit_margin`], [`super::MIN_DELTA_BIC`]): a slow state the data cannot tell
    ///   from its drive's static term or rate is not resolved as a state. A roll damping on this
    ///   project's tunnel was named a slow state of the roll rate at 21 s, and a mount's cubic
    ///   stiffness on the second tunnel a state of the roll angle at 13.6 s.
    /// - Its gains are the effect's ([`super::candidates::BalanceCandidate::admits`]). An
    ///   effect that keeps the sim's static gain
    ///   ([`super::candidates::BalanceCandidate::unit_gain`]) fits gains within
    ///   [`super::candidates::UNIT_GAIN_RANGE`]: a "delay" of 3 ms at eleven times the plant's
    ///   moment is the derivative of that moment (a mode the blowing rings), not a pneumatic
    ///   line. An inertia left in the balance has one sign on every mounting.
    ///
    /// An implausible fit is never named, but it stays in the ranking and in the sim's
    /// signature: what it takes of the sim's own error is still a floor.
    #[must_use]
    pub fn plausible(&self) -> bool {
        !self.beyond_its_range
            && self.limit_margin >= super::MIN_DELTA_BIC
            && self.candidate.admits(&self.form.shape, &self.fit.beta)
    }

    /// Mean square explained per touched training sample.
    #[must_use]
    pub fn explained(&self) -> f64 {
        self.fit.explained_per_sample()
    }

    /// The size of the effect the selection part confirms, per sample where it acts: the larger
    /// of two out-of-sample measures of it (the evidence the decisions rest on).
    ///
    /// - What it removes on the selection part, per selection sample where it acts.
    /// - What it explains on the training part, per training sample where it acts, times the
    ///   selection part's calibration slope (at most 1), when that slope stands [`CONFIRM_Z`]
    ///   standard errors above zero (0 otherwise).
    ///
    /// Why both: the selection part is a few blocks of each run, and an effect that acts in part
    /// of a run (a coupling only while the jets blow during the roll) is judged by the first
    /// measure on how much of its activity those blocks happen to hold. On the own tunnel a
    /// coupling at 2.4 times the noise explained 3.2 noise variances per training sample and
    /// removed 0.05 per selection sample, where its prediction held 0.07: its slope there was
    /// 0.85 (standard error 0.36), and its held-out shrink 0.80. The slope asks whether the
    /// fitted effect is there, whatever share of it the blocks hold, and the training part,
    /// four times larger, says how large it is. Where the blocks hold more of an effect than
    /// the training part does (a roll damping whose blocks fell in the fastest rolling), the
    /// first measure is the larger. Each alone named nothing on the clean recordings of either
    /// tunnel (0 of 20), so neither does their larger.
    ///
    /// Where the selection part cannot judge and the training part was cross-validated instead
    /// ([`CrossValidation`]), only what the folds remove per sample where it acts counts, and
    /// only when their pooled slope stands `CONFIRM_Z` standard errors above zero: the training
    /// part's fit of a form chosen there is not evidence for itself.
    #[must_use]
    pub fn selected(&self) -> f64 {
        if let Some(cross) = &self.cross_validation {
            return if cross.slope.confirmed() {
                (cross.removed / cross.active_share.max(f64::MIN_POSITIVE)).max(0.0)
            } else {
                0.0
            };
        }
        let removed = self.selection.removed() / self.selection_active_share.max(f64::MIN_POSITIVE);
        let confirmed = if self.selection_slope.confirmed() {
            self.explained() / self.active_share.max(f64::MIN_POSITIVE) * self.selection_slope.value.min(1.0)
        } else {
            0.0
        };
        if self.selection_active_share > 0.0 { removed.max(confirmed) } else { confirmed }
    }
}

/// How many of a family's leading coarse forms are refined ([`candidates::BalanceCandidate::refine`]),
/// besides the best of every other kind of form: more than one, because neighbouring optima of
/// a coarse grid (two modes, a delay and its alias) can swap order on the fine one.
const REFINED_LEADERS: usize = 3;

/// Which of a family's coarse forms, ranked best first by their shapes, are refined: the
/// `REFINED_LEADERS` leading ones and the best of every other kind of shape. The leaders of
/// one kind (neighbouring first-order lags) can fill the places, and a second-order valve whose
/// coarse grid falls between its optimum's neighbours would never be looked at near its optimum.
#[must_use]
pub fn refined_leaders(ranked: &[candidates::Shape]) -> Vec<usize> {
    let mut leaders: Vec<usize> = (0..ranked.len().min(REFINED_LEADERS)).collect();
    for (idx, shape) in ranked.iter().enumerate() {
        let kind = std::mem::discriminant(shape);
        if !leaders.iter().any(|&leader| std::mem::discriminant(&ranked[leader]) == kind) {
            leaders.push(idx);
        }
    }
    leaders
}

/// Standard errors above zero the selection part's calibration slope must stand for the fitted
/// effect to count as confirmed there (one-sided, about 2 % by chance).
pub const CONFIRM_Z: f64 = 2.0;

/// A calibration slope and its standard error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slope {
    /// `sum r p / sum p^2` over the selection samples of the touched runs.
    pub value: f64,
    /// Its standard error: the noise's variance times the residual's integrated
    /// autocorrelation time (samples), over `sum p^2`.
    pub standard_error: f64,
}

impl Slope {
    /// The slope of `sum r p` over `sum p^2`, its standard error from the noise's variance times
    /// the residual's integrated autocorrelation time (samples); NaN without a prediction.
    #[must_use]
    pub fn from_sums(rp: f64, pp: f64, noise_var: f64, autocorrelation_time: f64) -> Self {
        if pp > 0.0 {
            Self { value: rp / pp, standard_error: (noise_var * autocorrelation_time.max(1.0) / pp).sqrt() }
        } else {
            Self { value: f64::NAN, standard_error: f64::NAN }
        }
    }

    /// Whether it stands [`CONFIRM_Z`] standard errors above zero.
    #[must_use]
    pub fn confirmed(&self) -> bool {
        self.value.is_finite() && self.standard_error.is_finite() && self.value >= CONFIRM_Z * self.standard_error
    }
}

/// The selection part's residual regressed through the origin on the fitted effect's
/// prediction there (the touched runs, finite residuals); NaN without any prediction.
fn selection_slope(
    segments: &[Segment<'_>],
    columns: &[Vec<Vec<f64>>],
    fit: &Fit,
    noise_var: f64,
    autocorrelation_time: f64,
) -> Slope {
    let (rp, pp) = slope_sums(segments, columns, fit);
    Slope::from_sums(rp, pp, noise_var, autocorrelation_time)
}

/// A candidate cross-validated over the training part: each of the [`Interleave::EVERY`]
/// positions of the interleaved blocks in turn is set apart, the form with the most evidence
/// ([`delta_bic`]) among `forms` is chosen and fitted on the other blocks, and judged on the
/// set-apart blocks; the folds' sums give one calibration slope and one gap (Stone 1974; the
/// form chosen within each fold, so that the choice among many forms does not confirm itself:
/// Varma & Simon 2006). `None` without a prediction anywhere.
fn cross_validate(
    candidate: Candidate,
    forms: &[Form],
    runs: &[RunStreams],
    residuals: &[Vec<f64>],
    context: &Context<'_>,
    noise_var: f64,
    autocorrelation_time: f64,
) -> Option<CrossValidation> {
    let segments = segments(runs, residuals);
    let folds: Vec<Vec<Segment<'_>>> = (0..Interleave::EVERY)
        .map(|position| {
            segments
                .iter()
                .map(|segment| Segment { select: segment.select.fold(position), ..segment.clone() })
                .collect()
        })
        .collect();
    let fold_samples: Vec<regression::FitSamples> =
        folds.iter().map(|fold| regression::FitSamples::new(fold)).collect();
    // Per form, per fold: its evidence without the fold, and what it does on the fold.
    let per_form: Vec<Vec<(f64, FoldSums)>> = forms
        .par_iter()
        .map(|form| {
            let columns = all_columns(candidate, form, runs, context);
            folds
                .iter()
                .zip(&fold_samples)
                .map(|(fold, samples)| {
                    regression::fit_through_origin_on(samples, &columns).map_or(
                        (f64::NEG_INFINITY, FoldSums::default()),
                        |fit| {
                            let evidence = delta_bic(&fit, autocorrelation_time, fit.beta.len() + form.n_profiled());
                            let (rp, pp) = slope_sums(fold, &columns, &fit);
                            let gap = regression::selection_gap(fold, &columns, &fit.beta, &fit.touched);
                            let active =
                                active_share(fold, &columns, &fit.touched, |segment, i| segment.select.contains(i));
                            let n = gap.n as f64;
                            (evidence, FoldSums { rp, pp, removed: gap.removed() * n, active: active * n, n })
                        },
                    )
                })
                .collect()
        })
        .collect();
    let mut sums = FoldSums::default();
    for fold in 0..folds.len() {
        if let Some((_, best)) = per_form.iter().map(|folds| folds[fold]).max_by(|a, b| a.0.total_cmp(&b.0)) {
            sums = FoldSums {
                rp: sums.rp + best.rp,
                pp: sums.pp + best.pp,
                removed: sums.removed + best.removed,
                active: sums.active + best.active,
                n: sums.n + best.n,
            };
        }
    }
    (sums.pp > 0.0 && sums.n > 0.0).then(|| CrossValidation {
        slope: Slope::from_sums(sums.rp, sums.pp, noise_var, autocorrelation_time),
        removed: sums.removed / sums.n,
        active_share: sums.active / sums.n,
    })
}

/// One fold's sums: `sum r p`, `sum p^2`, the mean square removed times the samples, the active
/// share times the samples, and the samples.
#[derive(Debug, Clone, Copy, Default)]
struct FoldSums {
    rp: f64,
    pp: f64,
    removed: f64,
    active: f64,
    n: f64,
}

/// What a cross-validation over the training part confirms of a candidate
/// ([`Profiled::selected`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CrossValidation {
    /// The set-apart blocks' residual on the prediction there, pooled over the folds.
    pub slope: Slope,
    /// Mean square removed per set-apart sample, pooled over the folds.
    pub removed: f64,
    /// Share of the set-apart samples where the prediction acts.
    pub active_share: f64,
}

/// `sum r p` and `sum p^2` over the selection samples of the touched runs (finite residuals),
/// `p` the fitted effect's prediction.
fn slope_sums(segments: &[Segment<'_>], columns: &[Vec<Vec<f64>>], fit: &Fit) -> (f64, f64) {
    let (mut rp, mut pp) = (0.0, 0.0);
    for ((segment, cols), _) in segments.iter().zip(columns).zip(&fit.touched).filter(|(_, touched)| **touched) {
        for i in segment.select.samples().filter(|&i| segment.residual[i].is_finite()) {
            let predicted: f64 = cols.iter().zip(&fit.beta).map(|(col, b)| b * col[i]).sum();
            rp += segment.residual[i] * predicted;
            pp += predicted * predicted;
        }
    }
    (rp, pp)
}

/// Columns of a candidate in one form, for every run.
#[must_use]
pub fn all_columns(
    candidate: Candidate,
    form: &Form,
    runs: &[RunStreams],
    context: &Context<'_>,
) -> Vec<Vec<Vec<f64>>> {
    runs.iter().enumerate().map(|(idx, run)| candidates::columns(candidate, form, run, idx, context)).collect()
}

/// Profiles `candidate` on the residuals `residuals[run]`.
#[must_use]
pub fn profile(
    candidate: Candidate,
    runs: &[RunStreams],
    residuals: &[Vec<f64>],
    context: &Context<'_>,
    autocorrelation_time: f64,
) -> Option<Profiled> {
    let segments = segments(runs, residuals);
    let sample_hz = runs.first()?.sample_hz;
    let forms = candidates::forms(candidate, sample_hz, context);
    let samples = regression::FitSamples::new(&segments);
    // Each form of the family with its evidence: the best form is the one with the most evidence
    // (its columns and profiled parameters penalised), so a richer form wins only by its fit.
    let evaluate = |form: &Form| {
        let columns = all_columns(candidate, form, runs, context);
        regression::fit_through_origin_on(&samples, &columns).map(|fit| {
            let k = fit.beta.len() + form.n_profiled();
            let evidence = delta_bic(&fit, autocorrelation_time, k);
            (*form, fit, evidence)
        })
    };
    let mut fits: Vec<(Form, Fit, f64)> = forms.par_iter().filter_map(evaluate).collect();
    // The family's own refinement around its leading coarse forms: a fine grid only where the
    // coarse one points, so that a narrow optimum (a lightly damped mode, a delay) is found
    // without profiling the fine grid everywhere.
    let mut ranked: Vec<&(Form, Fit, f64)> = fits.iter().collect();
    ranked.sort_by(|a, b| b.2.total_cmp(&a.2));
    let shapes: Vec<candidates::Shape> = ranked.iter().map(|(form, _, _)| form.shape).collect();
    let leaders: Vec<&(Form, Fit, f64)> = refined_leaders(&shapes).into_iter().map(|idx| ranked[idx]).collect();
    let finer: Vec<Form> = leaders
        .iter()
        .flat_map(|(form, _, _)| {
            candidate
                .refine(&form.shape, sample_hz, context)
                .into_iter()
                .map(|shape| Form { shape, per_alpha: form.per_alpha })
        })
        .collect();
    fits.extend(finer.par_iter().filter_map(evaluate).collect::<Vec<_>>());
    let profile = fits.iter().map(|(form, fit, _)| (form.coordinate().map_or(0.0, |(_, v)| v), fit.ssr)).collect();
    let profiled_forms: Vec<Form> = fits.iter().map(|(form, _, _)| *form).collect();
    let (form, fit, delta_bic) = fits.into_iter().max_by(|a, b| a.2.total_cmp(&b.2))?;
    let columns = all_columns(candidate, &form, runs, context);
    let selection = regression::selection_gap(&segments, &columns, &fit.beta, &fit.touched);
    let heldout = regression::heldout_gap(&segments, &columns, &fit.beta, &fit.touched);
    let selection_slope = selection_slope(&segments, &columns, &fit, selection.noise_var, autocorrelation_time);
    // Selection blocks that hold too little of the effect to confirm even the fitted effect
    // itself (a delay acts at the blowing's few switches, which the blocks may all miss): the
    // training part is cross-validated instead, the form chosen again without each fold.
    // Only for a candidate with decisive evidence, the only kind that can be named.
    let selection_can_judge =
        (selection_slope.standard_error * CONFIRM_Z).is_finite() && selection_slope.standard_error * CONFIRM_Z <= 1.0;
    let cross_validation = (delta_bic >= super::MIN_DELTA_BIC && !selection_can_judge)
        .then(|| {
            cross_validate(
                candidate,
                &profiled_forms,
                runs,
                residuals,
                context,
                selection.noise_var,
                autocorrelation_time,
            )
        })
        .flatten();
    let limit_margin = limit_margin(candidate, &form, delta_bic, runs, &segments, context, autocorrelation_time);
    let fit_share = active_share(&segments, &columns, &fit.touched, |segment, i| !segment.select.contains(i));
    let selection_share = active_share(&segments, &columns, &fit.touched, |segment, i| segment.select.contains(i));
    Some(Profiled {
        candidate,
        form,
        fit,
        delta_bic,
        profile,
        selection,
        heldout,
        selection_slope,
        active_share: fit_share,
        selection_active_share: selection_share,
        cross_validation,
        beyond_its_range: candidate.beyond_its_range(&form.shape, context),
        limit_margin,
    })
}

/// [`Profiled::limit_margin`] of `form`, whose evidence is `evidence`: each limit fitted on the
/// same training samples, its evidence with one profiled parameter fewer (Schwarz 1978, the
/// penalty per parameter); infinite without limits.
fn limit_margin(
    candidate: Candidate,
    form: &Form,
    evidence: f64,
    runs: &[RunStreams],
    segments: &[Segment<'_>],
    context: &Context<'_>,
    autocorrelation_time: f64,
) -> f64 {
    let sample_hz = runs.first().map_or(1.0, |run| run.sample_hz);
    candidate
        .limits(&form.shape, sample_hz)
        .into_iter()
        .map(|shape| {
            let limit = Form { shape, ..*form };
            let columns = all_columns(candidate, &limit, runs, context);
            regression::fit_through_origin(segments, &columns).map_or(f64::INFINITY, |fit| {
                let k = (fit.beta.len() + limit.n_profiled()).saturating_sub(1);
                evidence - regression::delta_bic(&fit, autocorrelation_time, k)
            })
        })
        .fold(f64::INFINITY, f64::min)
}

/// Share of the training part's samples that `part` keeps (finite residual, touched runs) where
/// any column is not zero.
fn active_share(
    segments: &[Segment<'_>],
    columns: &[Vec<Vec<f64>>],
    touched: &[bool],
    part: impl Fn(&Segment<'_>, usize) -> bool,
) -> f64 {
    let (mut active, mut n) = (0usize, 0usize);
    for ((segment, cols), _) in segments.iter().zip(columns).zip(touched).filter(|(_, touched)| **touched) {
        let samples = segment.training.clone().filter(|&i| part(segment, i) && segment.residual[i].is_finite());
        for i in samples {
            n += 1;
            active += usize::from(cols.iter().any(|col| col[i] != 0.0));
        }
    }
    if n == 0 { 0.0 } else { active as f64 / n as f64 }
}

/// The segments of the residual stream.
#[must_use]
pub fn segments<'a>(runs: &[RunStreams], residuals: &'a [Vec<f64>]) -> Vec<Segment<'a>> {
    runs.iter()
        .zip(residuals)
        .map(|(run, residual)| Segment {
            residual,
            training: run.training.clone(),
            select: run.select,
            heldout: run.heldout.clone(),
        })
        .collect()
}

/// Subtracts a profiled effect from the residuals (over whole runs).
#[must_use]
pub fn subtract(
    profiled: &Profiled,
    runs: &[RunStreams],
    residuals: &[Vec<f64>],
    context: &Context<'_>,
) -> Vec<Vec<f64>> {
    let columns = all_columns(profiled.candidate, &profiled.form, runs, context);
    residuals
        .iter()
        .zip(&columns)
        .map(|(residual, cols)| {
            residual
                .iter()
                .enumerate()
                .map(|(idx, r)| r - cols.iter().zip(&profiled.fit.beta).map(|(col, b)| b * col[idx]).sum::<f64>())
                .collect()
        })
        .collect()
}

/// Groups of the structure probe: shapes outside every candidate's span that a real gap often
/// has. Used only to say that something remains, never to name it; each group is compared
/// with its own floor in the sim's signature.
pub const PROBE_GROUPS: [&str; 5] =
    ["static_nonlinearity", "moment_nonlinearity", "slow_gain", "input_dynamics", SPECTRAL_LINE];

/// The probe group of steady lines in the residual's spectrum ([`line_columns`]).
pub const SPECTRAL_LINE: &str = "spectral_line";

/// Damping ratio of the `spectral_line` probe's band-pass: a band of 4 % of the line's
/// frequency, which holds a tone that wanders by a few per cent and little of the white noise.
const LINE_BAND_ZETA: f64 = 0.02;

/// Columns of the `spectral_line` probe: for each of the residual's spectral peaks
/// (`seeds_hz`, [`candidates::resonance_seeds_hz`]), the next sample of a steady sinusoid
/// predicted from the last two of the residual's band at it, `2 cos(w dt) b[n-1] - b[n-2]` (an
/// undamped oscillator's recursion; Box & Jenkins 1970, ch. 3). A tone from the rig (a fan, a
/// pump, the mains) is a line no candidate spans and no input predicts, but its own past does;
/// the probe says that it is there, never names it. One gain per line for every run.
#[must_use]
pub fn line_columns(runs: &[RunStreams], residuals: &[Vec<f64>], seeds_hz: &[f64]) -> Vec<Vec<Vec<f64>>> {
    runs.iter()
        .zip(residuals)
        .map(|(run, residual)| {
            let n = run.len();
            let first = residual.iter().copied().find(|v| v.is_finite()).unwrap_or(0.0);
            let held = model_fit::fit::signals::hold_missing(residual, first);
            let dt_s = 1.0 / run.sample_hz;
            seeds_hz
                .iter()
                .map(|&freq_hz| {
                    let band = candidates::band_pass(&held, freq_hz, LINE_BAND_ZETA, dt_s);
                    let twice_cos = 2.0 * (std::f64::consts::TAU * freq_hz * dt_s).cos();
                    (0..n).map(|i| if i < 2 { 0.0 } else { twice_cos * band[i - 1] - band[i - 2] }).collect()
                })
                .collect()
        })
        .collect()
}

/// The probe groups also asked of the remainder after a named effect: shapes no candidate
/// spans. `input_dynamics` spans much of what the candidates do and asks only whether the
/// residual holds input-driven structure when nothing is named.
pub const REMAINDER_PROBE_GROUPS: [&str; 3] = ["static_nonlinearity", "moment_nonlinearity", "slow_gain"];

/// Time constants of the `input_dynamics` probe, s: fast, middle and slow, a decade apart.
const PROBE_TAUS_S: [f64; 3] = [0.02, 0.2, 2.0];

/// A typical roll moment coefficient of the wing (docs/equations.md, Magnitudes of the wing and its
/// sensors: |C_l| stays under about 0.06): the unit of the moment's powers in the
/// `moment_nonlinearity` probe.
const TYPICAL_MOMENT: f64 = 0.05;

/// Columns of one probe group (see [`PROBE_GROUPS`]): odd powers of the roll angle, rate
/// nonlinearity and the eGK moment's growth with the angle (`static_nonlinearity`); the same
/// and the square and cube of the sim's moment, a curved balance calibration or a spring that
/// stiffens with the load (`moment_nonlinearity`). The nested groups each meet their own floor
/// in the signature: the wider one sees shapes that mix both (a stiffening balance spring
/// after a named `vortex_lag` on the second tunnel, where the moment's powers alone did not),
/// while the narrower keeps its lower floor (in one group, a cubic of the roll angle at 0.7
/// times the noise went unseen there); the sim's
/// moment times Legendre polynomials of time per run, a slowly varying gain (`slow_gain`); the
/// roll angle, reduced roll rate, total blowing and the sim's moment through first-order lags of
/// three time scales (`input_dynamics`: any linear dynamics the sim lacks).
#[must_use]
pub fn probe_columns(runs: &[RunStreams], group: &str) -> Vec<Vec<Vec<f64>>> {
    let n_runs = runs.len();
    runs.iter()
        .enumerate()
        .map(|(run_idx, run)| {
            let n = run.len();
            if group == "input_dynamics" {
                let dt_s = 1.0 / run.sample_hz;
                let blowing: Vec<f64> = (0..n).map(|idx| run.cmu[0][idx] + run.cmu[1][idx]).collect();
                let sim = run.cl_sim();
                let mut cols = Vec::new();
                for signal in [&run.phi_rad, &run.phi_dot_rad_s, &blowing, &sim] {
                    for tau_s in PROBE_TAUS_S {
                        cols.push(candidates::first_order_lag(signal, tau_s, dt_s));
                    }
                }
                return cols;
            }
            if group == "static_nonlinearity" || group == "moment_nonlinearity" {
                let mut cols = vec![
                    run.phi_rad.iter().map(|phi| phi.powi(3)).collect::<Vec<f64>>(),
                    run.phi_rad.iter().map(|phi| phi.powi(5)).collect(),
                    run.phi_dot_rad_s.iter().map(|rate| rate * rate.abs()).collect(),
                    run.phi_dot_rad_s.iter().map(|rate| (rate / 0.2).tanh()).collect(),
                    run.phi_rad.iter().zip(&run.cl_egk).map(|(phi, cl)| cl * phi * phi).collect(),
                ];
                if group == "moment_nonlinearity" {
                    // The sim's moment in units of a typical moment, so that its powers keep
                    // the regression well scaled.
                    let moment: Vec<f64> = run.cl_sim().iter().map(|cl| cl / TYPICAL_MOMENT).collect();
                    cols.push(moment.iter().map(|m| m * m).collect());
                    cols.push(moment.iter().map(|m| m.powi(3)).collect());
                }
                return cols;
            }
            let sim = run.cl_sim();
            let duration = run.t_s.last().copied().unwrap_or(1.0).max(f64::MIN_POSITIVE);
            let mut cols = Vec::new();
            for run_slot in 0..n_runs {
                for degree in 1..=4 {
                    cols.push(if run_slot == run_idx {
                        (0..n).map(|idx| sim[idx] * legendre(degree, 2.0 * run.t_s[idx] / duration - 1.0)).collect()
                    } else {
                        vec![0.0; n]
                    });
                }
            }
            cols
        })
        .collect()
}

/// Legendre polynomial `P_degree(x)` by the three-term recurrence.
#[must_use]
pub fn legendre(degree: usize, x: f64) -> f64 {
    let (mut previous, mut current) = (1.0, x);
    if degree == 0 {
        return 1.0;
    }
    for n in 1..degree {
        let next = ((2 * n + 1) as f64 * x * current - n as f64 * previous) / (n + 1) as f64;
        previous = current;
        current = next;
    }
    current
}

#[cfg(test)]
mod tests;

//! Least squares of a residual stream on candidate columns, pooled over runs, through the
//! origin (a run's offset is part of the gap: docs/diagnosis.md, Three parts of every run) or
//! with a per-run intercept as nuisance (removed by centring each run's training part:
//! Frisch-Waugh-Lovell), and the held-out gap before and after the fitted effect.

use nalgebra::{DMatrix, DVector};

/// One run's residual, with the samples of the diagnosis's three parts: candidates are fitted
/// on the training part, chosen on the selection part, and reported on the held-out part, which
/// chooses nothing.
#[derive(Debug, Clone)]
pub struct Segment<'a> {
    /// Residual (NaN where missing).
    pub residual: &'a [f64],
    /// Training samples (the fit part).
    pub training: std::ops::Range<usize>,
    /// Selection samples: interleaved blocks of the training part, where the verdict and the
    /// choice of effects are made; fits leave them out.
    pub select: Interleave,
    /// Held-out samples: where the named effects' shrink is reported.
    pub heldout: std::ops::Range<usize>,
}

/// The selection part: every [`Interleave::EVERY`]th block of `block` samples of a run's
/// training part, so that an effect fitted on the other blocks is checked on samples it has
/// not seen but between them (a drift or a slowly varying gain interpolates there; a later
/// segment would ask it to extrapolate, which the held-out part does, for the report).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Interleave {
    /// First sample of the training part.
    pub start: usize,
    /// End of the training part.
    pub end: usize,
    /// Samples per block (0: no selection part).
    pub block: usize,
    /// Which block of every [`Interleave::EVERY`] is the selection part's (the last one;
    /// another for a fold of a cross-validation, [`Interleave::fold`]).
    pub position: usize,
}

impl Interleave {
    /// One block in this many is for selection.
    pub const EVERY: usize = 5;

    /// Blocks for a training part `range` sampled at `sample_hz`: a twentieth of the part, from
    /// a quarter of a second to one second (longer than the noise's memory, shorter than a
    /// drift's).
    #[must_use]
    pub fn over(range: std::ops::Range<usize>, sample_hz: f64) -> Self {
        let block = (range.len() / 20).clamp((0.25 * sample_hz) as usize, sample_hz as usize).max(1);
        Self { start: range.start, end: range.end, block, position: Self::EVERY - 1 }
    }

    /// The same blocks with the `position`th of every [`Interleave::EVERY`] set apart instead:
    /// one fold of a cross-validation over the training part (the selection blocks then fit).
    #[must_use]
    pub fn fold(self, position: usize) -> Self {
        Self { position: position % Self::EVERY, ..self }
    }

    /// True for a selection sample.
    #[must_use]
    pub fn contains(&self, idx: usize) -> bool {
        self.block > 0
            && idx >= self.start
            && idx < self.end
            && ((idx - self.start) / self.block) % Self::EVERY == self.position
    }

    /// The selection samples.
    pub fn samples(&self) -> impl Iterator<Item = usize> + '_ {
        (self.start..self.end).filter(|&idx| self.contains(idx))
    }
}

/// A least-squares fit of the residual on some columns over the training samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    /// Coefficients, one per column.
    pub beta: Vec<f64>,
    /// Residual sum of squares with the per-run intercepts only.
    pub ssr_base: f64,
    /// Residual sum of squares with the columns.
    pub ssr: f64,
    /// Training samples used.
    pub n: usize,
    /// Training samples of the runs where some column is not identically zero.
    pub n_touched: usize,
    /// Base residual sum of squares over those runs.
    pub ssr_base_touched: f64,
    /// Which runs the columns touch.
    pub touched: Vec<bool>,
}

impl Fit {
    /// Mean square the columns explain per touched training sample.
    #[must_use]
    pub fn explained_per_sample(&self) -> f64 {
        if self.n_touched == 0 { 0.0 } else { (self.ssr_base - self.ssr).max(0.0) / self.n_touched as f64 }
    }
}

/// Fits `columns[run][col]` (every run the same number of columns) to the residual over the
/// training samples, with a per-run intercept. Returns `None` without usable samples.
#[must_use]
pub fn fit(segments: &[Segment<'_>], columns: &[Vec<Vec<f64>>]) -> Option<Fit> {
    fit_with(segments, columns, true)
}

/// As [`fit`] but without the per-run intercept: for streams whose mean is part of the gap (a
/// pressure channel's innovation has zero mean under the model).
#[must_use]
pub fn fit_through_origin(segments: &[Segment<'_>], columns: &[Vec<Vec<f64>>]) -> Option<Fit> {
    fit_with(segments, columns, false)
}

fn fit_with(segments: &[Segment<'_>], columns: &[Vec<Vec<f64>>], centre: bool) -> Option<Fit> {
    fit_gathered(&FitSamples::new(segments), columns, centre)
}

/// The samples a fit uses in each run (the training part less the selection part, finite
/// residuals) and the residual there: the same for every form a family profiles, so
/// gathered once for them all ([`fit_through_origin_on`]).
#[derive(Debug, Clone)]
pub struct FitSamples {
    runs: Vec<(Vec<usize>, Vec<f64>)>,
}

impl FitSamples {
    /// Gathers the fit's samples of every segment.
    #[must_use]
    pub fn new(segments: &[Segment<'_>]) -> Self {
        let runs = segments
            .iter()
            .map(|segment| {
                let idx: Vec<usize> = segment
                    .training
                    .clone()
                    .filter(|&i| segment.residual[i].is_finite() && !segment.select.contains(i))
                    .collect();
                let r = idx.iter().map(|&i| segment.residual[i]).collect();
                (idx, r)
            })
            .collect();
        Self { runs }
    }
}

/// As [`fit_through_origin`], on samples gathered once.
#[must_use]
pub fn fit_through_origin_on(samples: &FitSamples, columns: &[Vec<Vec<f64>>]) -> Option<Fit> {
    fit_gathered(samples, columns, false)
}

fn fit_gathered(samples: &FitSamples, columns: &[Vec<Vec<f64>>], centre: bool) -> Option<Fit> {
    let p = columns.first().map_or(0, Vec::len);
    let mut xtx = DMatrix::<f64>::zeros(p, p);
    let mut xtr = DVector::<f64>::zeros(p);
    let (mut ssr_base, mut ssr_base_touched, mut n, mut n_touched) = (0.0, 0.0, 0usize, 0usize);
    let mut touched = Vec::with_capacity(samples.runs.len());
    for ((idx, residual), cols) in samples.runs.iter().zip(columns) {
        if idx.is_empty() {
            touched.push(false);
            continue;
        }
        let count = idx.len() as f64;
        let r_mean = if centre { residual.iter().sum::<f64>() / count } else { 0.0 };
        // Only the columns that are not identically zero on this run (per-run and per-alpha
        // columns are zero elsewhere): the products among them.
        let active: Vec<usize> = (0..p).filter(|&c| idx.iter().any(|&i| cols[c][i] != 0.0)).collect();
        let centred: Vec<Vec<f64>> = active
            .iter()
            .map(|&c| {
                let col = &cols[c];
                let mean = if centre { idx.iter().map(|&i| col[i]).sum::<f64>() / count } else { 0.0 };
                idx.iter().map(|&i| col[i] - mean).collect()
            })
            .collect();
        let rr: f64 = residual.iter().map(|v| (v - r_mean) * (v - r_mean)).sum();
        ssr_base += rr;
        n += idx.len();
        let is_touched = centred.iter().any(|col| col.iter().any(|v| v.abs() > 0.0));
        touched.push(is_touched);
        if is_touched {
            n_touched += idx.len();
            ssr_base_touched += rr;
        }
        for (a, &ca) in active.iter().enumerate() {
            xtr[ca] += centred[a].iter().zip(residual).map(|(x, y)| x * (y - r_mean)).sum::<f64>();
            for (b, &cb) in active.iter().enumerate().skip(a) {
                let value: f64 = centred[a].iter().zip(&centred[b]).map(|(x, y)| x * y).sum();
                xtx[(ca, cb)] += value;
                if a != b {
                    xtx[(cb, ca)] += value;
                }
            }
        }
    }
    if n == 0 {
        return None;
    }
    let beta = solve(&xtx, &xtr);
    let explained: f64 = beta.iter().zip(xtr.iter()).map(|(b, v)| b * v).sum();
    Some(Fit { beta, ssr_base, ssr: (ssr_base - explained).max(0.0), n, n_touched, ssr_base_touched, touched })
}

/// Solves the normal equations with the columns scaled to unit diagonal; a column without
/// energy, or one that adds nothing independent, gets a zero coefficient.
fn solve(xtx: &DMatrix<f64>, xtr: &DVector<f64>) -> Vec<f64> {
    let p = xtx.nrows();
    let scale: Vec<f64> = (0..p).map(|i| if xtx[(i, i)] > 0.0 { xtx[(i, i)].sqrt() } else { 0.0 }).collect();
    let active: Vec<usize> = (0..p).filter(|&i| scale[i] > 0.0).collect();
    let mut beta = vec![0.0; p];
    if active.is_empty() {
        return beta;
    }
    let k = active.len();
    let a = DMatrix::from_fn(k, k, |i, j| xtx[(active[i], active[j])] / (scale[active[i]] * scale[active[j]]));
    let b = DVector::from_fn(k, |i, _| xtr[active[i]] / scale[active[i]]);
    let svd = a.svd(true, true);
    if let Ok(solution) = svd.solve(&b, 1e-10) {
        for (i, &col) in active.iter().enumerate() {
            beta[col] = solution[i] / scale[col];
        }
    }
    beta
}

/// Held-out gap of one stream before and after subtracting the fitted columns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldoutGap {
    /// Mean square of the residual, before.
    pub mse_before: f64,
    /// Mean square after the effect.
    pub mse_after: f64,
    /// Noise variance (first-difference estimate on the held-out residual).
    pub noise_var: f64,
    /// Samples.
    pub n: usize,
    /// Mean square of the sim's own structural gap over these samples (from its signature; 0
    /// without one): a floor no added effect can remove.
    pub floor_var: f64,
}

impl HeldoutGap {
    /// Gap RMS beyond the noise and the sim's own floor, before: `sqrt(max(MSE - sigma^2 -
    /// floor, 0))`.
    #[must_use]
    pub fn gap_before(&self) -> f64 {
        (self.mse_before - self.noise_var - self.floor_var).max(0.0).sqrt()
    }

    /// Gap RMS beyond the noise and the floor, after.
    #[must_use]
    pub fn gap_after(&self) -> f64 {
        (self.mse_after - self.noise_var - self.floor_var).max(0.0).sqrt()
    }

    /// `1 - gap_after / gap_before` (0 without a gap).
    #[must_use]
    pub fn shrink(&self) -> f64 {
        let before = self.gap_before();
        if before > 0.0 { 1.0 - self.gap_after() / before } else { 0.0 }
    }

    /// Mean square removed, `MSE before - MSE after` (negative when the effect makes it worse).
    #[must_use]
    pub fn removed(&self) -> f64 {
        self.mse_before - self.mse_after
    }

    /// No samples.
    pub const EMPTY: Self = Self { mse_before: 0.0, mse_after: 0.0, noise_var: 0.0, n: 0, floor_var: 0.0 };
}

/// The held-out gap over the runs `touched`, before and after subtracting `sum beta_j x_j`.
#[must_use]
pub fn heldout_gap(segments: &[Segment<'_>], columns: &[Vec<Vec<f64>>], beta: &[f64], touched: &[bool]) -> HeldoutGap {
    gap_over(segments, columns, beta, touched, |segment| segment.heldout.clone().collect())
}

/// The same gap on the selection part.
#[must_use]
pub fn selection_gap(
    segments: &[Segment<'_>],
    columns: &[Vec<Vec<f64>>],
    beta: &[f64],
    touched: &[bool],
) -> HeldoutGap {
    gap_over(segments, columns, beta, touched, |segment| segment.select.samples().collect())
}

fn gap_over(
    segments: &[Segment<'_>],
    columns: &[Vec<Vec<f64>>],
    beta: &[f64],
    touched: &[bool],
    part: impl Fn(&Segment<'_>) -> Vec<usize>,
) -> HeldoutGap {
    let mut gap = GapSums::default();
    for ((segment, cols), &is_touched) in segments.iter().zip(columns).zip(touched) {
        if !is_touched {
            continue;
        }
        gap.next_run();
        for i in part(segment) {
            let effect: f64 = cols.iter().zip(beta).map(|(col, b)| b * col[i]).sum();
            gap.add(i, segment.residual[i], effect);
        }
    }
    gap.finish()
}

/// A part's gap, accumulated sample by sample over its runs: the residual's mean square before
/// and after an effect, and the noise from the differences of neighbouring samples.
#[derive(Debug, Default)]
pub struct GapSums {
    before: f64,
    after: f64,
    n: usize,
    differences: Vec<f64>,
    last: Option<(usize, f64)>,
}

impl GapSums {
    /// A new run starts (no difference across runs).
    pub fn next_run(&mut self) {
        self.last = None;
    }

    /// Sample `idx` of the current run: residual `r` (a non-finite one is skipped and breaks
    /// the neighbours) and the effect's prediction of it.
    pub fn add(&mut self, idx: usize, r: f64, effect: f64) {
        if !r.is_finite() {
            self.last = None;
            return;
        }
        self.before += r * r;
        self.after += (r - effect) * (r - effect);
        self.n += 1;
        // Differences only of neighbours (not across the gap between two selection blocks).
        if let Some((j, prev)) = self.last
            && j + 1 == idx
        {
            self.differences.push(r - prev);
        }
        self.last = Some((idx, r));
    }

    /// The gap (no floor).
    #[must_use]
    pub fn finish(mut self) -> HeldoutGap {
        let mean = |sum: f64, count: usize| if count == 0 { 0.0 } else { sum / count as f64 };
        HeldoutGap {
            mse_before: mean(self.before, self.n),
            mse_after: mean(self.after, self.n),
            noise_var: robust_difference_var(&mut self.differences),
            n: self.n,
            floor_var: 0.0,
        }
    }
}

/// `sigma^2` from first differences `d` of a white noise under a smooth signal: `d` has
/// variance `2 sigma^2`; its scale is taken robustly (1.4826 times the median absolute
/// deviation, Hampel 1974) so that spikes and steps, which are gap, are not counted as noise.
#[must_use]
pub fn robust_difference_var(differences: &mut [f64]) -> f64 {
    let scale = stats::mad_sigma(differences).unwrap_or(0.0);
    0.5 * scale * scale
}

/// Noise variance of a stream from first differences over the training samples (von Neumann):
/// a white measurement noise of variance `s^2` gives differences of variance `2 s^2` while a
/// smooth gap adds almost nothing; the scale is robust ([`robust_difference_var`]).
#[must_use]
pub fn difference_noise_var(segments: &[Segment<'_>], touched: Option<&[bool]>) -> f64 {
    let mut differences = Vec::new();
    for (idx, segment) in segments.iter().enumerate() {
        if touched.is_some_and(|t| !t[idx]) {
            continue;
        }
        for i in segment.training.clone().skip(1) {
            let (a, b) = (segment.residual[i], segment.residual[i - 1]);
            if a.is_finite() && b.is_finite() {
                differences.push(a - b);
            }
        }
    }
    robust_difference_var(&mut differences)
}

/// Integrated autocorrelation time of the centred training residual (Bartlett window over
/// `max_lag` lags, at least 1): `N / tau` is the effective number of independent samples.
#[must_use]
pub fn integrated_autocorrelation(segments: &[Segment<'_>], max_lag: usize) -> f64 {
    let mut acov = vec![0.0; max_lag + 1];
    let mut total = 0usize;
    for segment in segments {
        let values: Vec<f64> =
            segment.training.clone().map(|i| segment.residual[i]).filter(|v| v.is_finite()).collect();
        if values.len() <= max_lag {
            continue;
        }
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        let centred: Vec<f64> = values.iter().map(|v| v - mean).collect();
        for (lag, slot) in acov.iter_mut().enumerate() {
            *slot += centred.iter().zip(&centred[lag..]).map(|(a, b)| a * b).sum::<f64>();
        }
        total += values.len();
    }
    if total == 0 || acov[0] <= 0.0 {
        return 1.0;
    }
    let tau = 1.0
        + 2.0 * (1..=max_lag).map(|lag| (1.0 - lag as f64 / (max_lag + 1) as f64) * acov[lag] / acov[0]).sum::<f64>();
    tau.max(1.0)
}

/// Standard error of the held-out mean square of a segment's residual, `MSE sqrt(2 tau / n)`
/// with `tau = 1 + 2 sum_k (1 - k / (L + 1)) rho(k)^2`, the integrated autocorrelation of the
/// square of a Gaussian series (Priestley, Spectral Analysis and Time Series, 1981, section
/// 5.3: the variance of a sample autocovariance), over lags up to a fifth of the samples.
///
/// Why: the sim's structural error is coloured, so its mean square over a few seconds of one
/// recording scatters from recording to recording far more than white noise would; a gap
/// beyond the sim's own floor counts only outside that scatter.
#[must_use]
pub fn mean_square_standard_error(segment: &Segment<'_>) -> f64 {
    let values: Vec<f64> = segment.heldout.clone().map(|i| segment.residual[i]).filter(|v| v.is_finite()).collect();
    let n = values.len();
    if n < 10 {
        return f64::INFINITY;
    }
    let mean_square = values.iter().map(|v| v * v).sum::<f64>() / n as f64;
    let mean = values.iter().sum::<f64>() / n as f64;
    let centred: Vec<f64> = values.iter().map(|v| v - mean).collect();
    let autocovariance = |lag: usize| centred.iter().zip(&centred[lag..]).map(|(a, b)| a * b).sum::<f64>() / n as f64;
    let variance = autocovariance(0);
    if variance <= 0.0 {
        return 0.0;
    }
    let max_lag = n / 5;
    let tau = 1.0
        + 2.0
            * (1..=max_lag)
                .map(|lag| (1.0 - lag as f64 / (max_lag + 1) as f64) * (autocovariance(lag) / variance).powi(2))
                .sum::<f64>();
    mean_square * (2.0 * tau / n as f64).sqrt()
}

/// Evidence of a fit with `k` parameters over its base, in the Bayesian information criterion
/// (Schwarz, Ann. Stat. 6, 1978) on the effective sample size of a coloured residual:
/// `N_eff ln(SSR_0 / SSR) - k ln N_eff` with `N_eff = N / tau`, `tau` the residual's
/// autocorrelation time in samples.
#[must_use]
pub fn delta_bic(fit: &Fit, autocorrelation_time: f64, k: usize) -> f64 {
    let n_eff = fit.n as f64 / autocorrelation_time.max(1.0);
    if fit.ssr <= 0.0 || fit.ssr_base <= 0.0 || n_eff < 2.0 {
        return 0.0;
    }
    n_eff * (fit.ssr_base / fit.ssr).ln() - k as f64 * n_eff.ln()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The standard error of a mean square against the scatter it predicts: 100 independent
    /// Gaussian series each, white and AR(1) with rho = 0.9; the spread of their mean squares
    /// and the mean predicted standard error agree within 25 % (the scatter of a spread of 100).
    #[test]
    fn mean_square_standard_error_predicts_the_scatter_of_white_and_coloured_series() {
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n = 3000;
        for rho in [0.0f64, 0.9] {
            let (mut squares, mut predicted) = (Vec::new(), Vec::new());
            for _ in 0..100 {
                let mut state = 0.0;
                let series: Vec<f64> = (0..n)
                    .map(|_| {
                        let w: f64 = StandardNormal.sample(&mut rng);
                        state = rho * state + w;
                        state
                    })
                    .collect();
                squares.push(series.iter().map(|v| v * v).sum::<f64>() / n as f64);
                predicted.push(mean_square_standard_error(&Segment {
                    residual: &series,
                    training: 0..0,
                    select: Interleave::default(),
                    heldout: 0..n,
                }));
            }
            let mean = squares.iter().sum::<f64>() / squares.len() as f64;
            let spread = (squares.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (squares.len() - 1) as f64).sqrt();
            let ratio = predicted.iter().sum::<f64>() / predicted.len() as f64 / spread;
            assert!((0.75..1.25).contains(&ratio), "rho {rho}: predicted / observed {ratio}");
        }
    }

    #[test]
    fn recovers_a_coefficient_with_per_run_offsets() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let n = 5000;
        let x: Vec<Vec<f64>> = (0..2).map(|_| (0..n).map(|i| (i as f64 * 0.01).sin()).collect()).collect();
        let r: Vec<Vec<f64>> = (0..2)
            .map(|run| {
                (0..n).map(|i| 0.7 * x[run][i] + run as f64 * 5.0 + 0.01 * (rng.random::<f64>() - 0.5)).collect()
            })
            .collect();
        let segments: Vec<Segment<'_>> = r
            .iter()
            .map(|res| Segment { residual: res, training: 0..4000, select: Interleave::default(), heldout: 4000..n })
            .collect();
        let columns: Vec<Vec<Vec<f64>>> = x.iter().map(|col| vec![col.clone()]).collect();
        let fit = fit(&segments, &columns).unwrap();
        assert!((fit.beta[0] - 0.7).abs() < 1e-3, "{:?}", fit.beta);
        assert!(fit.explained_per_sample() > 0.2);
    }
}

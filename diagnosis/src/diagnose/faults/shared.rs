//! Forms with one parameter shared by every run: a bias, a drift and a wrong gain, each from an
//! onset of each run's own (or none) to the run's end ([`Form`], [`fit_shared`]).

use super::*;

/// A fault form whose size is one value of the channel, shared by every run, with an onset of
/// its own in each run (or none: a run without the fault), lasting to the run's end. The
/// contract's `pressure_fault` (docs/spec/diagnosis.md, What each name covers) is "one channel
/// ... biased, drifting, with a wrong gain ... from the start of a run or from any moment in
/// it": the fault is the channel's (one offset, one rate, one gain), only when it begins is the
/// run's. A level of its own in every run is the pressure model's error from run to run, not a
/// fault (docs/diagnosis.md, Pressure faults).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Form {
    /// A constant `value` added to the reading from the onset.
    Bias,
    /// A ramp `rate_per_s * (t - t_on)` added to the reading from the onset.
    Drift,
    /// The reading is `gain * Cp` from the onset.
    Gain,
}

impl Form {
    /// Every form, in the order they are tried.
    pub const ALL: [Self; 3] = [Self::Bias, Self::Drift, Self::Gain];

    /// The reported `mode`.
    #[must_use]
    pub fn mode(self) -> &'static str {
        match self {
            Self::Bias => "bias",
            Self::Drift => "drift",
            Self::Gain => "gain",
        }
    }

    /// The name of the reported parameter.
    #[must_use]
    pub fn parameter(self) -> &'static str {
        match self {
            Self::Bias => "value",
            Self::Drift => "rate_per_s",
            Self::Gain => "gain",
        }
    }

    /// The reported parameter from the fitted coefficient of `regressor`: a gain `g` adds
    /// `(g - 1)` of the pressure, so `g = 1 + beta`.
    #[must_use]
    pub fn reported(self, beta: f64) -> f64 {
        match self {
            Self::Bias | Self::Drift => beta,
            Self::Gain => 1.0 + beta,
        }
    }
}

/// What the fault adds to the judged innovation at sample `i`, per unit of its parameter, from
/// an onset at `onset_s`: 1 for a bias; `t - t_on` for a drift; for a wrong gain the pressure
/// itself, taken as what the other channels expect of the channel (reading less
/// [`judged`]): a channel reading `g Cp` departs by `(g - 1) Cp` from what the others expect,
/// and their expectation is not pulled by the faulty channel, where the filter's own
/// expectation (reading less its innovation) is.
fn regressor(run: &RunStreams, tap: usize, form: Form, onset_s: f64, i: usize) -> f64 {
    match form {
        Form::Bias => 1.0,
        Form::Drift => run.t_s[i] - onset_s,
        Form::Gain => expected(run, tap, i),
    }
}

/// Suffix sums over one run's usable samples: judged innovation `r`, time `t`, expectation `e`.
#[derive(Debug, Clone, Copy, Default)]
struct Tail {
    n: f64,
    r: f64,
    t: f64,
    tt: f64,
    tr: f64,
    ee: f64,
    er: f64,
}

/// One run's samples of a part for the shared forms, with the sums from each sample on.
struct RunScan {
    samples: Vec<usize>,
    /// `suffix[p]`: sums over `samples[p..]`.
    suffix: Vec<Tail>,
    ssr0: f64,
    n_eff: f64,
}

impl RunScan {
    fn new(run: &RunStreams, tap: usize, candidates: impl Iterator<Item = usize>, tau: f64) -> Option<Self> {
        let r = judged(run, tap);
        let samples: Vec<usize> =
            candidates.filter(|&i| r[i].is_finite() && expected(run, tap, i).is_finite()).collect();
        if samples.len() < 2 * MIN_FAULTY_SAMPLES {
            return None;
        }
        let mut suffix = vec![Tail::default(); samples.len() + 1];
        for (p, &i) in samples.iter().enumerate().rev() {
            let (y, t, e) = (r[i], run.t_s[i], expected(run, tap, i));
            let next = suffix[p + 1];
            suffix[p] = Tail {
                n: next.n + 1.0,
                r: next.r + y,
                t: next.t + t,
                tt: next.tt + t * t,
                tr: next.tr + t * y,
                ee: next.ee + e * e,
                er: next.er + e * y,
            };
        }
        let ssr0 = samples.iter().map(|&i| r[i] * r[i]).sum::<f64>();
        (ssr0 > 0.0).then(|| Self { n_eff: samples.len() as f64 / tau.max(1.0), samples, suffix, ssr0 })
    }

    /// `(sum x y, sum x x)` of the form's regressor `x` and the judged innovation `y` from
    /// position `p` on (onset at that sample's time).
    fn moments(&self, run: &RunStreams, form: Form, p: usize) -> (f64, f64) {
        let s = self.suffix[p];
        match form {
            Form::Bias => (s.r, s.n),
            Form::Drift => {
                let t0 = run.t_s[self.samples[p]];
                (s.tr - t0 * s.r, (s.tt - 2.0 * t0 * s.t + t0 * t0 * s.n).max(0.0))
            }
            Form::Gain => (s.er, s.ee),
        }
    }

    /// Onset positions tried: every sample leaving at least [`MIN_FAULTY_SAMPLES`] after it.
    fn positions(&self) -> std::ops::Range<usize> {
        0..self.samples.len() + 1 - MIN_FAULTY_SAMPLES
    }

    /// The run's evidence for a fault that takes `gain` off its sum of squares: BIC with the
    /// choice of the onset among the samples paid for, and `k` parameters of the run's own.
    fn evidence(&self, gain: f64, k: f64) -> f64 {
        let remaining = (self.ssr0 - gain).max(f64::MIN_POSITIVE);
        self.n_eff * (self.ssr0 / remaining).ln() - k * self.n_eff.ln() - (self.samples.len() as f64).ln()
    }

    /// The run's own best onset with a parameter of its own: `(position, coefficient)`, if
    /// decisive.
    fn own_best(&self, run: &RunStreams, form: Form) -> Option<(usize, f64)> {
        let (p, gain, beta) = self
            .positions()
            .filter_map(|p| {
                let (sxy, sxx) = self.moments(run, form, p);
                (sxx > 0.0).then(|| (p, sxy * sxy / sxx, sxy / sxx))
            })
            .max_by(|a, b| a.1.total_cmp(&b.1))?;
        (self.evidence(gain, 1.0) >= MIN_RUN_DELTA_BIC).then_some((p, beta))
    }

    /// The onset that a fault of the fixed coefficient `beta` fits best, if decisive (no
    /// parameter of the run's own: only the onset is chosen).
    fn onset_for(&self, run: &RunStreams, form: Form, beta: f64) -> Option<usize> {
        let (p, gain) = self
            .positions()
            .map(|p| {
                let (sxy, sxx) = self.moments(run, form, p);
                (p, 2.0 * beta * sxy - beta * beta * sxx)
            })
            .max_by(|a, b| a.1.total_cmp(&b.1))?;
        (gain > 0.0 && self.evidence(gain, 0.0) >= MIN_RUN_DELTA_BIC).then_some(p)
    }
}

/// Most rounds of choosing the onsets for the shared coefficient and re-fitting it.
const SHARED_ROUNDS: usize = 20;

/// A shared-parameter fault fitted on the training part.
#[derive(Debug, Clone, PartialEq)]
pub struct Shared {
    /// The form.
    pub form: Form,
    /// The shared coefficient of `regressor` (the reported parameter is
    /// [`Form::reported`]).
    pub beta: f64,
    /// Per run, the onset time found on the training part, s (`None`: the run has no fault
    /// there); the fault lasts to the run's end.
    pub onset_s: Vec<Option<f64>>,
}

impl Shared {
    /// Runs with the fault.
    #[must_use]
    pub fn runs_with(&self) -> usize {
        self.onset_s.iter().flatten().count()
    }

    /// The earliest onset, s.
    #[must_use]
    pub fn start_s(&self) -> f64 {
        self.onset_s.iter().flatten().copied().fold(f64::INFINITY, f64::min)
    }

    /// Seconds the fault holds, summed over the runs.
    #[must_use]
    pub fn faulty_s(&self, runs: &[RunStreams]) -> f64 {
        runs.iter()
            .zip(&self.onset_s)
            .filter_map(|(run, onset)| {
                onset.map(|t0| run.t_s.iter().filter(|&&t| t >= t0).count() as f64 / run.sample_hz)
            })
            .sum()
    }

    /// The fault's column per run for [`regression::fit_through_origin`] on [`segments_judged`].
    #[must_use]
    pub fn columns(&self, runs: &[RunStreams], tap: usize) -> Vec<Vec<Vec<f64>>> {
        runs.iter().zip(&self.onset_s).map(|(run, onset)| vec![column(run, tap, self.form, *onset)]).collect()
    }
}

/// The regressor of `form` from `onset_s` to the run's end (zero before it, and where it is not
/// finite).
fn column(run: &RunStreams, tap: usize, form: Form, onset_s: Option<f64>) -> Vec<f64> {
    (0..run.len())
        .map(|i| match onset_s {
            Some(t0) if run.t_s[i] >= t0 => {
                Some(regressor(run, tap, form, t0, i)).filter(|v| v.is_finite()).unwrap_or(0.0)
            }
            _ => 0.0,
        })
        .collect()
}

/// Fits a fault of `form` with one coefficient for every run and an onset per run on the
/// training part; `tau` is the judged innovation's integrated autocorrelation time (samples).
///
/// The coefficient starts at the median of the runs' own decisive coefficients; then, in turn,
/// each run takes the onset that the coefficient fits best (none unless decisive in that run),
/// and the coefficient is re-fitted over the runs' faulty samples, until the onsets hold. The
/// fault is one value: a run whose own coefficient is decisive but disagrees with the shared
/// one by more than `AGREEMENT_FACTOR` (or in sign) refutes it.
#[must_use]
pub fn fit_shared(runs: &[RunStreams], tap: usize, form: Form, tau: f64) -> Option<Shared> {
    let scans: Vec<Option<RunScan>> = runs.iter().map(|run| RunScan::new(run, tap, run.fit_samples(), tau)).collect();
    let own: Vec<Option<(usize, f64)>> =
        runs.iter().zip(&scans).map(|(run, scan)| scan.as_ref().and_then(|s| s.own_best(run, form))).collect();
    let mut betas: Vec<f64> = own.iter().flatten().map(|(_, b)| *b).collect();
    betas.sort_by(f64::total_cmp);
    let mut beta = *betas.get(betas.len() / 2)?;
    let mut onsets: Vec<Option<usize>> = vec![None; runs.len()];
    for _ in 0..SHARED_ROUNDS {
        let next: Vec<Option<usize>> = runs
            .iter()
            .zip(&scans)
            .map(|(run, scan)| scan.as_ref().and_then(|s| s.onset_for(run, form, beta)))
            .collect();
        let (sxy, sxx) =
            runs.iter().zip(&scans).zip(&next).fold((0.0, 0.0), |acc, ((run, scan), onset)| match (scan, onset) {
                (Some(s), Some(p)) => {
                    let (xy, xx) = s.moments(run, form, *p);
                    (acc.0 + xy, acc.1 + xx)
                }
                _ => acc,
            });
        if sxx <= 0.0 {
            return None;
        }
        beta = sxy / sxx;
        let settled = next == onsets;
        onsets = next;
        if settled {
            break;
        }
    }
    let agrees = |own: f64| {
        let ratio = own / beta;
        (1.0 / AGREEMENT_FACTOR..=AGREEMENT_FACTOR).contains(&ratio)
    };
    if own.iter().flatten().any(|(_, b)| !agrees(*b)) || onsets.iter().all(Option::is_none) {
        return None;
    }
    let onset_s = runs
        .iter()
        .zip(&scans)
        .zip(&onsets)
        .map(|((run, scan), onset)| Some(run.t_s[scan.as_ref()?.samples[(*onset)?]]))
        .collect();
    Some(Shared { form, beta, onset_s })
}

/// The gap of a shared-parameter fault's judged innovation over a part of every run (the
/// selection blocks or the held-out part), with nothing fitted on the part: the coefficient
/// is the training one; a run whose training part found the onset keeps it (the fault lasts
/// to the run's end), and in a run whose training part had none the same detector with the
/// coefficient fixed (`RunScan::onset_for`, its threshold and `tau` from training) looks for
/// an onset in the part (a fault may begin at any moment, the held-out part's too). Choosing
/// an onset with everything else fixed fits nothing; a healthy part gives none, and no shrink.
#[must_use]
pub fn shared_part_gap(
    runs: &[RunStreams],
    tap: usize,
    shared: &Shared,
    tau: f64,
    heldout: bool,
) -> regression::HeldoutGap {
    let mut gap = regression::GapSums::default();
    for (run_idx, run) in runs.iter().enumerate() {
        let samples: Vec<usize> = if heldout { run.heldout.clone().collect() } else { run.select.samples().collect() };
        let r = judged(run, tap);
        let onset = shared.onset_s.get(run_idx).copied().flatten().or_else(|| {
            let scan = RunScan::new(run, tap, samples.iter().copied(), tau)?;
            scan.onset_for(run, shared.form, shared.beta).map(|p| run.t_s[scan.samples[p]])
        });
        gap.next_run();
        for &i in &samples {
            let predicted = match onset {
                Some(t0) if run.t_s[i] >= t0 => shared.beta * regressor(run, tap, shared.form, t0, i),
                _ => 0.0,
            };
            gap.add(i, r[i], if predicted.is_finite() { predicted } else { 0.0 });
        }
    }
    gap.finish()
}

/// Segments of one channel's judged innovation ([`RunStreams::departure_alone`]) in every run.
#[must_use]
pub fn segments_judged(runs: &[RunStreams], tap: usize) -> Vec<Segment<'_>> {
    segments_over(runs, |run| judged(run, tap))
}

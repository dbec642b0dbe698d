//! A stuck (or flat-dead) channel: an interval per run where the reading stops following the
//! pressure and holds a constant with its transducer's noise ([`scan`]).

use super::*;

/// Slopes on the expectation that count as a reading that no longer follows the pressure (the
/// filter's own correction pulls the expectation a little towards the stuck reading).
const STUCK_SLOPE: (f64, f64) = (-1.5, -0.3);

/// Largest share of the expectation's smoothed variance a stuck reading may keep over its
/// interval: a stuck reading keeps only its noise (a few per cent after smoothing), a live
/// reading mapped with a wrong gain `g` keeps `g^2` (0.25 at half the gain).
const STUCK_FLATNESS: f64 = 0.1;

/// Largest ratio of the smoothed reading's variance over its interval to what the reading's own
/// noise alone would leave after the same smoothing (its white variance from first differences,
/// over the window's length). A stuck reading is a constant with its transducer's noise
/// (docs/spec/diagnosis.md, pressure_fault), so the ratio is 1 for white noise and stays
/// below 10 for noise correlated up to 0.6 from sample to sample (an AR(1) noise of
/// correlation rho leaves (1 + rho) / (1 - rho)^2 times more). A live channel moves with the
/// flow, tens of times above its smoothed noise: a channel that moves less than the filter
/// expects is not stuck while it still moves.
const STUCK_NOISE_FLATNESS: f64 = 10.0;

/// Half-width of the moving average that smooths reading and expectation for the flatness test,
/// s: the noise falls by the window's length, the flow's motion (a few hertz) stays.
const SMOOTHING_HALF_S: f64 = 0.01;

/// The shape of an interval fault (bias, drift and gain are [`Form`]s with one value for every
/// run, lasting to the run's end).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// A constant reading (with noise) over the interval.
    Stuck,
}

/// The scan's result: each run's interval (sample indices) or none, and the regression columns.
#[derive(Debug, Clone)]
pub struct Onsets {
    /// Per run, the faulty samples `start..end`.
    pub per_run: Vec<Option<std::ops::Range<usize>>>,
    /// The columns of the fault for [`regression::fit_through_origin`]: for a stuck reading, the
    /// shared slope on the expectation, then one level per run.
    pub columns: Vec<Vec<Vec<f64>>>,
}

/// Scans every run of channel `tap` for the interval of `shape`; `tau` is the innovation's
/// integrated autocorrelation time (samples), for the effective number of samples.
#[must_use]
pub fn scan(runs: &[RunStreams], tap: usize, shape: Shape, tau: f64) -> Onsets {
    let per_run: Vec<Option<std::ops::Range<usize>>> =
        runs.iter().map(|run| best_interval(run, tap, shape, tau)).collect();
    let n_runs = runs.len();
    let columns = runs
        .iter()
        .zip(&per_run)
        .enumerate()
        .map(|(run_idx, (run, interval))| {
            let n = run.len();
            let inside = |i: usize| interval.as_ref().is_some_and(|r| r.contains(&i));
            let step: Vec<f64> = (0..n).map(|i| if inside(i) { 1.0 } else { 0.0 }).collect();
            let levels = (0..n_runs).map(|slot| if slot == run_idx { step.clone() } else { vec![0.0; n] });
            match shape {
                Shape::Stuck => {
                    let expected = expectation(run, tap);
                    let mean = mean_of(run.fit_samples().filter(|&i| inside(i)).map(|i| expected[i]));
                    let slope = (0..n)
                        .map(|i| if inside(i) && expected[i].is_finite() { expected[i] - mean } else { 0.0 })
                        .collect();
                    std::iter::once(slope).chain(levels).collect()
                }
            }
        })
        .collect();
    Onsets { per_run, columns }
}

/// Sums over one grid cell's usable samples: innovation `y`, expectation `x`, the smoothed
/// reading `r` and expectation `e` of the flatness test, and the squared first differences `dd`
/// of the raw reading (over `nd` pairs) for its noise.
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    n: f64,
    y: f64,
    yy: f64,
    x: f64,
    xx: f64,
    xy: f64,
    r: f64,
    rr: f64,
    e: f64,
    ee: f64,
    dd: f64,
    nd: f64,
}

impl Sums {
    fn add(&mut self, other: &Self) {
        self.n += other.n;
        self.y += other.y;
        self.yy += other.yy;
        self.x += other.x;
        self.xx += other.xx;
        self.xy += other.xy;
        self.r += other.r;
        self.rr += other.rr;
        self.e += other.e;
        self.ee += other.ee;
        self.dd += other.dd;
        self.nd += other.nd;
    }

    fn minus(&self, other: &Self) -> Self {
        Self {
            n: self.n - other.n,
            y: self.y - other.y,
            yy: self.yy - other.yy,
            x: self.x - other.x,
            xx: self.xx - other.xx,
            xy: self.xy - other.xy,
            r: self.r - other.r,
            rr: self.rr - other.rr,
            e: self.e - other.e,
            ee: self.ee - other.ee,
            dd: self.dd - other.dd,
            nd: self.nd - other.nd,
        }
    }

    fn var(sum: f64, sq: f64, n: f64) -> f64 {
        if n > 0.0 { (sq - sum * sum / n).max(0.0) } else { 0.0 }
    }
}

/// The interval with the most evidence for `shape` in one run's training part, if decisive.
fn best_interval(run: &RunStreams, tap: usize, shape: Shape, tau: f64) -> Option<std::ops::Range<usize>> {
    let samples: Vec<usize> = run.fit_samples().collect();
    let found = best_interval_over(run, tap, shape, tau, &samples)?;
    // An interval that runs to the end of the training part runs on to the end of the run (the
    // held-out part), one from its first sample from the start.
    let usable = usable_samples(run, tap, &samples);
    let start = if usable.first() == Some(&found.start) { 0 } else { found.start };
    let end = if usable.last().map(|last| last + 1) == Some(found.end) { run.len() } else { found.end };
    Some(start..end)
}

/// The samples of `candidates` where both the innovation and the expectation are finite.
fn usable_samples(run: &RunStreams, tap: usize, candidates: &[usize]) -> Vec<usize> {
    let nu = &run.innovation[tap];
    candidates.iter().copied().filter(|&i| nu[i].is_finite() && (run.cp[tap][i] - nu[i]).is_finite()).collect()
}

/// The interval of `shape` with the most evidence over `samples`, if decisive: from the first
/// to the last of the samples that chose it.
///
/// The samples are cut into [`GRID`] cells of equal count (so a part made of interleaved
/// blocks is scanned at the same resolution as a contiguous one), every run of whole cells is
/// scored, and the best one's two ends are then moved sample by sample within a cell of where
/// they were (a fault starts where it starts, not on a cell edge).
fn best_interval_over(
    run: &RunStreams,
    tap: usize,
    shape: Shape,
    tau: f64,
    samples: &[usize],
) -> Option<std::ops::Range<usize>> {
    let nu = &run.innovation[tap];
    let expected = expectation(run, tap);
    let samples = usable_samples(run, tap, samples);
    let m = samples.len();
    if m < 20 {
        return None;
    }
    let half = ((SMOOTHING_HALF_S * run.sample_hz).round() as usize).max(1);
    let (reading, smooth_expected) = (moving_average(&run.cp[tap], half), moving_average(&expected, half));
    let window = (2 * half + 1) as f64;
    // Prefix sums over the samples: the sums of any stretch in constant time.
    let mut prefix = Vec::with_capacity(m + 1);
    prefix.push(Sums::default());
    for &i in &samples {
        let (y, x, r, e) = (nu[i], expected[i], reading[i], smooth_expected[i]);
        let (r, e) = if r.is_finite() && e.is_finite() { (r, e) } else { (x, x) };
        let step = i.checked_sub(1).map_or(f64::NAN, |before| run.cp[tap][i] - run.cp[tap][before]);
        let (dd, nd) = if step.is_finite() { (step * step, 1.0) } else { (0.0, 0.0) };
        let mut next = *prefix.last().unwrap_or(&Sums::default());
        next.add(&Sums { n: 1.0, y, yy: y * y, x, xx: x * x, xy: x * y, r, rr: r * r, e, ee: e * e, dd, nd });
        prefix.push(next);
    }
    let stretch = |a: usize, b: usize| prefix[b].minus(&prefix[a]);
    let total = stretch(0, m);
    let ssr0 = Sums::var(total.y, total.yy, total.n);
    if ssr0 <= 0.0 {
        return None;
    }
    let gain_of = |a: usize, b: usize| -> f64 {
        let inside = stretch(a, b);
        if inside.n < 10.0 {
            return 0.0;
        }
        match shape {
            Shape::Stuck => {
                let sxx = Sums::var(inside.x, inside.xx, inside.n);
                let sxy = inside.xy - inside.x * inside.y / inside.n;
                let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
                // How much the smoothed reading moves, past the first window (which straddles
                // the onset), against the white noise variance of the reading left after the
                // same smoothing.
                let settled = stretch((a + half).min(b - 1), b);
                let moved = Sums::var(settled.r, settled.rr, settled.n) / settled.n;
                let noise_left = if inside.nd > 0.0 { inside.dd / (2.0 * inside.nd) / window } else { 0.0 };
                let flat = Sums::var(inside.r, inside.rr, inside.n)
                    <= STUCK_FLATNESS * Sums::var(inside.e, inside.ee, inside.n)
                    // (A bit-identical reading leaves no noise: only the sums' rounding.)
                    && moved <= STUCK_NOISE_FLATNESS * noise_left + 1e-9 * settled.rr / settled.n;
                if (STUCK_SLOPE.0..=STUCK_SLOPE.1).contains(&slope) && flat { sxy * sxy / sxx } else { 0.0 }
            }
        }
    };
    let edge = |cell: usize| cell * m / GRID;
    let mut best: Option<((usize, usize), f64)> = None;
    // The contract's fault lasts from its onset (the run's start or any moment in it) to the
    // run's end (docs/spec/diagnosis.md, pressure_fault): only intervals to the samples' end.
    for first in 0..GRID {
        for last in GRID - 1..GRID {
            let (a, b) = (edge(first), edge(last + 1));
            let gain = gain_of(a, b);
            if gain > 0.0 && best.as_ref().is_none_or(|(_, g)| gain > *g) {
                best = Some(((a, b), gain));
            }
        }
    }
    let ((mut a, mut b), mut gain) = best?;
    // An end at the part's own end stays there: a fault from the start (or to the end) is a
    // claim of its own, not a cell edge to refine.
    let cell = m.div_ceil(GRID);
    let (fixed_start, fixed_end) = (a == 0, b == m);
    for candidate in (a.saturating_sub(cell)..(a + cell).min(b)).filter(|_| !fixed_start) {
        let g = gain_of(candidate, b);
        if g > gain {
            (a, gain) = (candidate, g);
        }
    }
    for candidate in ((b.saturating_sub(cell).max(a + 1))..=(b + cell).min(m)).filter(|_| !fixed_end) {
        let g = gain_of(a, candidate);
        if g > gain {
            (b, gain) = (candidate, g);
        }
    }
    let remaining = (ssr0 - gain).max(f64::MIN_POSITIVE);
    // Up to two parameters (a level, and a stuck reading's slope), and the choice of the
    // interval among GRID (GRID + 1) / 2.
    let choices = GRID as f64;
    let n_eff = m as f64 / tau.max(1.0);
    let evidence = n_eff * (ssr0 / remaining).ln() - 2.0 * n_eff.ln() - choices.ln();
    (evidence >= MIN_RUN_DELTA_BIC).then(|| samples[a]..samples[b - 1] + 1)
}

/// What the training part fixed of a stuck channel, for judging it on the other parts: per run,
/// the interval found there and the reading the channel froze at.
#[derive(Debug, Clone, PartialEq)]
pub struct Trained {
    /// Per run, the interval found on the training part (it runs on into the held-out part
    /// when it reached the training part's end).
    pub per_run: Vec<Option<std::ops::Range<usize>>>,
    /// Per run, the reading the stuck channel froze at on the training part.
    pub levels: Vec<Option<f64>>,
}

impl Trained {
    /// From the scan on the training part: for a stuck channel, the mean reading over the
    /// run's training interval.
    #[must_use]
    pub fn new(runs: &[RunStreams], tap: usize, shape: Shape, onsets: &Onsets) -> Self {
        let levels = runs
            .iter()
            .zip(&onsets.per_run)
            .map(|(run, interval)| {
                let interval = interval.as_ref()?;
                match shape {
                    Shape::Stuck => {
                        let reading =
                            mean_of(run.fit_samples().filter(|i| interval.contains(i)).map(|i| run.cp[tap][i]));
                        reading.is_finite().then_some(reading)
                    }
                }
            })
            .collect();
        Self { per_run: onsets.per_run.clone(), levels }
    }
}

/// Samples of a stuck reading's onset whose mean is its frozen value, s.
const FROZEN_ONSET_S: f64 = 0.01;

/// The gap of channel `tap` over a part of every run (the selection blocks or the held-out
/// part) before and after the fault the training part fixed (`trained`), with nothing fitted
/// on the part.
///
/// Where: a fault that comes and goes (a loose connector, a tube that clears) is not
/// predictable in time, so the fault acts where the training part's interval reaches into the
/// part and wherever the same detector (`best_interval_over`, its thresholds and the
/// innovation's autocorrelation time `tau` fixed on the training part) finds it in the part.
/// Running a fixed detector fits nothing. How much: nothing is estimated on the part. A stuck
/// channel reads its frozen value, the training one when the
/// interval continues the run's training interval, else the reading at the onset the detector
/// names (the mean of its first `FROZEN_ONSET_S`), the value it froze at. The innovation is
/// the reading less the filter's expectation, so a stuck channel's predicted innovation is the
/// frozen value less the expectation. A healthy channel gives no interval and no shrink; a
/// level that differs in the part is not re-fitted, so the part's gap shows it.
#[must_use]
pub fn part_gap(
    runs: &[RunStreams],
    tap: usize,
    shape: Shape,
    tau: f64,
    trained: &Trained,
    heldout: bool,
) -> regression::HeldoutGap {
    let mut gap = regression::GapSums::default();
    for (run_idx, run) in runs.iter().enumerate() {
        let samples: Vec<usize> = if heldout { run.heldout.clone().collect() } else { run.select.samples().collect() };
        let usable = usable_samples(run, tap, &samples);
        let nu = &run.innovation[tap];
        let expected = expectation(run, tap);
        let from_training = trained.per_run.get(run_idx).cloned().flatten();
        let found = best_interval_over(run, tap, shape, tau, &usable);
        let in_training = |i: &usize| from_training.as_ref().is_some_and(|range| range.contains(i));
        let in_found = |i: &usize| found.as_ref().is_some_and(|range| range.contains(i));
        let own_level = trained.levels.get(run_idx).copied().flatten();
        let level = match shape {
            Shape::Stuck => {
                let continues = found.as_ref().is_none_or(|range| {
                    from_training.as_ref().is_some_and(|t| t.contains(&range.start) || t.end == range.start)
                });
                if continues {
                    own_level
                } else {
                    let onset = found.as_ref().map_or(0, |range| range.start);
                    let width = ((FROZEN_ONSET_S * run.sample_hz).round() as usize).max(1);
                    let frozen = mean_of(usable.iter().filter(|&&i| i >= onset).take(width).map(|&i| run.cp[tap][i]));
                    frozen.is_finite().then_some(frozen)
                }
            }
        };
        gap.next_run();
        for &i in &usable {
            let predicted = match (level, in_training(&i) || in_found(&i)) {
                (Some(level), true) => match shape {
                    Shape::Stuck => level - expected[i],
                },
                _ => 0.0,
            };
            gap.add(i, nu[i], predicted);
        }
    }
    gap.finish()
}

/// Whether a fitted stuck shape really stopped following the pressure (its shared slope).
#[must_use]
pub fn stuck_slope_holds(fit: &regression::Fit) -> bool {
    fit.beta.first().is_some_and(|slope| (STUCK_SLOPE.0..=STUCK_SLOPE.1).contains(slope))
}

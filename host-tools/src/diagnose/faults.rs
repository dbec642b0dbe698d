//! Where a pressure-channel fault acts in each run (the `pressure_fault` family, shared/spec/
//! diagnosis.md): a fault can start at any time and end again (a loose connector, a tube that
//! clears), in any run, or be there throughout; each run gets its own interval, or none, chosen
//! on the training part by the evidence of the fault's shape in that run alone.
//!
//! Two shapes are scanned. A bias adds a constant to the reading over its interval: the
//! innovation's mean steps (by a value of its own in each run), or sits off zero over the whole
//! run (an offset from the start). A stuck (or flat-dead) channel
//! stops following the pressure and reads a constant with its transducer's noise: over the
//! interval the innovation is that constant less the filter's expectation of the channel, so it
//! regresses on the expectation with a slope near -1 (a live channel: near 0), and the reading,
//! smoothed, stays flat where the expectation moves. Flatness is what tells a stuck channel from
//! one the sim maps with too large a gain (its innovation too regresses on the expectation, but
//! its reading still follows the pressure). Bit-identical repeats are the noise-free case of the
//! same shape.

use super::regression::{self, Segment};
use super::streams::RunStreams;

/// Interval ends scanned per run: this many cells, evenly spaced over the run; an interval is
/// any run of whole cells.
const GRID: usize = 40;

/// Evidence a run needs for its own interval (BIC, with the choice of the interval paid for).
const MIN_RUN_DELTA_BIC: f64 = 10.0;

/// Slopes on the expectation that count as a reading that no longer follows the pressure (the
/// filter's own correction pulls the expectation a little towards the stuck reading).
const STUCK_SLOPE: (f64, f64) = (-1.5, -0.3);

/// Largest share of the expectation's smoothed variance a stuck reading may keep over its
/// interval: a stuck reading keeps only its noise (a few per cent after smoothing), a live
/// reading mapped with a wrong gain `g` keeps `g^2` (0.25 at half the gain).
const STUCK_FLATNESS: f64 = 0.1;

/// Half-width of the moving average that smooths reading and expectation for the flatness test,
/// s: the noise falls by the window's length, the flow's motion (a few hertz) stays.
const SMOOTHING_HALF_S: f64 = 0.01;

/// The shape of a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// A constant added over the interval.
    Bias,
    /// A constant reading (with noise) over the interval.
    Stuck,
}

/// The scan's result: each run's interval (sample indices) or none, and the regression columns.
#[derive(Debug, Clone)]
pub struct Onsets {
    /// Per run, the faulty samples `start..end`.
    pub per_run: Vec<Option<std::ops::Range<usize>>>,
    /// The columns of the fault for [`regression::fit_through_origin`]: for a bias, one level per
    /// run; for a stuck reading, the shared slope on the expectation, then one level per run.
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
                Shape::Bias => levels.collect(),
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

/// The filter's one-step expectation of the channel (reading less innovation).
fn expectation(run: &RunStreams, tap: usize) -> Vec<f64> {
    run.cp[tap].iter().zip(&run.innovation[tap]).map(|(cp, nu)| cp - nu).collect()
}

fn mean_of(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.filter(|v| v.is_finite()).fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// A centred moving average of `half` samples each side over the finite values (NaN where the
/// window holds none).
fn moving_average(values: &[f64], half: usize) -> Vec<f64> {
    let (mut sum, mut count) = (vec![0.0; values.len() + 1], vec![0usize; values.len() + 1]);
    for (i, v) in values.iter().enumerate() {
        let finite = v.is_finite();
        sum[i + 1] = sum[i] + if finite { *v } else { 0.0 };
        count[i + 1] = count[i] + usize::from(finite);
    }
    (0..values.len())
        .map(|i| {
            let (lo, hi) = (i.saturating_sub(half), (i + half + 1).min(values.len()));
            let n = count[hi] - count[lo];
            if n == 0 { f64::NAN } else { (sum[hi] - sum[lo]) / n as f64 }
        })
        .collect()
}

/// Sums over one grid cell's usable samples: innovation `y`, expectation `x`, and the smoothed
/// reading `r` and expectation `e` of the flatness test.
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
    // Prefix sums over the samples: the sums of any stretch in constant time.
    let mut prefix = Vec::with_capacity(m + 1);
    prefix.push(Sums::default());
    for &i in &samples {
        let (y, x, r, e) = (nu[i], expected[i], reading[i], smooth_expected[i]);
        let (r, e) = if r.is_finite() && e.is_finite() { (r, e) } else { (x, x) };
        let mut next = *prefix.last().unwrap_or(&Sums::default());
        next.add(&Sums { n: 1.0, y, yy: y * y, x, xx: x * x, xy: x * y, r, rr: r * r, e, ee: e * e });
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
            // A level inside, zero outside (a healthy channel's innovation has no mean): the
            // fault's own column, so that an interval over part of the run and one over all of
            // it (an offset from the start) compete on the same footing.
            Shape::Bias => inside.y * inside.y / inside.n,
            Shape::Stuck => {
                let sxx = Sums::var(inside.x, inside.xx, inside.n);
                let sxy = inside.xy - inside.x * inside.y / inside.n;
                let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
                let flat = Sums::var(inside.r, inside.rr, inside.n)
                    <= STUCK_FLATNESS * Sums::var(inside.e, inside.ee, inside.n);
                if (STUCK_SLOPE.0..=STUCK_SLOPE.1).contains(&slope) && flat { sxy * sxy / sxx } else { 0.0 }
            }
        }
    };
    let edge = |cell: usize| cell * m / GRID;
    let mut best: Option<((usize, usize), f64)> = None;
    for first in 0..GRID {
        for last in first..GRID {
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
    let choices = (GRID * (GRID + 1) / 2) as f64;
    let n_eff = m as f64 / tau.max(1.0);
    let evidence = n_eff * (ssr0 / remaining).ln() - 2.0 * n_eff.ln() - choices.ln();
    (evidence >= MIN_RUN_DELTA_BIC).then(|| samples[a]..samples[b - 1] + 1)
}

/// What the training part fixed of a fault, for judging it on the other parts: per run, the
/// interval found there and the fault's level (a bias's constant, a stuck channel's frozen
/// reading), and the level for a run whose training part had none.
#[derive(Debug, Clone, PartialEq)]
pub struct Trained {
    /// Per run, the interval found on the training part (it runs on into the held-out part
    /// when it reached the training part's end).
    pub per_run: Vec<Option<std::ops::Range<usize>>>,
    /// Per run, the level fitted on the training part: the bias added to the reading, or the
    /// reading a stuck channel froze at.
    pub levels: Vec<Option<f64>>,
}

impl Trained {
    /// From the scan on the training part and the fitted coefficients of its columns
    /// ([`Onsets::columns`]): a bias's level per run; for a stuck channel, the mean reading over
    /// the run's training interval.
    #[must_use]
    pub fn new(runs: &[RunStreams], tap: usize, shape: Shape, onsets: &Onsets, beta: &[f64]) -> Self {
        let levels = runs
            .iter()
            .zip(&onsets.per_run)
            .enumerate()
            .map(|(run_idx, (run, interval))| {
                let interval = interval.as_ref()?;
                match shape {
                    Shape::Bias => beta.get(run_idx).copied(),
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

    /// The level for a run without its own: the median of the runs' levels.
    fn typical(&self) -> Option<f64> {
        let mut levels: Vec<f64> = self.levels.iter().flatten().copied().collect();
        levels.sort_by(f64::total_cmp);
        levels.get(levels.len() / 2).copied()
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
/// part and wherever the same detector ([`best_interval_over`], its thresholds and the
/// innovation's autocorrelation time `tau` fixed on the training part) finds it in the part.
/// Running a fixed detector fits nothing. How much: nothing is estimated on the part. A bias
/// keeps its training level (the run's own, or the median over the runs for a run whose
/// training part had none); a stuck channel reads its frozen value, the training one when the
/// interval continues the run's training interval, else the reading at the onset the detector
/// names (the mean of its first [`FROZEN_ONSET_S`]), the value it froze at. The innovation is
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
    let typical = trained.typical();
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
            Shape::Bias => own_level.or(typical),
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
                    Shape::Bias => level,
                    Shape::Stuck => level - expected[i],
                },
                _ => 0.0,
            };
            gap.add(i, nu[i], predicted);
        }
    }
    gap.finish()
}

/// Segments of one channel's innovation (for the fit of the fault's columns).
#[must_use]
pub fn segments_of(runs: &[RunStreams], tap: usize) -> Vec<Segment<'_>> {
    segments_over(runs, |run| &run.innovation[tap])
}

/// Segments of one stream of every run (`stream(run)`), with each run's split.
pub fn segments_over<'a>(runs: &'a [RunStreams], stream: impl Fn(&'a RunStreams) -> &'a [f64]) -> Vec<Segment<'a>> {
    segments_with(runs, runs.iter().map(stream))
}

/// Segments of the given streams, one per run in order, with each run's split.
pub fn segments_with<'a>(runs: &'a [RunStreams], streams: impl IntoIterator<Item = &'a [f64]>) -> Vec<Segment<'a>> {
    runs.iter()
        .zip(streams)
        .map(|(run, residual)| Segment {
            residual,
            training: run.training.clone(),
            select: run.select,
            heldout: run.heldout.clone(),
        })
        .collect()
}

/// Whether a fitted stuck shape really stopped following the pressure (its shared slope).
#[must_use]
pub fn stuck_slope_holds(fit: &regression::Fit) -> bool {
    fit.beta.first().is_some_and(|slope| (STUCK_SLOPE.0..=STUCK_SLOPE.1).contains(slope))
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    use super::*;
    use crate::diagnose::streams::synthetic_run;

    const HZ: f64 = 1000.0;
    const DURATION_S: f64 = 20.0;
    const NOISE: f64 = 0.01;

    /// One channel whose expectation is a 2 Hz swing of 0.3 and whose reading is
    /// `reading(t_s, expected)` plus transducer noise (seeded).
    fn run_with(seed: u64, reading: impl Fn(f64, f64) -> f64) -> RunStreams {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, NOISE).expect("a valid deviation");
        let n = (DURATION_S * HZ) as usize;
        let (mut cp, mut nu) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for i in 0..n {
            let t_s = i as f64 / HZ;
            let expected = 0.3 * (std::f64::consts::TAU * 2.0 * t_s).sin() - 0.5;
            let value = reading(t_s, expected) + noise.sample(&mut rng);
            cp.push(value);
            nu.push(value - expected);
        }
        synthetic_run(HZ, vec![cp], vec![nu])
    }

    fn interval_s(run: &RunStreams, shape: Shape) -> Option<(f64, f64)> {
        let onsets = scan(std::slice::from_ref(run), 0, shape, 1.0);
        onsets.per_run[0].clone().map(|r| (r.start as f64 / HZ, r.end as f64 / HZ))
    }

    /// One grid cell, s: the resolution of the scan (before the trim to the fit samples).
    const CELL_S: f64 = DURATION_S / GRID as f64;

    #[test]
    fn a_channel_stuck_for_a_while_is_found_over_that_while() {
        let run = run_with(1, |t_s, e| if (6.0..11.0).contains(&t_s) { -0.4 } else { e });
        let (start, end) = interval_s(&run, Shape::Stuck).expect("a stuck interval");
        assert!((start - 6.0).abs() <= CELL_S + 0.3, "start {start} s");
        assert!((end - 11.0).abs() <= CELL_S + 0.3, "end {end} s");
    }

    #[test]
    fn a_channel_stuck_to_the_end_of_training_stays_stuck_in_the_held_out_part() {
        let run = run_with(2, |t_s, e| if t_s >= 9.0 { -0.4 } else { e });
        let (start, end) = interval_s(&run, Shape::Stuck).expect("a stuck interval");
        assert!((start - 9.0).abs() <= CELL_S + 0.3, "start {start} s");
        assert!((end - DURATION_S).abs() < 1e-9, "end {end} s: runs on into the held-out part");
    }

    #[test]
    fn a_live_channel_read_at_half_its_gain_is_not_stuck() {
        // Its innovation regresses on the expectation with slope -0.5 (inside the stuck band):
        // only the flatness of the reading tells the two apart.
        let run = run_with(3, |_, e| 0.5 * e - 0.25);
        assert_eq!(interval_s(&run, Shape::Stuck), None);
    }

    #[test]
    fn a_bias_over_part_of_a_run_is_found_over_that_part_and_one_from_the_start_over_the_run() {
        let part = run_with(4, |t_s, e| if (4.0..13.0).contains(&t_s) { e + 0.02 } else { e });
        let (start, end) = interval_s(&part, Shape::Bias).expect("a bias interval");
        assert!((start - 4.0).abs() <= CELL_S + 0.3, "start {start} s, end {end} s");
        assert!((end - 13.0).abs() <= CELL_S + 0.3, "end {end} s");
        let whole = run_with(5, |_, e| e + 0.02);
        assert_eq!(interval_s(&whole, Shape::Bias), Some((0.0, DURATION_S)));
    }

    #[test]
    fn a_healthy_channel_has_no_fault() {
        let run = run_with(6, |_, e| e);
        assert_eq!(interval_s(&run, Shape::Stuck), None);
        assert_eq!(interval_s(&run, Shape::Bias), None);
    }

    /// Nothing fitted: no interval in the training part, the level the training part would
    /// have fixed.
    fn untrained(level: f64) -> Trained {
        Trained { per_run: vec![None], levels: vec![Some(level)] }
    }

    /// A fault that comes and goes is found again in the part it is judged on by the fixed
    /// detector: a channel stuck for one second inside the held-out part only (the training
    /// part never saw it) shrinks the held-out gap by most of it, read at the value it froze
    /// at; the same detector on a healthy channel finds nothing there and changes nothing.
    #[test]
    fn a_fault_inside_the_held_out_part_is_found_there_and_a_healthy_channel_is_left_alone() {
        let runs = [run_with(9, |t_s, e| if (17.0..18.0).contains(&t_s) { -0.4 } else { e })];
        assert_eq!(scan(&runs, 0, Shape::Stuck, 1.0).per_run[0], None, "not in the training part");
        let gap = part_gap(&runs, 0, Shape::Stuck, 1.0, &Trained { per_run: vec![None], levels: vec![None] }, true);
        assert!(gap.shrink() > 0.8, "held-out shrink {}", gap.shrink());
        let bias = part_gap(
            &[run_with(10, |t_s, e| if t_s >= 18.5 { e + 0.05 } else { e })],
            0,
            Shape::Bias,
            1.0,
            &untrained(0.05),
            true,
        );
        assert!(bias.shrink() > 0.8, "held-out bias shrink {}", bias.shrink());
        let healthy = [run_with(11, |_, e| e)];
        for shape in [Shape::Stuck, Shape::Bias] {
            for heldout in [true, false] {
                let gap = part_gap(&healthy, 0, shape, 1.0, &untrained(0.05), heldout);
                assert!(gap.n > 0 && gap.mse_after == gap.mse_before, "{shape:?} heldout={heldout}");
            }
        }
    }

    /// Nothing is re-fitted on the held-out part: a bias whose level there differs from the
    /// training level is predicted at the training level, so the held-out gap keeps the
    /// difference (a re-fit would have removed it all).
    #[test]
    fn a_bias_keeps_its_training_level_on_the_held_out_part() {
        let runs = [run_with(13, |t_s, e| if t_s < 16.0 { e + 0.03 } else { e + 0.06 })];
        let onsets = scan(&runs, 0, Shape::Bias, 1.0);
        let segments = segments_of(&runs, 0);
        let fit = regression::fit_through_origin(&segments, &onsets.columns).expect("a fit");
        let trained = Trained::new(&runs, 0, Shape::Bias, &onsets, &fit.beta);
        let level = trained.levels[0].expect("a training level");
        assert!((level - 0.03).abs() < 0.003, "training level {level}");
        let gap = part_gap(&runs, 0, Shape::Bias, 1.0, &trained, true);
        // Before: 0.06 of bias; after: 0.03 left, so the gap halves and no more.
        assert!((gap.shrink() - 0.5).abs() < 0.1, "held-out shrink {}", gap.shrink());
        assert!(gap.gap_after() > 0.02, "the held-out difference stays: {}", gap.gap_after());
    }

    /// On the selection blocks (interleaved with the training part) a fault inside one block is
    /// found there.
    #[test]
    fn a_fault_inside_a_selection_block_is_found_there() {
        let probe = run_with(12, |_, e| e);
        let block: Vec<usize> = probe.select.samples().take(probe.select.block).collect();
        let (from_s, to_s) = (block[0] as f64 / HZ + 0.1, *block.last().unwrap() as f64 / HZ - 0.1);
        let runs = [run_with(12, |t_s, e| if (from_s..to_s).contains(&t_s) { e + 0.08 } else { e })];
        let gap = part_gap(&runs, 0, Shape::Bias, 1.0, &untrained(0.08), false);
        assert!(gap.shrink() > 0.8, "selection shrink {}", gap.shrink());
    }

    #[test]
    fn the_stuck_columns_hold_the_slope_then_one_level_per_run() {
        let runs = [run_with(7, |t_s, e| if t_s >= 5.0 { -0.4 } else { e }), run_with(8, |_, e| e)];
        let onsets = scan(&runs, 0, Shape::Stuck, 1.0);
        assert!(onsets.per_run[0].is_some() && onsets.per_run[1].is_none());
        assert_eq!(onsets.columns[0].len(), 1 + runs.len());
        let inside = onsets.per_run[0].clone().expect("found");
        assert!(onsets.columns[0][1].iter().enumerate().all(|(i, v)| *v == f64::from(u8::from(inside.contains(&i)))));
        assert!(onsets.columns[1].iter().flatten().all(|v| *v == 0.0));
    }
}

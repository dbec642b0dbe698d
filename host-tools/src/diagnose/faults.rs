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

    fn var(sum: f64, sq: f64, n: f64) -> f64 {
        if n > 0.0 { (sq - sum * sum / n).max(0.0) } else { 0.0 }
    }
}

/// The interval with the most evidence for `shape` in one run, if decisive.
fn best_interval(run: &RunStreams, tap: usize, shape: Shape, tau: f64) -> Option<std::ops::Range<usize>> {
    let nu = &run.innovation[tap];
    let expected = expectation(run, tap);
    let samples: Vec<usize> = run.fit_samples().filter(|&i| nu[i].is_finite() && expected[i].is_finite()).collect();
    if samples.len() < 20 {
        return None;
    }
    let half = ((SMOOTHING_HALF_S * run.sample_hz).round() as usize).max(1);
    let (reading, smooth_expected) = (moving_average(&run.cp[tap], half), moving_average(&expected, half));
    let n = run.len();
    let cell_of = |i: usize| (i * GRID / n.max(1)).min(GRID - 1);
    let mut cells = vec![Sums::default(); GRID];
    for &i in &samples {
        let (y, x, r, e) = (nu[i], expected[i], reading[i], smooth_expected[i]);
        let (r, e) = if r.is_finite() && e.is_finite() { (r, e) } else { (x, x) };
        let cell = &mut cells[cell_of(i)];
        cell.add(&Sums { n: 1.0, y, yy: y * y, x, xx: x * x, xy: x * y, r, rr: r * r, e, ee: e * e });
    }
    let mut total = Sums::default();
    cells.iter().for_each(|c| total.add(c));
    let ssr0 = Sums::var(total.y, total.yy, total.n);
    if ssr0 <= 0.0 {
        return None;
    }
    let n_eff = samples.len() as f64 / tau.max(1.0);
    let mut best: Option<(std::ops::Range<usize>, f64)> = None;
    for first in 0..GRID {
        let mut inside = Sums::default();
        for (last, cell) in cells.iter().enumerate().skip(first) {
            inside.add(cell);
            if inside.n < 10.0 {
                continue;
            }
            let gain = match shape {
                // A level inside, zero outside (a healthy channel's innovation has no mean):
                // the fault's own column, so that an interval over part of the run and one over
                // all of it (an offset from the start) compete on the same footing.
                Shape::Bias => inside.y * inside.y / inside.n,
                Shape::Stuck => {
                    let sxx = Sums::var(inside.x, inside.xx, inside.n);
                    let sxy = inside.xy - inside.x * inside.y / inside.n;
                    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
                    let flat = Sums::var(inside.r, inside.rr, inside.n)
                        <= STUCK_FLATNESS * Sums::var(inside.e, inside.ee, inside.n);
                    if (STUCK_SLOPE.0..=STUCK_SLOPE.1).contains(&slope) && flat { sxy * sxy / sxx } else { 0.0 }
                }
            };
            if best.as_ref().is_none_or(|(_, g)| gain > *g) {
                let start = n * first / GRID;
                let end = if last + 1 == GRID { n } else { n * (last + 1) / GRID };
                best = Some((start..end, gain));
            }
        }
    }
    let (interval, gain) = best?;
    // Trimmed to the samples that chose it: a cell edge inside a selection block is not where
    // the fault starts or ends (no sample there said so), and a fault put on samples it was not
    // seen on would be judged there against a reading it never had. An interval that runs to the
    // end of the training part runs on to the end of the run (the held-out part), one from its
    // first sample from the start.
    let first = samples.iter().copied().find(|i| interval.contains(i))?;
    let last = samples.iter().copied().rev().find(|i| interval.contains(i))?;
    let start = if Some(&first) == samples.first() { 0 } else { first };
    let interval = start..if Some(&last) == samples.last() { n } else { last + 1 };
    let remaining = (ssr0 - gain).max(f64::MIN_POSITIVE);
    // Up to two parameters (a level, and a stuck reading's slope), and the choice of the
    // interval among GRID (GRID + 1) / 2.
    let choices = (GRID * (GRID + 1) / 2) as f64;
    let evidence = n_eff * (ssr0 / remaining).ln() - 2.0 * n_eff.ln() - choices.ln();
    (evidence >= MIN_RUN_DELTA_BIC).then_some(interval)
}

/// Segments of one channel's innovation (for the fit of the fault's columns).
#[must_use]
pub fn segments_of(runs: &[RunStreams], tap: usize) -> Vec<Segment<'_>> {
    runs.iter()
        .map(|run| Segment {
            residual: &run.innovation[tap],
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

//! The balance's own behaviour (G3, G7): lightly damped structural modes of balance and sting
//! excited by the load, the motion and the blowing, and a slow drift of its zero (docs/diagnosis.md,
//! Balance resonance and Bias drift).

use firmware_sim::effect::Effect;

use super::{BalanceCandidate, Context, Params, Shape, log_grid};
use crate::diagnose::streams::{MODE_DRIVE_CORNERS_HZ, RunStreams};

/// Damping ratios of the balance-resonance candidate's fine grid: from 0.005 (a bolted steel
/// sting) to 0.3, the span of "lightly damped" in the contract's definition (docs/diagnosis.md,
/// Balance resonance); a more damped "mode" is a broad filter that any error of the sim's
/// dynamics can feed.
pub const RESONANCE_DAMPING: [f64; 9] = [0.005, 0.01, 0.02, 0.04, 0.07, 0.1, 0.15, 0.2, 0.3];

/// Damping ratios of the coarse grid: one narrow, one moderate, one broad mode, so that a mode of
/// any damping correlates with one of them near its frequency and the fine grid takes it from
/// there.
const RESONANCE_DAMPING_COARSE: [f64; 3] = [0.02, 0.08, 0.25];

/// Natural frequencies of the coarse grid (logarithmic), and of the fine grid around each
/// leading coarse frequency (one coarse cell either side).
const RESONANCE_COARSE: usize = 40;
const RESONANCE_FINE: usize = 9;

/// Corners of the acceleration's smoother on the coarse grid: the sharpest and the smoothest
/// but one (the refinement tries every corner of [`MODE_DRIVE_CORNERS_HZ`] at the leading mode).
const RESONANCE_CORNERS_COARSE: [f64; 2] = [MODE_DRIVE_CORNERS_HZ[1], MODE_DRIVE_CORNERS_HZ[3]];

/// Damping ratios of the rung mode's grid ([`Shape::Ringing`]): the lightly damped part of the
/// contract's range. A mode rung by a load no input records is told from the residual's other
/// colour only by a narrow peak; a broad one (damping 0.3) is any coloured residual, and the
/// recorded drives ([`Shape::Mode`]) keep the contract's whole range.
const RINGING_DAMPING_COARSE: [f64; 2] = [0.02, 0.07];
const RINGING_DAMPING: [f64; 6] = [0.005, 0.01, 0.02, 0.04, 0.07, 0.1];

/// Width of the rung mode's band-pass over the mode's own, as damping ratios: a band as narrow
/// as the mode turns the phase across the mode's band, and the last two samples then predict
/// less of it (of a mode at 50 Hz, damping 0.07, under noise of a third of its RMS, the
/// recursion predicted 0.91 of its variance through five times its width, 0.88 through three).
const RINGING_BAND_WIDENING: f64 = 5.0;

/// Least coefficient of variation of a rung mode's envelope (its power over two periods, along
/// the run): a mode rung by a random load has a Rayleigh envelope, whose power varies as much
/// as its mean (a coefficient of 1, less a little for the averaging); a tone from the rig (a
/// fan, a pump: outside the vocabulary) holds its amplitude, and the band-pass's own noise
/// leaves it a few hundredths. Half the random mode's is the boundary.
const RINGING_MIN_ENVELOPE_CV: f64 = 0.5;

/// Least power density of a rung mode's band over that of the bands an octave either side: a
/// mode stands out of its neighbourhood by at least twice (3 dB).
const RINGING_MIN_PEAK: f64 = 2.0;

/// Knot spacings of the drift's piecewise-linear form, s: a zero that wanders (a random walk)
/// rather than a smooth trend.
pub const DRIFT_KNOT_SPACING_S: [f64; 2] = [4.0, 2.0];

/// Time constants of the drift's exponential settling, s: from 0.8 s (the contract's drift is
/// slower than 0.2 Hz, `1 / (2 pi 0.2 Hz)`) to 30 s, beyond which it is a ramp.
const DRIFT_SETTLE_S: [f64; 6] = [0.8, 1.6, 3.2, 6.4, 13.0, 30.0];

/// Most steps per run of the drift's stepped form.
const DRIFT_MAX_STEPS: u8 = 3;

/// `balance_resonance`: a mode from [`Context::resonance_min_hz`] to 0.35 of the sample rate
/// (at most 300 Hz), damping [`RESONANCE_DAMPING`], driven by the sim's load, the inertial load of
/// the motion (the acceleration smoothed at one of [`MODE_DRIVE_CORNERS_HZ`]) and the blowing;
/// or rung by a load no input records (the buffet of the flow: the contract's "excited by ...
/// the aerodynamic load" holds the unsteady load the sim does not have), predicted from the
/// residual's own past ([`Shape::Ringing`]). Several modes are named one after the other on the
/// remainder.
#[derive(Debug, Clone, Copy)]
pub struct BalanceResonance;

impl BalanceResonance {
    /// The band the family searches, Hz.
    #[must_use]
    pub fn band_hz(sample_hz: f64, resonance_min_hz: f64) -> (f64, f64) {
        let top_hz = (0.35 * sample_hz).min(300.0);
        (resonance_min_hz.min(0.5 * top_hz), top_hz)
    }
}

/// Most peaks of the residual's spectrum added to the resonance family's coarse grid.
const MAX_SPECTRAL_SEEDS: usize = 4;

/// Length of the spectral windows of [`resonance_seeds_hz`], s (about 0.5 Hz bins), at most one
/// stretch of fit samples between two selection blocks.
const SEED_WINDOW_S: f64 = 2.0;

/// Chance that white noise seeds a peak anywhere in the band (the Bonferroni share per bin).
const SEED_FALSE_RATE: f64 = 0.01;

/// The frequencies of the residual's spectral peaks in `band_hz`, strongest first: at most
/// `MAX_SPECTRAL_SEEDS` bins that are local maxima and stand at least `RINGING_MIN_PEAK`
/// times above the median of their neighbours (`ledger::local_peak_ratio`), and beyond
/// what the estimate's own scatter gives white noise anywhere in the band: a Welch average of
/// `K` windows is `chi2(2K) / 2K` times the true density (Welch 1967), so a bin must exceed
/// that ratio's `1 - SEED_FALSE_RATE / bins` quantile. From the training part's fit samples only
/// (Welch windows inside each stretch between selection blocks).
///
/// Why: a lightly damped mode off the coarse grid is nearly in quadrature with the grid's
/// neighbouring modes (a mode's phase turns by 180 deg across its band, `2 zeta` of its
/// frequency: 2 % at `zeta = 0.01`, where the grid's steps are about 10 %), so no coarse form
/// correlates with it and the refinement never comes near. Its spectral peak sits at its
/// frequency whatever its damping, to a bin.
#[must_use]
pub fn resonance_seeds_hz(runs: &[RunStreams], residuals: &[Vec<f64>], band_hz: (f64, f64)) -> Vec<f64> {
    let Some(sample_hz) = runs.first().map(|run| run.sample_hz) else { return Vec::new() };
    let window = (SEED_WINDOW_S * sample_hz) as usize;
    let mut stretches: Vec<&[f64]> = Vec::new();
    for (run, residual) in runs.iter().zip(residuals) {
        let mut start = None;
        for idx in run.training.clone().chain(std::iter::once(usize::MAX)) {
            let usable = idx != usize::MAX && run.is_fit_sample(idx) && residual[idx].is_finite();
            match (usable, start) {
                (true, None) => start = Some(idx),
                (false, Some(first)) => {
                    if idx.min(run.training.end) - first >= window {
                        stretches.push(&residual[first..idx.min(run.training.end)]);
                    }
                    start = None;
                }
                _ => {}
            }
        }
    }
    let Some(spectrum) = crate::diagnose::ledger::welch_psd(&stretches, sample_hz, window) else { return Vec::new() };
    let psd = &spectrum.psd;
    let bins = spectrum.freq_hz.iter().filter(|f| (band_hz.0..=band_hz.1).contains(*f)).count().max(1);
    let dof = 2.0 * spectrum.n_windows as f64;
    let scatter = statrs::distribution::ChiSquared::new(dof)
        .map(|chi2| statrs::distribution::ContinuousCDF::inverse_cdf(&chi2, 1.0 - SEED_FALSE_RATE / bins as f64) / dof)
        .unwrap_or(f64::INFINITY);
    let least_ratio = RINGING_MIN_PEAK.max(scatter);
    let mut peaks: Vec<(f64, f64)> = (1..psd.len().saturating_sub(1))
        .filter(|&idx| (band_hz.0..=band_hz.1).contains(&spectrum.freq_hz[idx]))
        .filter(|&idx| psd[idx] > psd[idx - 1] && psd[idx] >= psd[idx + 1])
        .filter_map(|idx| {
            let ratio = crate::diagnose::ledger::local_peak_ratio(&spectrum, idx)?;
            (ratio >= least_ratio).then_some((ratio, spectrum.freq_hz[idx]))
        })
        .collect();
    peaks.sort_by(|a, b| b.0.total_cmp(&a.0));
    peaks.into_iter().take(MAX_SPECTRAL_SEEDS).map(|(_, freq_hz)| freq_hz).collect()
}

/// `bias_drift`: a slow drift of the zero per run, from the run's own tare at its start: a
/// smooth trend (powers of time, degree 1 to 3), a zero that wanders (piecewise linear between
/// knots [`DRIFT_KNOT_SPACING_S`] apart; beyond the training part it holds its last slope, all a
/// drift lets anyone predict), an exponential settling, or steps at times found on the training
/// part.
#[derive(Debug, Clone, Copy)]
pub struct BiasDrift;

impl BalanceCandidate for BalanceResonance {
    fn regressors(&self) -> &'static str {
        "(H - 1) of the sim's load, of the roll acceleration over q S b and of the plant's moment (the blowing), H a unit-gain mode; or, for a mode rung by a load no input records, the mode's recursion on the residual's last two samples through a band-pass at the mode"
    }

    fn effect(&self) -> Option<Effect> {
        Some(Effect::BalanceResonance)
    }

    fn separating_experiment(&self) -> &'static str {
        "a wind-off tap test of balance and sting"
    }

    /// A second mode is named on the remainder of the first.
    fn repeatable(&self) -> bool {
        true
    }

    /// The coarse grid, and the residual's spectral peaks ([`resonance_seeds_hz`]).
    fn shapes(&self, sample_hz: f64, context: &Context<'_>) -> Vec<Shape> {
        let (low, high) = Self::band_hz(sample_hz, context.resonance_min_hz);
        let mut shapes = Vec::new();
        for freq_hz in
            log_grid(low, high, RESONANCE_COARSE).into_iter().chain(context.resonance_seeds_hz.iter().copied())
        {
            for zeta in RESONANCE_DAMPING_COARSE {
                for drive_corner_hz in RESONANCE_CORNERS_COARSE {
                    shapes.push(Shape::Mode { freq_hz, zeta, drive_corner_hz });
                }
            }
            shapes.extend(RINGING_DAMPING_COARSE.map(|zeta| Shape::Ringing { freq_hz, zeta }));
        }
        shapes
    }

    fn refine(&self, best: &Shape, sample_hz: f64, context: &Context<'_>) -> Vec<Shape> {
        let (low, high) = Self::band_hz(sample_hz, context.resonance_min_hz);
        let ratio = super::grid_ratio(low, high, RESONANCE_COARSE);
        if let Shape::Ringing { freq_hz, .. } = *best {
            return super::around(freq_hz, ratio, RESONANCE_FINE, low, high)
                .into_iter()
                .flat_map(|freq_hz| RINGING_DAMPING.map(|zeta| Shape::Ringing { freq_hz, zeta }))
                .collect();
        }
        let Shape::Mode { freq_hz, zeta, drive_corner_hz } = *best else { return Vec::new() };
        let mut shapes: Vec<Shape> = MODE_DRIVE_CORNERS_HZ
            .iter()
            .filter(|corner| **corner != drive_corner_hz)
            .map(|&drive_corner_hz| Shape::Mode { freq_hz, zeta, drive_corner_hz })
            .collect();
        for freq_hz in super::around(freq_hz, ratio, RESONANCE_FINE, low, high) {
            for zeta in RESONANCE_DAMPING {
                shapes.push(Shape::Mode { freq_hz, zeta, drive_corner_hz });
            }
        }
        shapes
    }

    fn columns(&self, shape: &Shape, run: &RunStreams, _run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        if let Shape::Ringing { freq_hz, zeta } = *shape {
            return Vec::from(ringing_columns(run, freq_hz, zeta));
        }
        let Shape::Mode { freq_hz, zeta, drive_corner_hz } = *shape else { return Vec::new() };
        let dt_s = 1.0 / run.sample_hz;
        let load = run.cl_sim();
        let Some(acceleration) = run.acceleration_at(drive_corner_hz) else { return Vec::new() };
        // The blowing excites the mode through the jets' own moment, apart from the rest of the
        // load (a mode fed by the jets' reaction, not by the flow over the wing).
        let blowing = run.cl_afc();
        let scale = [1.0, 1.0 / context.moment_scale_nm, 1.0];
        Vec::from(mode_excess([&load, acceleration, &blowing], scale, freq_hz, zeta, dt_s))
    }

    fn params(&self, shape: &Shape, beta: &[f64], _context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        if matches!(shape, Shape::Ringing { .. }) {
            return super::gains(&["gain_recursion"], beta);
        }
        super::gains(&["gain_load", "gain_inertial", "gain_blowing"], beta)
    }
}

impl BalanceCandidate for BiasDrift {
    fn regressors(&self) -> &'static str {
        "per run, powers of time from zero at its start, or a piecewise-linear zero between knots"
    }

    fn effect(&self) -> Option<Effect> {
        Some(Effect::BiasDrift)
    }

    fn separating_experiment(&self) -> &'static str {
        "wind-off zero readings before and after each run"
    }

    fn shapes(&self, _sample_hz: f64, context: &Context<'_>) -> Vec<Shape> {
        let trends = (1..=3).map(|degree| Shape::Trend { degree });
        let runs = u16::try_from(context.n_runs).unwrap_or(u16::MAX);
        trends
            .chain(DRIFT_KNOT_SPACING_S.map(|knot_spacing_s| Shape::Wander { knot_spacing_s }))
            .chain(DRIFT_SETTLE_S.map(|tau_s| Shape::Settle { tau_s }))
            .chain((1..=DRIFT_MAX_STEPS).map(|count| Shape::Steps { count, runs }))
            .collect()
    }

    fn columns(&self, shape: &Shape, run: &RunStreams, run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        let duration = run.t_s.last().copied().unwrap_or(1.0).max(f64::MIN_POSITIVE);
        let shapes: Vec<Box<dyn Fn(f64) -> f64>> = match *shape {
            Shape::Wander { knot_spacing_s } => {
                let knots = (duration / knot_spacing_s).floor() as usize;
                std::iter::once(Box::new(move |t: f64| t / duration) as Box<dyn Fn(f64) -> f64>)
                    .chain((1..=knots).map(move |k| {
                        let knot = k as f64 * knot_spacing_s;
                        Box::new(move |t: f64| (t - knot).max(0.0) / duration) as Box<dyn Fn(f64) -> f64>
                    }))
                    .collect()
            }
            Shape::Trend { degree } => (1..=i32::from(degree.max(1)))
                .map(|power| Box::new(move |t: f64| (t / duration).powi(power)) as Box<dyn Fn(f64) -> f64>)
                .collect(),
            Shape::Settle { tau_s } => vec![Box::new(move |t: f64| 1.0 - (-t / tau_s).exp())],
            Shape::Steps { count, .. } => step_times_s(run, usize::from(count))
                .into_iter()
                .map(|at_s| Box::new(move |t: f64| if t >= at_s { 1.0 } else { 0.0 }) as Box<dyn Fn(f64) -> f64>)
                .collect(),
            _ => return Vec::new(),
        };
        // Every run has its own columns (zero in the other runs).
        let width = drift_width(shape, context);
        let mut out = vec![vec![0.0; run.len()]; width * context.n_runs];
        for (slot, shape) in shapes.iter().enumerate().take(width) {
            let column = &mut out[width * run_idx + slot];
            for (idx, t) in run.t_s.iter().enumerate() {
                column[idx] = shape(*t);
            }
        }
        out
    }

    /// The fitted drift at the end of each run (it starts from the run's tare at zero): the
    /// largest in size.
    fn params(&self, _shape: &Shape, beta: &[f64], _context: &Context<'_>, columns: &[Vec<Vec<f64>>]) -> Params {
        let worst = columns
            .iter()
            .filter_map(|cols| {
                let last = cols.first()?.len().checked_sub(1)?;
                Some(cols.iter().zip(beta).map(|(col, b)| b * col[last]).sum::<f64>())
            })
            .fold(0.0, |acc: f64, v| if v.abs() > acc.abs() { v } else { acc });
        vec![("largest_drift_over_run".into(), worst)]
    }
}

/// Columns per run of a drift: the degree, or one slope and one hinge per knot of the longest
/// run.
fn drift_width(shape: &Shape, context: &Context<'_>) -> usize {
    match *shape {
        Shape::Wander { knot_spacing_s } => 1 + (context.longest_run_s / knot_spacing_s).floor() as usize,
        Shape::Trend { degree } => usize::from(degree.max(1)),
        Shape::Settle { .. } => 1,
        Shape::Steps { count, .. } => usize::from(count),
        _ => 0,
    }
}

/// The column of a mode rung by an unrecorded load: the mode's own recursion on the run's
/// residual through a band-pass at the mode ([`band_pass`], [`RINGING_BAND_WIDENING`] times the
/// mode's damping), one and two samples back. A mode's response obeys its own second-order
/// recursion whatever rings it, so its next sample follows from its last two (Box & Jenkins,
/// Time Series Analysis, 1970, ch. 3: the AR(2) with complex roots); the band-pass keeps the
/// mode's band of the residual and leaves out most of the white noise, and one gain is fitted.
/// With the recursion's weights fitted freely instead, a tone anywhere in the band's skirt was
/// predicted as well as a mode at its centre. Zero on a run whose band is no peak of the residual's spectrum
/// ([`is_peak`]), whose band holds a steady tone ([`RINGING_MIN_ENVELOPE_CV`]), or without a
/// finite residual.
fn ringing_columns(run: &RunStreams, freq_hz: f64, zeta: f64) -> [Vec<f64>; 1] {
    let n = run.len();
    let zero = || [vec![0.0; n]];
    let Some(first) = run.residual.iter().copied().find(|v| v.is_finite()) else { return zero() };
    let held = model_fit::fit::signals::hold_missing(&run.residual, first);
    let dt_s = 1.0 / run.sample_hz;
    let width = (RINGING_BAND_WIDENING * zeta).min(0.5);
    let band = band_pass(&held, freq_hz, width, dt_s);
    if !is_peak(&held, &band, run, freq_hz, width) || envelope_cv(&band, run, freq_hz, width) < RINGING_MIN_ENVELOPE_CV
    {
        return zero();
    }
    // The mode's own recursion, its poles `exp((-zeta +- i sqrt(1 - zeta^2)) w dt)` (impulse
    // invariance): `m[n] = 2 r cos(theta) m[n-1] - r^2 m[n-2]` for the mode left to itself.
    let omega = std::f64::consts::TAU * freq_hz;
    let radius = (-zeta * omega * dt_s).exp();
    let theta = omega * (1.0 - zeta * zeta).sqrt() * dt_s;
    let (a1, a2) = (2.0 * radius * theta.cos(), -radius * radius);
    let predicted = (0..n)
        .map(|i| match i {
            0 => 0.0,
            1 => a1 * band[0],
            _ => a1 * band[i - 1] + a2 * band[i - 2],
        })
        .collect();
    [predicted]
}

/// Whether the residual's band at `freq_hz` is a peak of its spectrum: its power density (the
/// band's mean square over its width, which grows with the frequency at a fixed damping) at
/// least [`RINGING_MIN_PEAK`] times that an octave below and an octave above (or at 0.45 of the
/// sample rate). A mode is a peak; the colour of other effects (a lag, a slow state, the sim's
/// own error) falls with the frequency, and is no mode however predictable it is.
fn is_peak(held: &[f64], band: &[f64], run: &RunStreams, freq_hz: f64, width: f64) -> bool {
    let dt_s = 1.0 / run.sample_hz;
    let here = mean_square_on_fit(band.iter().copied(), run) / freq_hz;
    // The side bands only as far as they are needed (the profile asks every coarse frequency).
    let side = |at_hz: f64| mean_square_on_fit(BandPass::new(at_hz, width, dt_s).over(held), run) / at_hz;
    let peaks_over = |at_hz: f64| here >= RINGING_MIN_PEAK * side(at_hz);
    if here <= 0.0 || !peaks_over(0.5 * freq_hz) {
        return false;
    }
    let above_hz = (2.0 * freq_hz).min(0.45 * run.sample_hz);
    above_hz <= freq_hz * 1.2 || peaks_over(above_hz)
}

/// Mean square of `values` (a run's samples in order) over the run's fit samples past the first
/// second (the band-passes' settling).
fn mean_square_on_fit(values: impl Iterator<Item = f64>, run: &RunStreams) -> f64 {
    let settle = run.sample_hz.round() as usize;
    let (sum, n) = values
        .enumerate()
        .filter(|&(i, _)| i >= settle && run.is_fit_sample(i))
        .fold((0.0, 0usize), |(sum, n), (_, v)| (sum + v * v, n + 1));
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// A band-pass of unit peak gain at `freq_hz`, `2 zeta w s / (s^2 + 2 zeta w s + w^2)` (bilinear
/// transform, natural frequency pre-warped), started at rest.
#[must_use]
pub fn band_pass(values: &[f64], freq_hz: f64, zeta: f64, dt_s: f64) -> Vec<f64> {
    BandPass::new(freq_hz, zeta, dt_s).over(values).collect()
}

/// The filter of [`band_pass`]: its coefficients, applied sample by sample.
#[derive(Debug, Clone, Copy)]
struct BandPass {
    b0: f64,
    a1: f64,
    a2: f64,
}

impl BandPass {
    fn new(freq_hz: f64, zeta: f64, dt_s: f64) -> Self {
        let omega = 2.0 / dt_s * (std::f64::consts::PI * freq_hz * dt_s).tan();
        let k = 2.0 / dt_s;
        let two_zw = 2.0 * zeta * omega;
        let a0 = k * k + two_zw * k + omega * omega;
        Self {
            b0: two_zw * k / a0,
            a1: (2.0 * omega * omega - 2.0 * k * k) / a0,
            a2: (k * k - two_zw * k + omega * omega) / a0,
        }
    }

    /// The filtered `values`, started at rest.
    fn over(self, values: &[f64]) -> impl Iterator<Item = f64> + '_ {
        let Self { b0, a1, a2 } = self;
        let (mut x1, mut x2, mut y1, mut y2) = (0.0, 0.0, 0.0, 0.0);
        values.iter().map(move |&x| {
            let y = b0 * (x - x2) - a1 * y1 - a2 * y2;
            (x2, x1, y2, y1) = (x1, x, y1, y);
            y
        })
    }
}

/// Coefficient of variation of the band's power averaged over two periods of `freq_hz`, over
/// the run's fit samples past the band-pass's settling (five of the mode's time constants,
/// `1 / (zeta w)`, at least a second); 0 when the run is too short. The band is the one the
/// form predicts from: the two free weights predict a tone anywhere in it, off its centre too
/// (a tone at 15.2 Hz was predicted by the band at 11.5 Hz, whose centre holds only noise).
fn envelope_cv(band: &[f64], run: &RunStreams, freq_hz: f64, zeta: f64) -> f64 {
    let window = ((2.0 * run.sample_hz / freq_hz).round() as usize).max(2);
    let settle_s = (5.0 / (zeta * std::f64::consts::TAU * freq_hz)).max(1.0);
    let settle = (settle_s * run.sample_hz).round() as usize;
    // Non-overlapping windows of consecutive fit samples: (last sample, samples, sum of squares).
    let mut powers = Vec::new();
    let mut chunk: Option<(usize, usize, f64)> = None;
    for i in run.fit_samples().filter(|&i| i >= settle + window) {
        let (count, sum) = match chunk {
            Some((last, count, sum)) if last + 1 == i => (count + 1, sum + band[i] * band[i]),
            _ => (1, band[i] * band[i]),
        };
        chunk = if count == window {
            powers.push(sum / window as f64);
            None
        } else {
            Some((i, count, sum))
        };
    }
    if powers.len() < 10 {
        return 0.0;
    }
    let mean = powers.iter().sum::<f64>() / powers.len() as f64;
    if mean <= 0.0 {
        return 0.0;
    }
    let var = powers.iter().map(|p| (p - mean).powi(2)).sum::<f64>() / (powers.len() - 1) as f64;
    var.sqrt() / mean
}

/// The times of up to `count` steps of the run's zero, s from its start: greedy binary
/// segmentation of the balance residual on the training part's fit samples (selection blocks and
/// the held-out part choose nothing), each split the one that removes the most squared deviation
/// from the segment means (Scott & Knott 1974; the least-squares change point of Hinkley 1970).
/// Fewer when a segment is too short to split.
#[must_use]
pub fn step_times_s(run: &RunStreams, count: usize) -> Vec<f64> {
    let samples: Vec<(f64, f64)> =
        run.fit_samples().filter(|&i| run.residual[i].is_finite()).map(|i| (run.t_s[i], run.residual[i])).collect();
    let min_len = (run.sample_hz * 0.2) as usize + 1;
    let mut bounds = vec![0, samples.len()];
    let mut times = Vec::new();
    for _ in 0..count {
        let best = bounds
            .windows(2)
            .filter_map(|w| best_split(&samples[w[0]..w[1]], min_len).map(|(at, gain)| (w[0] + at, gain)))
            .max_by(|a, b| a.1.total_cmp(&b.1));
        let Some((at, _)) = best else { break };
        times.push(samples[at].0 - run.t_s.first().copied().unwrap_or(0.0));
        bounds.push(at);
        bounds.sort_unstable();
    }
    times.sort_by(f64::total_cmp);
    times
}

/// The split of `segment` into two parts of at least `min_len` samples that removes the most
/// squared deviation from their means, and how much it removes.
fn best_split(segment: &[(f64, f64)], min_len: usize) -> Option<(usize, f64)> {
    let n = segment.len();
    if n < 2 * min_len {
        return None;
    }
    let total: f64 = segment.iter().map(|(_, r)| r).sum();
    let mut left = 0.0;
    let mut best: Option<(usize, f64)> = None;
    for (k, (_, r)) in segment.iter().enumerate().take(n - min_len) {
        left += r;
        let m = k + 1;
        if m < min_len {
            continue;
        }
        // Between-segment sum of squares of a split after `m` samples.
        let right = total - left;
        let gain = left * left / m as f64 + right * right / (n - m) as f64 - total * total / n as f64;
        if best.is_none_or(|(_, g)| gain > g) {
            best = Some((m, gain));
        }
    }
    best
}

/// Coefficients `(b, a1, a2)` of a unit-gain second-order resonator
/// `w^2 / (s^2 + 2 zeta w s + w^2)` by the bilinear transform with the natural frequency
/// pre-warped.
fn resonator_coefficients(freq_hz: f64, zeta: f64, dt_s: f64) -> ([f64; 3], f64, f64) {
    let omega = 2.0 / dt_s * (std::f64::consts::PI * freq_hz * dt_s).tan();
    let k = 2.0 / dt_s;
    let (w2, two_zw) = (omega * omega, 2.0 * zeta * omega);
    let a0 = k * k + two_zw * k + w2;
    ([w2 / a0, 2.0 * w2 / a0, w2 / a0], (2.0 * w2 - 2.0 * k * k) / a0, (k * k - two_zw * k + w2) / a0)
}

/// A unit-gain second-order resonator `w^2 / (s^2 + 2 zeta w s + w^2)` (bilinear transform with
/// the natural frequency pre-warped), started at rest at the first input.
#[must_use]
pub fn resonator(values: &[f64], freq_hz: f64, zeta: f64, dt_s: f64) -> Vec<f64> {
    let (b, a1, a2) = resonator_coefficients(freq_hz, zeta, dt_s);
    let first = values.first().copied().unwrap_or(0.0);
    let (mut x1, mut x2, mut y1, mut y2) = (first, first, first, first);
    values
        .iter()
        .map(|&x| {
            let y = b[0] * x + b[1] * x1 + b[2] * x2 - a1 * y1 - a2 * y2;
            (x2, x1, y2, y1) = (x1, x, y1, y);
            y
        })
        .collect()
}

/// A unit-gain second-order Butterworth low-pass (a [`resonator`] with damping `1/sqrt(2)`): the
/// balance's own anti-alias filter, causal as the balance's electronics are.
#[must_use]
pub fn lowpass2(values: &[f64], corner_hz: f64, dt_s: f64) -> Vec<f64> {
    resonator(values, corner_hz, std::f64::consts::FRAC_1_SQRT_2, dt_s)
}

/// What a mode adds to each of `N` inputs, `scale (H - 1) u` with `H` the [`resonator`], in one
/// pass: the recursions are independent, so they run side by side (the recursion is bound by its
/// latency, and the family profiles hundreds of forms).
fn mode_excess<const N: usize>(
    inputs: [&[f64]; N],
    scale: [f64; N],
    freq_hz: f64,
    zeta: f64,
    dt_s: f64,
) -> [Vec<f64>; N] {
    let (b, a1, a2) = resonator_coefficients(freq_hz, zeta, dt_s);
    let n = inputs.iter().map(|values| values.len()).min().unwrap_or(0);
    let mut out: [Vec<f64>; N] = std::array::from_fn(|_| vec![0.0; n]);
    let first = inputs.map(|values| values.first().copied().unwrap_or(0.0));
    // Per input: x[k-1], x[k-2], y[k-1], y[k-2].
    let mut state: [[f64; 4]; N] = first.map(|x| [x; 4]);
    for idx in 0..n {
        for k in 0..N {
            let x = inputs[k][idx];
            let [x1, x2, y1, y2] = state[k];
            let y = b[0] * x + b[1] * x1 + b[2] * x2 - a1 * y1 - a2 * y2;
            state[k] = [x, x1, y, y1];
            out[k][idx] = scale[k] * (y - x);
        }
    }
    out
}

#[cfg(test)]
mod tests;

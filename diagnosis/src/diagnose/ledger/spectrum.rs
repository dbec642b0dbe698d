//! The residual in the frequency domain: Welch spectra, power shares per band, narrow peaks
//! and residual–input coherence (docs/diagnosis.md, Spectrum and coherence).
//!
//! A narrow residual peak at a frequency unrelated to the excitation points to a structural
//! resonance (docs/diagnosis.md, Balance resonance); power at harmonics of the forcing points to
//! nonlinearity or hysteresis; coherence with an input localises unmodelled input dynamics in
//! frequency, for any input.
//!
//! All spectra use Welch's method (Welch 1967): periodic Hann windows with 50 % overlap, each
//! window's mean removed before windowing (scipy's `detrend='constant'`), windows taken inside
//! one finite run and never across a join or a missing sample; a run's tail shorter than a
//! window is not used.
//!
//! # Examples
//!
//! ```
//! use diagnosis::diagnose::ledger::{band_shares, welch_psd};
//!
//! // A unit 10 Hz sine at 100 Hz: all its power, 0.5, in the 5-15 Hz band.
//! let sample_hz = 100.0;
//! let tau = 2.0 * std::f64::consts::PI;
//! let x: Vec<f64> = (0..4096).map(|k| (tau * 10.0 * k as f64 / sample_hz).sin()).collect();
//! let psd = welch_psd(&[&x], sample_hz, 256).unwrap();
//! let shares = band_shares(&psd, &[0.0, 5.0, 15.0, 50.0]);
//! assert!(shares[1].share > 0.99);
//! assert!((shares[1].rms - 0.5_f64.sqrt()).abs() < 0.01);
//! ```

use rustfft::FftPlanner;
use rustfft::num_complex::Complex;
use serde::Serialize;

use super::{demeaned_paired_runs, demeaned_runs};

/// Confidence of the coherence bound.
pub const COHERENCE_CONFIDENCE: f64 = 0.99;

/// Bins on each side whose median is the local floor of [`spectral_peak`]: wide enough that
/// the peak's own Hann main lobe (±2 bins) is a minority of them.
pub const PEAK_NEIGHBOUR_BINS: usize = 8;

/// Welch power spectral density (Hann, 50 % overlap).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Spectrum {
    /// Bin frequencies `k·fs/L`, `k = 0..=L/2`, in Hz.
    pub freq_hz: Vec<f64>,
    /// One-sided PSD in (signal units)²/Hz: `Σ psd·Δf` is the variance.
    pub psd: Vec<f64>,
    /// Number of Welch windows averaged.
    pub n_windows: usize,
}

/// Welch estimate of the one-sided PSD of the pooled segments, windows of `segment_len`
/// samples at `sample_hz`.
///
/// Each window `x_w` gives `2|FFT(x_w·w)|²/(fs Σw²)` (not doubled at DC and Nyquist), the
/// density scaling under which the PSD integrates to the variance (Welch 1967; scipy
/// `signal.welch(scaling='density')`); the windows of all runs are averaged with equal weight.
///
/// Returns `None` when `segment_len < 4`, `sample_hz` is not positive and finite, or no run is
/// as long as one window.
pub fn welch_psd(segments: &[&[f64]], sample_hz: f64, segment_len: usize) -> Option<Spectrum> {
    if segment_len < 4 || !(sample_hz.is_finite() && sample_hz > 0.0) {
        return None;
    }
    let runs = demeaned_runs(segments, segment_len);
    let welch = Welch::new(segment_len);
    let mut psd = vec![0.0; welch.n_bins()];
    let mut n_windows = 0;
    for run in &runs {
        for start in welch.starts(run.len()) {
            let spectrum = welch.transform(&run[start..start + segment_len]);
            for (acc, bin) in psd.iter_mut().zip(&spectrum) {
                *acc += bin.norm_sqr();
            }
            n_windows += 1;
        }
    }
    if n_windows == 0 {
        return None;
    }
    let scale = 1.0 / (n_windows as f64 * sample_hz * welch.window_power());
    for (idx, value) in psd.iter_mut().enumerate() {
        *value *= scale * one_sided_factor(idx, segment_len);
    }
    Some(Spectrum { freq_hz: welch.freqs(sample_hz), psd, n_windows })
}

/// The residual's power in one frequency band.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BandShare {
    /// `[low, high)` in Hz (the last band also holds its upper edge).
    pub band_hz: [f64; 2],
    /// This band's power over the power of the whole spectrum.
    pub share: f64,
    /// RMS of the signal in this band, `√(Σ psd·Δf)`, in signal units.
    pub rms: f64,
}

/// Power share and RMS per band between consecutive `edges_hz` (increasing, in Hz).
///
/// A bin belongs to the band whose `[low, high)` holds its centre frequency; the last band also
/// holds its upper edge, so edges from 0 to `fs/2` give shares that sum to 1. Bands with
/// non-increasing or non-finite edges are skipped; a spectrum without power gives shares of 0.
pub fn band_shares(spectrum: &Spectrum, edges_hz: &[f64]) -> Vec<BandShare> {
    let bin_hz = bin_width_hz(spectrum);
    let total: f64 = spectrum.psd.iter().sum::<f64>() * bin_hz;
    let n_bands = edges_hz.len().saturating_sub(1);
    edges_hz
        .windows(2)
        .enumerate()
        .filter(|(_, e)| e[0].is_finite() && e[1].is_finite() && e[0] < e[1])
        .map(|(band_idx, e)| {
            let last = band_idx + 1 == n_bands;
            let power = spectrum
                .freq_hz
                .iter()
                .zip(&spectrum.psd)
                .filter(|&(&f, _)| f >= e[0] && (f < e[1] || (last && f <= e[1])))
                .map(|(_, p)| p)
                .sum::<f64>()
                * bin_hz;
            let share = if total > 0.0 { power / total } else { 0.0 };
            BandShare { band_hz: [e[0], e[1]], share, rms: power.sqrt() }
        })
        .collect()
}

/// The largest narrow peak of a spectrum.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpectralPeak {
    /// Frequency of the peak bin, in Hz.
    pub freq_hz: f64,
    /// PSD at the peak over the median PSD of the neighbouring bins.
    pub ratio_to_local_median: f64,
}

/// The bin in `[min_hz, max_hz]` whose PSD most exceeds the median of its neighbours, for
/// resonance detection (docs/diagnosis.md, Spectrum and coherence; Balance resonance).
///
/// The local floor is the median of up to [`PEAK_NEIGHBOUR_BINS`] bins on each side (the bin
/// itself excluded); a median rather than a mean so that the peak's own leakage does not raise
/// its floor. Returns `None` when no bin in the range has a positive floor.
pub fn spectral_peak(spectrum: &Spectrum, min_hz: f64, max_hz: f64) -> Option<SpectralPeak> {
    let mut best: Option<SpectralPeak> = None;
    for (idx, &freq_hz) in spectrum.freq_hz.iter().enumerate().take(spectrum.psd.len()) {
        if !(freq_hz >= min_hz && freq_hz <= max_hz) {
            continue;
        }
        let Some(ratio) = local_peak_ratio(spectrum, idx) else { continue };
        if best.as_ref().is_none_or(|b| ratio > b.ratio_to_local_median) {
            best = Some(SpectralPeak { freq_hz, ratio_to_local_median: ratio });
        }
    }
    best
}

/// The PSD at bin `idx` over the median of up to [`PEAK_NEIGHBOUR_BINS`] bins on each side (the
/// bin itself excluded); `None` where that floor is not positive or the bin not finite.
#[must_use]
pub fn local_peak_ratio(spectrum: &Spectrum, idx: usize) -> Option<f64> {
    let psd = &spectrum.psd;
    let lo = idx.saturating_sub(PEAK_NEIGHBOUR_BINS);
    let hi = (idx + PEAK_NEIGHBOUR_BINS).min(psd.len().checked_sub(1)?);
    let mut neighbours: Vec<f64> = (lo..=hi).filter(|&j| j != idx).map(|j| psd[j]).collect();
    neighbours.retain(|p| p.is_finite());
    neighbours.sort_by(f64::total_cmp);
    let floor = stats::quantile_sorted(&neighbours, 0.5).unwrap_or(f64::NAN);
    (floor > 0.0 && psd.get(idx)?.is_finite()).then(|| psd[idx] / floor)
}

/// Magnitude-squared coherence between residual and input, with its 99 % bound under
/// independence.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Coherence {
    /// Name of the input signal.
    pub input: String,
    /// Bin frequencies in Hz.
    pub freq_hz: Vec<f64>,
    /// `γ²(f)` in `[0, 1]`.
    pub gamma2: Vec<f64>,
    /// `1 − (1 − 0.99)^{1/(L−1)}`: the 99 % quantile of `γ²` for independent signals.
    pub bound_99: f64,
    /// `L`, the equivalent number of independent windows.
    pub equivalent_segments: f64,
    /// Welch windows averaged.
    pub n_windows: usize,
    /// Contiguous frequency ranges `[first, last]` (bin centres, Hz) where `γ² > bound_99`.
    pub bands_above_bound: Vec<[f64; 2]>,
}

/// Welch coherence `γ²(f) = |Σ E U*|²/(Σ|E|² Σ|U|²)` of paired residual and input segments.
///
/// Under independence `γ² ~ Beta(1, L−1)`, so its `c` quantile is `1 − (1−c)^{1/(L−1)}`
/// (dsmc `validation/coherence.rs`; docs/diagnosis.md, Spectrum and coherence). Overlapping windows
/// are not independent; the equivalent number is `L = K/(1 + 2 Σ_m (1 − m/K) c_m²)` for `K` windows
/// in one run, with `c_m` the normalised overlap of the window with itself shifted by `m` steps
/// (Welch 1967; `c_1 = 1/6` for Hann at 50 %, Harris 1978 table 1). Windows in different runs do
/// not overlap, so for several runs the sum counts only pairs inside one run:
/// `L = K²/(K + 2 Σ_m n_m c_m²)`, `n_m` the number of window pairs `m` steps apart; for one run
/// this is the formula above.
///
/// Returns `None` when the segments do not pair up, the arguments are invalid as for
/// [`welch_psd`], or there are too few windows for `L > 1`.
pub fn coherence(
    input_name: &str,
    residual: &[&[f64]],
    input: &[&[f64]],
    sample_hz: f64,
    segment_len: usize,
) -> Option<Coherence> {
    if segment_len < 4 || !(sample_hz.is_finite() && sample_hz > 0.0) {
        return None;
    }
    let runs = demeaned_paired_runs(residual, input, segment_len)?;
    let welch = Welch::new(segment_len);
    let spectra = welch.cross_spectra(&runs);
    let equivalent_segments = welch.equivalent_windows(&spectra.windows_per_run);
    if equivalent_segments.is_nan() || equivalent_segments <= 1.0 {
        return None;
    }
    let gamma2: Vec<f64> = (0..welch.n_bins())
        .map(|bin| {
            let denom = spectra.power_e[bin] * spectra.power_u[bin];
            if denom > 0.0 { (spectra.cross[bin].norm_sqr() / denom).min(1.0) } else { 0.0 }
        })
        .collect();
    let bound_99 = 1.0 - (1.0 - COHERENCE_CONFIDENCE).powf(1.0 / (equivalent_segments - 1.0));
    let freq_hz = welch.freqs(sample_hz);
    let bands_above_bound = ranges_above(&freq_hz, &gamma2, bound_99);
    Some(Coherence {
        input: input_name.to_owned(),
        freq_hz,
        gamma2,
        bound_99,
        equivalent_segments,
        n_windows: spectra.windows_per_run.iter().sum(),
        bands_above_bound,
    })
}

/// Welch sums over all windows of two signals: `Σ E U*`, `Σ|E|²`, `Σ|U|²` per bin.
struct CrossSpectra {
    cross: Vec<Complex<f64>>,
    power_e: Vec<f64>,
    power_u: Vec<f64>,
    windows_per_run: Vec<usize>,
}

/// A Welch set-up: window length, the periodic Hann window and an FFT plan.
struct Welch {
    len: usize,
    window: Vec<f64>,
    fft: std::sync::Arc<dyn rustfft::Fft<f64>>,
}

impl Welch {
    fn new(len: usize) -> Self {
        // Periodic Hann (scipy `get_window('hann', L)`): the DFT-even form used for spectra.
        let window = (0..len).map(|n| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * n as f64 / len as f64).cos()).collect();
        let fft = FftPlanner::new().plan_fft_forward(len);
        Welch { len, window, fft }
    }

    /// Hop between windows: 50 % overlap.
    fn step(&self) -> usize {
        (self.len / 2).max(1)
    }

    fn n_bins(&self) -> usize {
        self.len / 2 + 1
    }

    /// Start indices of the windows inside a run of `run_len` samples.
    fn starts(&self, run_len: usize) -> Vec<usize> {
        if run_len < self.len {
            return Vec::new();
        }
        (0..=run_len - self.len).step_by(self.step()).collect()
    }

    /// `Σ w²`, the window's power (Welch's `U` up to the factor `L`).
    fn window_power(&self) -> f64 {
        self.window.iter().map(|w| w * w).sum()
    }

    fn freqs(&self, sample_hz: f64) -> Vec<f64> {
        (0..self.n_bins()).map(|k| k as f64 * sample_hz / self.len as f64).collect()
    }

    /// The one-sided DFT bins of one window of data, mean removed before windowing.
    fn transform(&self, data: &[f64]) -> Vec<Complex<f64>> {
        let mean = data.iter().sum::<f64>() / data.len() as f64;
        let mut buffer: Vec<Complex<f64>> =
            data.iter().zip(&self.window).map(|(x, w)| Complex::new((x - mean) * w, 0.0)).collect();
        self.fft.process(&mut buffer);
        buffer.truncate(self.n_bins());
        buffer
    }

    /// The Welch sums of paired runs, windows inside each run only.
    fn cross_spectra(&self, runs: &[(Vec<f64>, Vec<f64>)]) -> CrossSpectra {
        let n_bins = self.n_bins();
        let mut sums = CrossSpectra {
            cross: vec![Complex::new(0.0, 0.0); n_bins],
            power_e: vec![0.0; n_bins],
            power_u: vec![0.0; n_bins],
            windows_per_run: Vec::with_capacity(runs.len()),
        };
        for (e, u) in runs {
            let starts = self.starts(e.len());
            sums.windows_per_run.push(starts.len());
            for start in starts {
                let spec_e = self.transform(&e[start..start + self.len]);
                let spec_u = self.transform(&u[start..start + self.len]);
                for bin in 0..n_bins {
                    sums.cross[bin] += spec_e[bin] * spec_u[bin].conj();
                    sums.power_e[bin] += spec_e[bin].norm_sqr();
                    sums.power_u[bin] += spec_u[bin].norm_sqr();
                }
            }
        }
        sums
    }

    /// `c_m²`: squared normalised overlap of the window with itself shifted by `m` steps.
    fn overlap_sq(&self, shift_steps: usize) -> f64 {
        let shift = shift_steps * self.step();
        if shift >= self.len {
            return 0.0;
        }
        let overlap: f64 = self.window[shift..].iter().zip(&self.window).map(|(a, b)| a * b).sum();
        (overlap / self.window_power()).powi(2)
    }

    /// Equivalent number of independent windows for runs holding `windows_per_run` windows.
    fn equivalent_windows(&self, windows_per_run: &[usize]) -> f64 {
        let total: usize = windows_per_run.iter().sum();
        let max_shift = self.len.div_ceil(self.step());
        let correlated: f64 = (1..max_shift)
            .map(|m| {
                let pairs: usize = windows_per_run.iter().map(|k| k.saturating_sub(m)).sum();
                pairs as f64 * self.overlap_sq(m)
            })
            .sum();
        let total = total as f64;
        total * total / (total + 2.0 * correlated)
    }
}

/// Factor 2 of a one-sided spectrum, except at DC and (for even lengths) Nyquist.
fn one_sided_factor(bin: usize, len: usize) -> f64 {
    if bin == 0 || (len.is_multiple_of(2) && bin == len / 2) { 1.0 } else { 2.0 }
}

/// Bin spacing of a spectrum in Hz (0 for fewer than two bins).
fn bin_width_hz(spectrum: &Spectrum) -> f64 {
    match spectrum.freq_hz.as_slice() {
        [first, second, ..] => second - first,
        _ => 0.0,
    }
}

/// Contiguous runs of bins with `value > bound`, as `[first, last]` bin frequencies.
fn ranges_above(freq_hz: &[f64], values: &[f64], bound: f64) -> Vec<[f64; 2]> {
    let mut ranges: Vec<[f64; 2]> = Vec::new();
    let mut open = false;
    for (&f, &value) in freq_hz.iter().zip(values) {
        if value > bound {
            match ranges.last_mut() {
                Some(range) if open => range[1] = f,
                _ => ranges.push([f, f]),
            }
            open = true;
        } else {
            open = false;
        }
    }
    ranges
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::ledger::test_signals::{resonance, white};

    const FS_HZ: f64 = 200.0;

    #[test]
    fn white_noise_psd_integrates_to_its_variance() {
        let variance: f64 = 2.5;
        let series: Vec<f64> = white(1, 20_000).iter().map(|x| x * variance.sqrt()).collect();
        let spectrum = welch_psd(&[&series], FS_HZ, 256).unwrap();
        let integral: f64 = spectrum.psd.iter().sum::<f64>() * bin_width_hz(&spectrum);
        assert!((integral / variance - 1.0).abs() < 0.05, "integral {integral}");
        // White: flat at s²/(fs/2) across the band.
        let level = variance / (FS_HZ / 2.0);
        let mid = &spectrum.psd[10..100];
        let mean_mid = mid.iter().sum::<f64>() / mid.len() as f64;
        assert!((mean_mid / level - 1.0).abs() < 0.05);
    }

    #[test]
    fn band_shares_sum_to_one() {
        let series = resonance(2, 10_000, 25.0, FS_HZ, 0.95);
        let spectrum = welch_psd(&[&series], FS_HZ, 256).unwrap();
        let shares = band_shares(&spectrum, &[0.0, 10.0, 20.0, 30.0, 100.0]);
        assert_eq!(shares.len(), 4);
        let total: f64 = shares.iter().map(|b| b.share).sum();
        assert!((total - 1.0).abs() < 1e-12, "{total}");
        assert!(shares[2].share > 0.5, "the 20-30 Hz band holds the resonance");
        assert!(band_shares(&spectrum, &[5.0]).is_empty());
        assert_eq!(band_shares(&spectrum, &[0.0, f64::NAN, 100.0]).len(), 0);
    }

    #[test]
    fn finds_a_lightly_damped_25_hz_resonance_in_noise() {
        let noise = white(3, 20_000);
        let resonant = resonance(4, 20_000, 25.0, FS_HZ, 0.99);
        let series: Vec<f64> = noise.iter().zip(&resonant).map(|(n, r)| 2.0 * n + 0.1 * r).collect();
        let spectrum = welch_psd(&[&series], FS_HZ, 512).unwrap();
        let peak = spectral_peak(&spectrum, 1.0, 90.0).unwrap();
        assert!((peak.freq_hz - 25.0).abs() < 1.0, "peak at {} Hz", peak.freq_hz);
        assert!(peak.ratio_to_local_median > 3.0, "ratio {}", peak.ratio_to_local_median);
    }

    #[test]
    fn welch_windows_never_straddle_a_join() {
        let a = white(5, 300);
        let b: Vec<f64> = white(6, 300).iter().map(|x| x + 100.0).collect();
        // 300 samples hold (300 − 128)/64 + 1 = 3 windows of 128 each; 6 in all, not 8.
        let spectrum = welch_psd(&[&a, &b], FS_HZ, 128).unwrap();
        assert_eq!(spectrum.n_windows, 6);
        // The offset step would otherwise dominate the lowest bins.
        assert!(spectrum.psd[1] < 10.0 * (1.0 / (FS_HZ / 2.0)));
    }

    #[test]
    fn independent_noise_stays_under_the_coherence_bound() {
        let mut above = 0;
        let mut bins = 0;
        for seed in 0..10 {
            let e = white(100 + seed, 16_384);
            let u = white(200 + seed, 16_384);
            let c = coherence("u", &[&e], &[&u], FS_HZ, 256).unwrap();
            above += c.gamma2.iter().filter(|&&g| g > c.bound_99).count();
            bins += c.gamma2.len();
        }
        let rate = above as f64 / bins as f64;
        assert!(rate <= 0.025, "{above} of {bins} bins above the 99 % bound");
    }

    #[test]
    fn equivalent_segments_follow_welch_for_hann_50() {
        let e = white(7, 16_384);
        let u = white(8, 16_384);
        let c = coherence("u", &[&e], &[&u], FS_HZ, 256).unwrap();
        assert_eq!(c.n_windows, 127);
        // c_1 = 1/6 for Hann at 50 % overlap (Harris 1978), c_2 = 0.
        let expected = 127.0 / (1.0 + 2.0 * (1.0 - 1.0 / 127.0) / 36.0);
        assert!((c.equivalent_segments / expected - 1.0).abs() < 0.01, "{} vs {expected}", c.equivalent_segments);
    }

    #[test]
    fn detects_a_shared_25_hz_sinusoid() {
        let n = 8192;
        let tone = |phase: f64| -> Vec<f64> {
            (0..n).map(|k| (2.0 * std::f64::consts::PI * 25.0 * k as f64 / FS_HZ + phase).sin()).collect()
        };
        let (t1, t2) = (tone(0.0), tone(1.0));
        let e: Vec<f64> = white(9, n).iter().zip(&t1).map(|(w, s)| w + 0.5 * s).collect();
        let u: Vec<f64> = white(10, n).iter().zip(&t2).map(|(w, s)| w + 0.5 * s).collect();
        let c = coherence("u", &[&e], &[&u], FS_HZ, 256).unwrap();
        let bin_25 = c.freq_hz.iter().position(|&f| (f - 25.0).abs() < 1e-9).unwrap();
        assert!(c.gamma2[bin_25] > 0.5, "γ²(25 Hz) = {}", c.gamma2[bin_25]);
        assert!(c.bands_above_bound.iter().any(|b| b[0] <= 25.0 && 25.0 <= b[1]));
    }

    #[test]
    fn degenerate_inputs_give_none() {
        let a = white(1, 100);
        assert!(welch_psd(&[&a], FS_HZ, 256).is_none());
        assert!(welch_psd(&[&a], 0.0, 32).is_none());
        assert!(welch_psd(&[], FS_HZ, 32).is_none());
        assert!(coherence("u", &[&a], &[&a[..90]], FS_HZ, 32).is_none());
        assert!(coherence("u", &[&a[..40]], &[&a[..40]], FS_HZ, 32).is_none());
        let flat = Spectrum { freq_hz: vec![0.0, 1.0], psd: vec![0.0, 0.0], n_windows: 1 };
        assert!(spectral_peak(&flat, 0.0, 10.0).is_none());
        let malformed = Spectrum { freq_hz: vec![0.0, 1.0, 2.0, 3.0], psd: vec![1.0, 5.0], n_windows: 1 };
        assert_eq!(spectral_peak(&malformed, 0.0, 10.0).unwrap().freq_hz, 1.0);
        assert_eq!(band_shares(&flat, &[0.0, 1.0])[0].share, 0.0);
    }
}

//! The gap ledger ("where"): the classical residual tests of [`super::ledger`] run on the
//! diagnosis's streams (docs/diagnosis.md, The gap ledger): the balance residual's
//! whiteness, its cross-correlation and coherence with every input, its spectrum by band, its
//! energy by regime, and the pressure innovations channel by channel.

use serde::Serialize;

use super::finding::channel_name;
use super::ledger::{self, BandShare, ChannelInnovation, CrossCorrelation, RegimeShare, Whiteness};
use super::streams::RunStreams;

/// Band edges of the ledger's spectrum, Hz.
pub const BAND_EDGES_HZ: [f64; 7] = [0.0, 0.5, 2.0, 10.0, 50.0, 150.0, 500.0];

/// Lags of the whiteness test.
const WHITENESS_LAGS: usize = 25;

/// Lags of the cross-correlations, samples.
const CCF_LAGS: usize = 100;

/// Welch segment length, samples.
const WELCH_SEGMENT: usize = 2048;

/// The gap ledger of one diagnosis.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct GapLedger {
    /// Ljung-Box on the held-out balance residual, before any effect.
    pub whiteness_before: Option<Whiteness>,
    /// The same after the named effects.
    pub whiteness_after: Option<Whiteness>,
    /// Residual-input cross-correlations (held-out), positive lags: the input leads.
    pub cross_correlation: Vec<CrossCorrelation>,
    /// Coherence bands above the 99 % Beta bound, per input.
    pub coherent_bands_hz: Vec<(String, Vec<[f64; 2]>)>,
    /// Share of the residual power beyond the white-noise floor, per band.
    pub bands: Vec<BandShare>,
    /// The band holding most of it, Hz.
    pub dominant_band_hz: Option<[f64; 2]>,
    /// Residual energy by regime, with stationary-bootstrap intervals.
    pub regimes: Vec<RegimeShare>,
    /// Per pressure channel, the innovation statistics.
    pub channels: Vec<ChannelInnovation>,
}

/// Builds the ledger; `remainder` is the balance residual after the named effects.
#[must_use]
pub fn build(runs: &[RunStreams], remainder: &[Vec<f64>], noise_var: f64, seed: u64) -> GapLedger {
    let Some(sample_hz) = runs.first().map(|run| run.sample_hz) else {
        return GapLedger::default();
    };
    let heldout = |values: &[Vec<f64>]| -> Vec<Vec<f64>> {
        runs.iter().zip(values).map(|(run, v)| v[run.heldout.clone()].to_vec()).collect()
    };
    let residual: Vec<Vec<f64>> = heldout(&runs.iter().map(|run| run.residual.clone()).collect::<Vec<_>>());
    let after = heldout(remainder);
    let residual_refs: Vec<&[f64]> = residual.iter().map(Vec::as_slice).collect();
    let after_refs: Vec<&[f64]> = after.iter().map(Vec::as_slice).collect();

    let inputs: Vec<(&str, Vec<Vec<f64>>)> = vec![
        ("phi_rad", heldout(&runs.iter().map(|r| r.phi_rad.clone()).collect::<Vec<_>>())),
        ("phi_dot_rad_s", heldout(&runs.iter().map(|r| r.phi_dot_rad_s.clone()).collect::<Vec<_>>())),
        ("phi_ddot_rad_s2", heldout(&runs.iter().map(|r| r.phi_ddot_rad_s2.clone()).collect::<Vec<_>>())),
        (
            "cmu_total",
            heldout(
                &runs.iter().map(|r| r.cmu[0].iter().zip(&r.cmu[1]).map(|(a, b)| a + b).collect()).collect::<Vec<_>>(),
            ),
        ),
        ("cl_sim", heldout(&runs.iter().map(RunStreams::cl_sim).collect::<Vec<_>>())),
    ];
    let mut cross_correlation = Vec::new();
    let mut coherent_bands_hz = Vec::new();
    for (name, input) in &inputs {
        // Only runs where the input moves: a constant input has no correlation to test.
        let (res, inp): (Vec<&[f64]>, Vec<&[f64]>) = residual_refs
            .iter()
            .zip(input)
            .filter(|(_, u)| u.iter().any(|v| (v - u[0]).abs() > 0.0))
            .map(|(r, u)| (*r, u.as_slice()))
            .unzip();
        if res.is_empty() {
            continue;
        }
        if let Some(ccf) = ledger::cross_correlation(name, &res, &inp, CCF_LAGS) {
            cross_correlation.push(ccf);
        }
        if let Some(coherence) = ledger::coherence(name, &res, &inp, sample_hz, WELCH_SEGMENT) {
            coherent_bands_hz.push(((*name).to_owned(), coherence.bands_above_bound));
        }
    }

    let (bands, dominant_band_hz) = match ledger::welch_psd(&residual_refs, sample_hz, WELCH_SEGMENT) {
        Some(spectrum) => {
            // Beyond the white-noise floor: a white noise of variance s^2 has the one-sided
            // density 2 s^2 / fs.
            let floor = 2.0 * noise_var / sample_hz;
            let excess = ledger::Spectrum {
                freq_hz: spectrum.freq_hz.clone(),
                psd: spectrum.psd.iter().map(|p| (p - floor).max(0.0)).collect(),
                n_windows: spectrum.n_windows,
            };
            let edges: Vec<f64> = BAND_EDGES_HZ.iter().copied().filter(|f| *f <= 0.5 * sample_hz).collect();
            let bands = ledger::band_shares(&excess, &edges);
            let dominant = bands
                .iter()
                .filter(|b| b.share.is_finite())
                .max_by(|a, b| a.share.total_cmp(&b.share))
                .map(|b| b.band_hz);
            (bands, dominant)
        }
        None => (Vec::new(), None),
    };

    // Regimes: blowing off/on, roll rate low/high, upstroke/downstroke.
    let labels: Vec<String> =
        ["held roll, no blowing", "held roll, blowing", "rolling, no blowing", "rolling, blowing"]
            .map(String::from)
            .to_vec();
    let rate_threshold = 0.05;
    let bins: Vec<Vec<usize>> = runs
        .iter()
        .map(|run| {
            let cmu_max = run.cmu.iter().flatten().copied().fold(0.0, f64::max);
            run.heldout
                .clone()
                .map(|idx| {
                    let blowing = cmu_max > 0.0 && run.cmu[0][idx] + run.cmu[1][idx] > 0.1 * cmu_max;
                    let rolling = run.phi_dot_rad_s[idx].abs() > rate_threshold;
                    usize::from(blowing) + 2 * usize::from(rolling)
                })
                .collect()
        })
        .collect();
    let bin_refs: Vec<&[usize]> = bins.iter().map(Vec::as_slice).collect();
    let regimes = ledger::regime_shares(&residual_refs, &bin_refs, &labels, seed, 200);

    let n_taps = runs.first().map_or(0, |run| run.cp.len());
    let channels = (0..n_taps)
        .map(|tap| {
            let raw: Vec<&[f64]> = runs.iter().map(|run| &run.cp[tap][run.heldout.clone()]).collect();
            let innovation: Vec<&[f64]> = runs.iter().map(|run| &run.innovation[tap][run.heldout.clone()]).collect();
            let std = ledger::difference_noise_var(&innovation).unwrap_or(0.0).sqrt();
            ledger::channel_innovation(&channel_name(tap), &raw, &innovation, std, sample_hz)
        })
        .collect();

    GapLedger {
        whiteness_before: ledger::ljung_box(&residual_refs, WHITENESS_LAGS, 0),
        whiteness_after: ledger::ljung_box(&after_refs, WHITENESS_LAGS, 0),
        cross_correlation,
        coherent_bands_hz,
        bands,
        dominant_band_hz,
        regimes,
        channels,
    }
}

//! Fit of the pressure path (paper section III.A; docs/equations.md, Time-shifted pressure model):
//! a time-shifted, reduced linear model of the 12 surface pressures with control inputs, its
//! steady-state Kalman filter, and the linear map of the filtered pressures to `C_l,roll,p`.
//!
//! 1. Delay embedding (shift-stacking, B. W. Brunton, Johnson, Ojemann & Kutz, J. Neurosci.
//!    Methods 258, 2016): `z_k = [x_k; x_{k-s}; ...; x_{k-(h-1)s}]`, `x = Cp`, newest block
//!    first, built inside each run and only where every needed tap is finite.
//! 2. Proper orthogonal decomposition of the centred snapshots: `Z - zbar = U S V^T`, truncated
//!    to the smallest rank keeping the configured energy (sum of `sigma^2`), at most
//!    [`PRESSURE_RANK`] and the data's rank. `U` comes from the eigen-decomposition (an SVD of a
//!    symmetric matrix) of the Gram matrix `(Z - zbar)(Z - zbar)^T`, whose eigenvalues are
//!    `sigma^2` (method of snapshots, Sirovich, Q. Appl. Math. 45, 1987).
//! 3. Reduced coordinates `a_k = U_r^T (z_k - zbar)`, so `z_k ~ zbar + U_r a_k` and, for the
//!    newest block, `Cp_k ~ C a_k + cp_mean` with `C` the first 12 rows of `U_r` and `cp_mean`
//!    the first 12 entries of `zbar`.
//! 4. DMD with control (Proctor, Brunton & Kutz, SIAM J. Appl. Dyn. Syst. 15, 2016):
//!    least squares `a_k ~ A a_{k-1} + B u_k` over consecutive snapshots, with the input of the
//!    step the state belongs to, because the core predicts step `k` as `A a_{k-1} + B u_k`.
//! 5. Stability: if the spectral radius of `A` exceeds the configured bound, `A` is scaled to it
//!    and `B` refitted with that `A`.
//! 6. Noise: `R` per tap from the median absolute deviation of second differences (white noise
//!    of variance `sigma^2` has second differences of variance `6 sigma^2`; a signal at
//!    `omega` keeps only `(omega dt)^4` of its variance, about 1e-8 for 3 Hz at 1 kHz; the
//!    median ignores spikes and steps; Gasser, Sroka & Jennen-Steinmetz, Biometrika 73, 1986);
//!    `Q = q_scale * cov(a_k - A a_{k-1} - B u_k)`, with `q_scale` from a grid, chosen to
//!    minimise the `R`-weighted mean squared innovation on the training data (the steady-state
//!    Kalman filter of the true model minimises the one-step prediction error: prediction-error
//!    identification, Ljung, System Identification, 2nd ed., 1999, section 7.3).
//! 7. The DARE ([`super::dare`]) gives `K` and `S`; `innovation_std = sqrt(diag S)`.
//! 8. `C_l,p = w . Cp_filtered + w0` by ridge least squares on the standardised filtered
//!    pressures of the disturbance runs (Hoerl & Kennard, Technometrics 12, 1970).
//!
//! The fit tunes, scores and maps the core's own filter
//! ([`estimator_core::pressure::PressureFilter`]) run in f64 on the table it builds
//! ([`PressureTable`], [`filter_step`]), so what it chooses is what flies, gating, isolation
//! and the stuck-channel check included.
//!
//! Modules: `identification` (steps 1-5), `tuning` (6-7), `cl_map` (8), `table` (the
//! table in f64 and the filter run on it).

mod cl_map;
mod identification;
mod table;
#[cfg(test)]
mod tests;
mod tuning;

use std::ops::Range;

use estimator_core::coeffs::{N_PRESSURE_INPUTS, N_TAPS, PRESSURE_RANK, PressureModel};
use firmware_sim::dataset::Channels;
use rayon::prelude::*;

use super::dare::{DareError, DareOptions};
use super::signals::RunSignals;
use cl_map::*;
use identification::*;
use table::*;
pub use table::{PressureStep, PressureTable, filter_step, run_pressure_filter};
pub use tuning::settle_steps;
use tuning::*;

/// One run's samples for the pressure fit or its evaluation, as the core sees them: the inputs
/// are held over missing samples and the roll rate is the core's filtered differentiator
/// (build them with [`super::signals::RunSignals`]); the pressures and `C_l` keep their NaNs.
///
/// All slices have the same length. A NaN input removes that step from the dynamics fit; a NaN
/// tap removes every snapshot that needs it; a NaN `cl` removes that sample from the map fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PressureRun<'a> {
    /// Roll angle, rad.
    pub phi_rad: &'a [f64],
    /// Filtered roll rate, rad/s (`estimator_core::rate`).
    pub phi_dot_rad_s: &'a [f64],
    /// Port and starboard momentum coefficients.
    pub cmu: [&'a [f64]; 2],
    /// Pressure coefficients `cp01`..`cp12`.
    pub cp: [&'a [f64]; N_TAPS],
    /// Measured roll-moment coefficient.
    pub cl: &'a [f64],
    /// Angle of attack, deg (it picks the map to `C_l` in the alpha schedule).
    pub alpha_deg: &'a [f64],
    /// The disturbance moment at every sample, where it is known: the measured `cl` of a roll
    /// run, or the disturbance model's moment in an actuation run (the wing is held, so the
    /// balance carries the jets' moment as well; the blowing changes the pressures too, and the
    /// map must not read that as roll moment). `None` for runs that mix both. Only runs with it
    /// fit the map to `C_l`.
    pub disturbance: Option<&'a [f64]>,
}

impl<'a> PressureRun<'a> {
    /// The samples `range` of a run: inputs from its derived signals, pressures and `C_l` from
    /// its channels, the disturbance moment (see [`PressureRun::disturbance`]) from
    /// `disturbance`, indexed like the channels.
    ///
    /// # Errors
    ///
    /// [`PressureFitError::RangeOutOfBounds`] when `range` does not lie inside all of them.
    pub fn from_signals(
        signals: &'a RunSignals,
        channels: &'a Channels,
        range: Range<usize>,
        disturbance: Option<&'a [f64]>,
    ) -> Result<Self, PressureFitError> {
        let len = signals.len().min(channels.len());
        let out_of_bounds = || PressureFitError::RangeOutOfBounds { start: range.start, end: range.end, len };
        let slice = |values: &'a [f64]| values.get(range.clone()).ok_or_else(out_of_bounds);
        let mut cp: [&'a [f64]; N_TAPS] = [&[]; N_TAPS];
        for (dst, src) in cp.iter_mut().zip(&channels.cp) {
            *dst = slice(src)?;
        }
        Ok(Self {
            phi_rad: slice(&signals.phi_rad)?,
            phi_dot_rad_s: slice(&signals.phi_dot_rad_s)?,
            cmu: [slice(&signals.cmu[0])?, slice(&signals.cmu[1])?],
            cp,
            cl: slice(&channels.cl)?,
            alpha_deg: slice(&signals.alpha_deg)?,
            disturbance: disturbance.map(slice).transpose()?,
        })
    }

    /// Number of samples.
    #[must_use]
    pub fn len(&self) -> usize {
        self.phi_rad.len()
    }

    /// True when the run has no samples.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.phi_rad.is_empty()
    }

    /// The pressure-model inputs `[phi_rad, phi_dot_rad_s, cmu_port, cmu_stbd, 1]` of sample
    /// `k` (which must be in range), as recorded (possibly NaN).
    fn inputs(&self, k: usize) -> [f64; N_PRESSURE_INPUTS] {
        [self.phi_rad[k], self.phi_dot_rad_s[k], self.cmu[0][k], self.cmu[1][k], 1.0]
    }

    /// The 12 pressures of sample `k` (which must be in range).
    fn cp_at(&self, k: usize) -> [f64; N_TAPS] {
        std::array::from_fn(|tap| self.cp[tap][k])
    }

    /// Checks that every slice has the run's length.
    fn check(&self, run: usize) -> Result<(), PressureFitError> {
        let expected = self.len();
        let named = [("phi_dot_rad_s", self.phi_dot_rad_s), ("cmu_port", self.cmu[0]), ("cmu_stbd", self.cmu[1])];
        let taps = self.cp.iter().map(|cp| ("cp", *cp));
        for (channel, values) in named.into_iter().chain(taps).chain([("cl", self.cl), ("alpha_deg", self.alpha_deg)]) {
            if values.len() != expected {
                return Err(PressureFitError::LengthMismatch { run, channel, len: values.len(), expected });
            }
        }
        Ok(())
    }
}

/// Settings of [`fit_pressure_model`].
#[derive(Debug, Clone, PartialEq)]
pub struct PressureFitConfig {
    /// Number of delay blocks `h` of the embedding (1 = no delays). Default 4.
    pub delays: usize,
    /// Samples `s` between delay blocks. Default 5: with `h = 4` the embedding spans 15 ms at
    /// 1 kHz, about two periods of the 120 Hz pressure tubing, while consecutive snapshots share
    /// no sample (so their noise is independent).
    pub delay_spacing: usize,
    /// Energy fraction (`sum sigma^2`) the truncated basis keeps. Default 0.999.
    pub energy_fraction: f64,
    /// Largest spectral radius of the fitted `A`. Default 0.999 (a 1 s time constant at 1 kHz,
    /// slower than any pressure dynamics of a roll at 0.25-3 Hz).
    pub max_spectral_radius: f64,
    /// Candidate factors of the residual covariance for `Q`. Default `10^-3 .. 10^1` in half
    /// decades: the raw residual covariance also carries projected measurement noise (too
    /// large) and unmodelled dynamics (too small), so the factor spans both directions.
    pub q_scales: Vec<f64>,
    /// Innovation gate in standard deviations. Default 5.0 (a false rejection rate of 6e-7 per
    /// Gaussian sample).
    pub gate_sigma: f64,
    /// Consecutive rejections after which a channel is isolated. Default 20 (20 ms at 1 kHz).
    pub isolate_after: u16,
    /// Ridge of the `C_l` map relative to the standardised columns' unit variance (> 0). Default
    /// 1e-6: the filtered pressures span only `rank` < 12 directions, so the ridge picks the
    /// smallest weights in the unexcited ones without biasing the excited ones.
    pub ridge: f64,
    /// Samples at the start of each run left out of the scores and the `C_l` fit while the
    /// filter (started at the mean pressures) settles. Default 200 (0.2 s).
    pub warmup_samples: usize,
    /// Settings of the DARE solver.
    pub dare: DareOptions,
}

impl Default for PressureFitConfig {
    fn default() -> Self {
        Self {
            delays: 4,
            delay_spacing: 5,
            energy_fraction: 0.999,
            max_spectral_radius: 0.999,
            q_scales: (-6..=2).map(|half_decade| 10f64.powf(f64::from(half_decade) / 2.0)).collect(),
            gate_sigma: 5.0,
            isolate_after: 20,
            ridge: 1e-6,
            warmup_samples: 200,
            dare: DareOptions::default(),
        }
    }
}

/// What the fit chose and how well it fits the training data.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PressureFitReport {
    /// Modes kept, `r`.
    pub rank: usize,
    /// Rank of the centred snapshot matrix (singular values above `1e-6 sigma_max`).
    pub data_rank: usize,
    /// Energy fraction (`sum sigma^2`) the `r` modes keep.
    pub energy_kept: f64,
    /// Spectral radius of the least-squares `A`.
    pub spectral_radius_fitted: f64,
    /// Spectral radius of the `A` in the model (lower when it was scaled).
    pub spectral_radius: f64,
    /// True when `A` was scaled to [`PressureFitConfig::max_spectral_radius`].
    pub stabilised: bool,
    /// Chosen factor of the residual covariance for `Q`.
    pub q_scale: f64,
    /// Doubling steps of the DARE solver.
    pub dare_iterations: usize,
    /// Relative residual of the DARE at the solution.
    pub dare_residual: f64,
    /// Estimated measurement noise variance of each tap (`R`).
    pub noise_variance: [f64; N_TAPS],
    /// RMS over taps and samples of the one-step prediction error `Cp - (C a_pred + cp_mean)`.
    pub cp_prediction_rms: f64,
    /// RMS of `Cp - (C a + cp_mean)` after the update.
    pub cp_filtered_rms: f64,
    /// RMS of `cl - C_l,p` on the training samples of the disturbance runs.
    pub cl_rms: f64,
    /// Standard deviation of `cl` on those samples.
    pub cl_std: f64,
    /// Delay-embedded snapshots (the POD's columns).
    pub n_snapshots: usize,
    /// Consecutive snapshot pairs with finite inputs (the dynamics fit's rows).
    pub n_dynamics_samples: usize,
    /// Samples of the `C_l` map fit.
    pub n_cl_samples: usize,
    /// Taps (1-based, `cpNN`) with finite data in fewer than half of the training samples,
    /// fitted as absent.
    pub dead_taps: Vec<usize>,
    /// Steps after the start before the innovation gate is armed ([`settle_steps`]).
    pub settle_steps: u16,
}

/// A fitted pressure path: the core's table, the same table in f64, and the report.
#[derive(Debug, Clone, PartialEq)]
pub struct PressureFit {
    /// The table for `CoefficientSet::pressure`.
    pub model: PressureModel,
    /// The table in f64 before rounding (for [`run_pressure_filter`]).
    pub table: PressureTable,
    /// Choices and training scores.
    pub report: PressureFitReport,
}

/// Why the pressure model could not be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PressureFitError {
    /// A setting is out of its range.
    #[error("invalid pressure-fit setting: {0}")]
    InvalidConfig(&'static str),
    /// A channel of a run has a different length from the run's `phi_rad`.
    #[error("run {run}: {channel} has {len} samples, expected {expected}")]
    LengthMismatch {
        /// Index of the run in the slice passed.
        run: usize,
        /// Which channel.
        channel: &'static str,
        /// Its length.
        len: usize,
        /// The run's length.
        expected: usize,
    },
    /// A sample range does not lie inside the run.
    #[error("sample range {start}..{end} is outside a run of {len} samples")]
    RangeOutOfBounds {
        /// Start of the range.
        start: usize,
        /// End of the range.
        end: usize,
        /// Samples in the run.
        len: usize,
    },
    /// Not enough usable samples for a step of the fit.
    #[error("too few usable samples for the {stage}: {found}, need at least {needed}")]
    TooFewSamples {
        /// Which step of the fit.
        stage: &'static str,
        /// Usable samples found.
        found: usize,
        /// Samples needed.
        needed: usize,
    },
    /// A dense decomposition did not converge or was singular.
    #[error("the {0} failed")]
    Decomposition(&'static str),
    /// The Riccati equation could not be solved.
    #[error("steady-state Kalman gain: {0}")]
    Dare(#[from] DareError),
    /// A fitted value is not finite.
    #[error("non-finite value in the {0}")]
    NonFinite(&'static str),
    /// No tap has data in at least half of the training samples.
    #[error("no pressure tap has data in at least half of the training samples")]
    NoPressureData,
    /// The fitted model does not make a core table.
    #[error("the pressure model cannot become a core table: {0}")]
    InvalidModel(&'static str),
}

/// Fits the pressure path on the training samples in `runs` (module docs, steps 1-8).
///
/// # Errors
///
/// [`PressureFitError`] for an invalid setting, mismatched channel lengths, too few usable
/// samples, a failed decomposition or DARE, or a non-finite result.
pub fn fit_pressure_model(
    runs: &[PressureRun<'_>],
    config: &PressureFitConfig,
    breakpoints_deg: &[f64],
) -> Result<PressureFit, PressureFitError> {
    check_config(config)?;
    for (idx, run) in runs.iter().enumerate() {
        run.check(idx)?;
    }
    // A tap without data (a blocked tube, a dead scanner port) would leave no snapshot in
    // which every tap is finite: it is fitted as a constant zero instead, so its row of `C`
    // and its column of `K` come out exactly zero and the filter neither predicts nor uses it.
    let dead = dead_taps(runs);
    if dead.iter().all(|&is_dead| is_dead) {
        return Err(PressureFitError::NoPressureData);
    }
    let zeros: Vec<Vec<f64>> = runs.iter().map(|run| vec![0.0; run.len()]).collect();
    let filled: Vec<PressureRun<'_>> = runs
        .iter()
        .zip(&zeros)
        .map(|(run, zeros)| {
            let mut run = *run;
            for (cp, _) in run.cp.iter_mut().zip(&dead).filter(|(_, is_dead)| **is_dead) {
                *cp = zeros;
            }
            run
        })
        .collect();
    let runs = &filled[..];
    let embedding = Embedding { delays: config.delays, spacing: config.delay_spacing };
    let pod = Pod::fit(runs, &embedding, config.energy_fraction)?;
    let reduced: Vec<ReducedRun> = runs.par_iter().map(|run| pod.reduce(run, &embedding)).collect();
    let dynamics = Dynamics::fit(runs, &reduced, config.max_spectral_radius)?;
    let mut noise_variance = noise_variance(runs)?;
    // A dead tap's zero has no noise; the median of the live taps keeps its gate ordinary
    // should it carry data in a later recording (its gain column is zero either way).
    let mut live: Vec<f64> = (0..N_TAPS).filter(|&tap| !dead[tap]).map(|tap| noise_variance[tap]).collect();
    let typical = stats::median_high(&mut live).unwrap_or(MIN_NOISE_VARIANCE);
    for (variance, _) in noise_variance.iter_mut().zip(&dead).filter(|(_, is_dead)| **is_dead) {
        *variance = typical;
    }
    let base = untuned_model(&pod, &dynamics, config, breakpoints_deg)?;
    let tuned = tune_filter(runs, base, &dynamics.residual_cov, &noise_variance, config)?;
    let mut table = tuned.table;
    // The eigen-solver leaves round-off where a dead tap's row of `C` is zero in exact
    // arithmetic; make it exact, and its gain column with it.
    for tap in (0..N_TAPS).filter(|&tap| dead[tap]) {
        table.model.c[tap] = [0.0; PRESSURE_RANK];
        for row in &mut table.model.gain {
            row[tap] = 0.0;
        }
    }
    let mut map = fit_cl_map(runs, &table, config)?;
    for weights in &mut map.weights {
        for (weight, _) in weights.iter_mut().zip(&dead).filter(|(_, is_dead)| **is_dead) {
            *weight = 0.0;
        }
    }
    // Slots past the schedule's breakpoints repeat the last map (the core never reads them).
    let last = map.weights.len().saturating_sub(1);
    table.model.cl_weights =
        std::array::from_fn(|idx| map.weights.get(idx.min(last)).copied().unwrap_or([0.0; N_TAPS]));
    table.model.cl_offset = std::array::from_fn(|idx| map.offsets.get(idx.min(last)).copied().unwrap_or(0.0));
    table.model.settle_steps = settle_steps(&table, &state_covariance(&reduced))?;
    let model = table.to_core()?;
    let report = PressureFitReport {
        rank: pod.rank,
        data_rank: pod.data_rank,
        energy_kept: pod.energy_kept,
        spectral_radius_fitted: dynamics.radius_fitted,
        spectral_radius: dynamics.radius,
        stabilised: dynamics.radius_fitted > config.max_spectral_radius,
        q_scale: tuned.q_scale,
        dare_iterations: tuned.dare_iterations,
        dare_residual: tuned.dare_residual,
        noise_variance,
        cp_prediction_rms: tuned.scores.prediction_rms(),
        cp_filtered_rms: tuned.scores.filtered_rms(),
        cl_rms: map.rms,
        cl_std: map.cl_std,
        n_snapshots: pod.n_snapshots,
        n_dynamics_samples: dynamics.n_samples,
        n_cl_samples: map.n_samples,
        dead_taps: (0..N_TAPS).filter(|&tap| dead[tap]).map(|tap| tap + 1).collect(),
        settle_steps: table.model.settle_steps,
    };
    Ok(PressureFit { model, table, report })
}

/// Checks the settings' ranges.
fn check_config(config: &PressureFitConfig) -> Result<(), PressureFitError> {
    let checks = [
        (config.delays >= 1, "delays must be >= 1"),
        (config.delay_spacing >= 1, "delay_spacing must be >= 1"),
        (config.energy_fraction > 0.0 && config.energy_fraction <= 1.0, "energy_fraction must be in (0, 1]"),
        (config.max_spectral_radius > 0.0 && config.max_spectral_radius < 1.0, "max_spectral_radius must be in (0, 1)"),
        (
            !config.q_scales.is_empty() && config.q_scales.iter().all(|&q| q.is_finite() && q > 0.0),
            "q_scales must be non-empty, finite and > 0",
        ),
        (config.gate_sigma.is_finite() && config.gate_sigma > 0.0, "gate_sigma must be finite and > 0"),
        (config.ridge.is_finite() && config.ridge > 0.0, "ridge must be finite and > 0"),
    ];
    match checks.into_iter().find(|(ok, _)| !ok) {
        Some((_, message)) => Err(PressureFitError::InvalidConfig(message)),
        None => Ok(()),
    }
}

//! Fit of the plant model of one jet, the paper's eq. 5: `C_l,AFC[k+1] = Xi Theta(C_l,AFC[k],
//! Cmu[k], dCmu[k], alpha[k])`, with the paper's library (all products up to degree 2 of the
//! four variables, without `C_l,AFC^2`, section III.B), on the actuation runs; extended by a
//! cube of Cmu and by the slow state `C_l,slow` of [`estimator_core::coeffs::PlantParams`],
//! whose time constant is profiled on a grid. Sparsity decides: a plant that is first order
//! and quadratic keeps the paper's terms only.
//!
//! At 1 kHz, `C_l[k+1]` is nearly `C_l[k]`, so thresholds would act on the identity rather
//! than on the dynamics; the regression therefore targets the increment
//! `C_l[k+1] - C_l[k]` and the identity is added back to the `C_l,AFC` term afterwards
//! (docs/equations.md, "Sparse regression: sampling, threshold sweep, excitation"). Regressor and target use the balance
//! moment through a zero-phase low-pass, so that measurement noise in the regressor does not
//! bias the lag towards zero. Every model of the threshold sweep is simulated open loop over
//! validation samples (the end of the training part), as the core runs it, and the selection
//! uses that free-run error; the chosen support is then refitted on the whole training part
//! ([`super::split`]).

use std::ops::Range;

use estimator_core::coeffs::{MAX_TERMS, MAX_VARS, PlantParams, plant_var};
use estimator_core::plant::Plant;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use rayon::prelude::*;

use super::FitError;
use super::signals::{RunSignals, first_order_lag, zero_phase_lowpass};
use super::sparse_fit::{
    SelectBy, SparseFit, effective_samples, lag_one_autocorrelation, refit_support, select_index, sparse_fit,
};
use sindy::{HeldoutScore, Library, Normalisation, QrProblem, SelectionConfig, StlsConfig, log_thresholds, sweep};

/// Most terms of a selected increment model: one slot of the core's table
/// ([`MAX_TERMS`]) stays free for the identity term `C_l,AFC[k]` that turns the increment into
/// the difference equation ([`add_identity`]), which the selected support may lack.
const PLANT_MAX_TERMS: usize = MAX_TERMS - 1;
/// Variable names of the plant library, in the core's order (`estimator_core::coeffs::plant_var`).
pub const PLANT_VARIABLES: [&str; 5] = ["cl_afc", "cmu", "dcmu", "alpha", "cl_slow"];

/// The paper's four plant variables.
const PAPER_VARIABLES: [&str; 4] = ["cl_afc", "cmu", "dcmu", "alpha"];

/// Time constants of the slow state tried by the fit, s: from a few convective times of a
/// small wing to the half-second wake relaxation of a large one (docs/equations.md, "The
/// synthetic tunnel's model", puts the turn-on overshoot's decay at about 1.5 c/U).
pub const SLOW_TAU_GRID_S: [f64; 8] = [0.015, 0.025, 0.04, 0.06, 0.1, 0.16, 0.25, 0.4];

/// Largest |C_l,AFC| a simulated candidate may reach before it counts as diverged.
const DIVERGED: f64 = 1.0;

/// Settings of the plant fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantConfig {
    /// Corner of the zero-phase low-pass on the balance moment, Hz.
    pub corner_hz: f64,
    /// Number of swept thresholds.
    pub n_thresholds: usize,
    /// Smallest threshold as a fraction of the largest normalised least-squares coefficient.
    pub min_fraction: f64,
}

impl Default for PlantConfig {
    fn default() -> Self {
        Self { corner_hz: 40.0, n_thresholds: 40, min_fraction: 1e-5 }
    }
}

/// One actuation run's samples for the plant fit.
#[derive(Debug, Clone)]
pub struct PlantRun<'a> {
    /// The run's signals.
    pub signals: &'a RunSignals,
    /// Samples the candidates are fitted on (the training part less its validation part).
    pub train: Range<usize>,
    /// Samples the structure is chosen on (the end of the training part); the chosen structure
    /// is then refitted on `train` and `validation` together. The held-out part of the run is
    /// not here at all.
    pub validation: Range<usize>,
    /// The moment this jet's model must reproduce: the balance, less the other jet's modelled
    /// moment when both jets blow in the run (NaN where the balance is missing).
    pub target: Vec<f64>,
}

impl PlantRun<'_> {
    /// The whole training part: `train` and `validation` together.
    fn training(&self) -> Range<usize> {
        self.train.start..self.validation.end.max(self.train.end)
    }
}

/// The paper's plant library: products up to degree 2 of `(C_l,AFC, Cmu, dCmu, alpha)`
/// including the constant, without `C_l,AFC^2`, plus the alpha-interactions of degree 3; and
/// the extension: `Cmu^3` (the jet's moment is sub-linear in Cmu, jet-flap theory's square
/// root, which a quadratic alone fits poorly over the whole range) and the slow state alone and
/// times alpha.
pub fn plant_library() -> Result<Library, FitError> {
    let paper = Library::polynomial(&PAPER_VARIABLES, 2, true)?;
    let mut library = Library::new(&PLANT_VARIABLES)?;
    for term in paper.terms() {
        library.push(*term)?;
    }
    let square = library.monomial(&[("cl_afc", 2)], &[])?;
    library.exclude_term(&square);
    // The paper fitted separate models at low and high alpha; with alpha as an input, the
    // alpha-dependence of the gain and of the time constant needs the degree-3 terms that
    // multiply the degree-2 actuation terms by alpha.
    for factors in [
        &[("cmu", 2), ("alpha", 1)][..],
        &[("cmu", 1), ("alpha", 2)],
        &[("cl_afc", 1), ("alpha", 2)],
        &[("cl_afc", 1), ("cmu", 1), ("alpha", 1)],
        &[("cmu", 3)],
        &[("cl_slow", 1)],
        &[("cl_slow", 1), ("alpha", 1)],
    ] {
        library.push(library.monomial(factors, &[])?)?;
    }
    Ok(library)
}

/// A run's regressors at every sample for jet `side`: the core's plant in f64
/// ([`Plant::forced_variables`]) with its moment set to `cl_afc` at every sample, so that the
/// slow state, the Cmu limit and `dCmu` are the ones the core runs.
fn variables(signals: &RunSignals, side: usize, cl_afc: &[f64], shape: Shape) -> Vec<[f64; MAX_VARS]> {
    let mut plant = Plant::<f64>::new();
    (0..signals.len())
        .map(|k| {
            let alpha_rad = signals.alpha_deg[k].to_radians();
            plant.forced_variables(shape.slow_pole, shape.cmu_max, signals.cmu[side][k], alpha_rad, cl_afc[k])
        })
        .collect()
}

/// The plant's structure besides its terms: the slow pole and the Cmu range
/// ([`PlantParams`]).
#[derive(Debug, Clone, Copy)]
struct Shape {
    slow_pole: f64,
    cmu_max: f64,
}

/// The sweep at one slow pole, its selected model scored on the held-out samples.
struct PoleSweep {
    shape: Shape,
    scored: sindy::ScoredSweep,
}

impl PoleSweep {
    fn free_run_rms(&self) -> f64 {
        self.scored.selected().heldout.free_run_rms.filter(|rms| rms.is_finite()).unwrap_or(f64::INFINITY)
    }
}

/// Fits jet `side` (0 = port, 1 = starboard) on `runs`; returns the core's model and the report.
///
/// The slow pole is profiled: the sweep and its free-run selection run at every time constant
/// of [`SLOW_TAU_GRID_S`], the pole whose selected model runs best open loop on the validation
/// samples is kept, and only that model is refined by output error (kept when that lowers the
/// validation error). The chosen pole and support are then refitted on the training and
/// validation samples together, by equation error and, if it was kept, output error.
pub fn fit_plant(
    runs: &[PlantRun<'_>],
    side: usize,
    sample_hz: f64,
    config: &PlantConfig,
) -> Result<(PlantParams, SparseFit), FitError> {
    let library = plant_library()?;
    // Filtered up to the end of the training part only: the backward pass of a zero-phase
    // filter would otherwise carry held-out samples into the last training samples.
    let filtered: Vec<Vec<f64>> = runs
        .iter()
        .map(|run| {
            let end = run.training().end.min(run.target.len());
            let mut smooth = zero_phase_lowpass(&run.target[..end], config.corner_hz, sample_hz);
            smooth.resize(run.target.len(), f64::NAN);
            smooth
        })
        .collect();
    let cmu_max = runs
        .iter()
        .flat_map(|run| run.signals.cmu[side][run.training()].iter().copied())
        .filter(|cmu| cmu.is_finite())
        .fold(0.0, f64::max);
    if cmu_max <= 0.0 {
        return Err(FitError::NoPlantModel { side });
    }
    let sweeps: Vec<Result<PoleSweep, FitError>> = SLOW_TAU_GRID_S
        .par_iter()
        .map(|&tau_s| {
            let shape = Shape { slow_pole: (-1.0 / (tau_s * sample_hz)).exp(), cmu_max };
            sweep_at(shape, &library, runs, &filtered, side, config)
        })
        .collect();
    let mut best: Option<PoleSweep> = None;
    for candidate in sweeps {
        let candidate = candidate?;
        if best.as_ref().is_none_or(|best| candidate.free_run_rms() < best.free_run_rms()) {
            best = Some(candidate);
        }
    }
    let PoleSweep { shape, mut scored } = best.ok_or(FitError::NoPlantModel { side })?;
    let selected = scored.selected().point.coefficients.clone();
    // Output-error refinement of the selected support, kept when it also lowers the validation
    // free-run error (the error the core's open-loop plant makes).
    let refined = refine_output_error(&library, runs, side, shape, &selected);
    let before = score(&library, runs, &filtered, side, shape, &selected).free_run_rms;
    let after = score(&library, runs, &filtered, side, shape, &refined);
    let refine = after.free_run_rms.zip(before).is_some_and(|(after, before)| after < before);
    if refine {
        let point = &mut scored.points[scored.selected];
        point.point.coefficients.clone_from(&refined);
        point.heldout = after;
    }
    // The chosen structure refitted on the whole training part.
    let whole: Vec<PlantRun<'_>> =
        runs.iter().map(|run| PlantRun { train: run.training(), validation: 0..0, ..run.clone() }).collect();
    let (samples, targets) = increment_rows(&whole, &filtered, side, shape);
    let support: Vec<bool> = selected.iter().map(|&c| c != 0.0).collect();
    let mut coefficients = refit_support(&library.theta(&samples)?, &targets, &support)?;
    if refine {
        coefficients = refine_output_error(&library, &whole, side, shape, &coefficients);
    }
    let n_train = targets.len();
    add_identity(&library, &mut coefficients)?;
    let model = library.to_sparse_model(&coefficients)?;
    let uses_slow =
        model.terms[..usize::from(model.n_terms)].iter().any(|term| term.monomial.powers()[plant_var::CL_SLOW] > 0);
    // Without slow terms the pole changes nothing; zero says so in the tables.
    let slow_pole = if uses_slow { shape.slow_pole as f32 } else { 0.0 };
    let report =
        sparse_fit(&library, &scored, SelectBy::FreeRun, PLANT_MAX_TERMS, scored.selected, &coefficients, n_train);
    Ok((PlantParams { slow_pole, cmu_max: cmu_max as f32, model }, report))
}

/// The increment regression's rows over the `train` samples of `runs`.
fn increment_rows(
    runs: &[PlantRun<'_>],
    filtered: &[Vec<f64>],
    side: usize,
    shape: Shape,
) -> (Vec<[f64; MAX_VARS]>, Vec<f64>) {
    let (mut samples, mut targets) = (Vec::new(), Vec::new());
    for (run, smooth) in runs.iter().zip(filtered) {
        let vars = variables(run.signals, side, smooth, shape);
        for k in run.train.start..run.train.end.saturating_sub(1) {
            samples.push(vars[k]);
            targets.push(smooth[k + 1] - smooth[k]);
        }
    }
    (samples, targets)
}

/// The threshold sweep of the increment regression at one slow pole, scored open loop on the
/// validation samples, with the free-run selection made.
fn sweep_at(
    shape: Shape,
    library: &Library,
    runs: &[PlantRun<'_>],
    filtered: &[Vec<f64>],
    side: usize,
    config: &PlantConfig,
) -> Result<PoleSweep, FitError> {
    let (samples, targets) = increment_rows(runs, filtered, side, shape);
    let problem = QrProblem::new(&library.theta(&samples)?, &targets)?;
    let stls = StlsConfig { threshold: 0.0, alpha: 0.0, max_iter: 20, unbias: true, normalisation: Normalisation::Rms };
    let thresholds = log_thresholds(&problem, Normalisation::Rms, config.n_thresholds, config.min_fraction)?;
    let swept = sweep(&problem, &stls, &thresholds)?;
    let validation = |coefficients: &[f64]| score(library, runs, filtered, side, shape, coefficients);
    let mut scored = swept.select(validation, &SelectionConfig::default())?;
    scored.selected =
        select_index(&scored, SelectBy::FreeRun, PLANT_MAX_TERMS).ok_or(FitError::NoPlantModel { side })?;
    Ok(PoleSweep { shape, scored })
}

/// Refines the non-zero coefficients of an increment model by Levenberg-Marquardt on the
/// open-loop simulation error over the training samples (an output-error fit; Ljung, System
/// Identification, section 4.2): the equation-error fit of the sweep is biased for a model that
/// runs open loop, and this removes the bias on the chosen support.
fn refine_output_error(
    library: &Library,
    runs: &[PlantRun<'_>],
    side: usize,
    shape: Shape,
    coefficients: &[f64],
) -> Vec<f64> {
    let support: Vec<usize> = (0..coefficients.len()).filter(|&idx| coefficients[idx] != 0.0).collect();
    let problem = OutputError { library, runs, side, shape, support: support.clone(), full: coefficients.to_vec() };
    let (solved, _) = LevenbergMarquardt::new().with_patience(30).minimize(problem);
    if solved.full.iter().all(|c| c.is_finite()) { solved.full } else { coefficients.to_vec() }
}

/// The output-error problem on the support of an increment model.
struct OutputError<'a, 'b> {
    library: &'a Library,
    runs: &'a [PlantRun<'b>],
    side: usize,
    shape: Shape,
    support: Vec<usize>,
    full: Vec<f64>,
}

impl OutputError<'_, '_> {
    fn residuals_of(&self, full: &[f64]) -> Vec<f64> {
        let mut residuals = Vec::new();
        for run in self.runs {
            let simulated = simulate_increments(self.library, full, run.signals, self.side, self.shape, run.train.end);
            for k in run.train.clone() {
                if run.target[k].is_finite() {
                    // A diverged candidate is a large finite error, so the optimiser backs off.
                    let value = if simulated[k].is_finite() { simulated[k] } else { DIVERGED };
                    residuals.push(value - run.target[k]);
                }
            }
        }
        residuals
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for OutputError<'_, '_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        for (&slot, value) in self.support.iter().zip(x.iter()) {
            self.full[slot] = *value;
        }
    }

    fn params(&self) -> DVector<f64> {
        DVector::from_iterator(self.support.len(), self.support.iter().map(|&slot| self.full[slot]))
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        Some(DVector::from_vec(self.residuals_of(&self.full)))
    }

    /// Forward differences, one coefficient per thread.
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let base = self.residuals_of(&self.full);
        let columns: Vec<Vec<f64>> = self
            .support
            .par_iter()
            .map(|&slot| {
                let step = 1e-7 * self.full[slot].abs().max(1e-9);
                let mut shifted = self.full.clone();
                shifted[slot] += step;
                self.residuals_of(&shifted).iter().zip(&base).map(|(h, b)| (h - b) / step).collect()
            })
            .collect();
        let jacobian = DMatrix::from_fn(base.len(), self.support.len(), |row, col| columns[col][row]);
        jacobian.iter().all(|value| value.is_finite()).then_some(jacobian)
    }
}

/// Turns increment coefficients into the absolute form of eq. 5 (`C[k+1] = C[k] + ...`).
fn add_identity(library: &Library, coefficients: &mut [f64]) -> Result<(), FitError> {
    let identity = library.monomial(&[("cl_afc", 1)], &[])?;
    let slot = library
        .terms()
        .iter()
        .position(|term| *term == identity)
        .ok_or(FitError::Internal("the plant library lacks C_l,AFC"))?;
    coefficients[slot] += 1.0;
    Ok(())
}

/// Validation one-step and free-run errors of an increment model.
fn score(
    library: &Library,
    runs: &[PlantRun<'_>],
    filtered: &[Vec<f64>],
    side: usize,
    shape: Shape,
    coefficients: &[f64],
) -> HeldoutScore {
    let (mut one_step_sq, mut n_one_step) = (0.0, 0usize);
    let mut free_run_errors = Vec::new();
    for (run, smooth) in runs.iter().zip(filtered) {
        let vars = variables(run.signals, side, smooth, shape);
        for k in run.validation.start..run.validation.end.saturating_sub(1) {
            let predicted = library.predict(coefficients, &vars[k]).unwrap_or(f64::NAN);
            one_step_sq += (predicted - (smooth[k + 1] - smooth[k])).powi(2);
            n_one_step += 1;
        }
        let simulated = simulate_increments(library, coefficients, run.signals, side, shape, run.validation.end);
        for k in run.validation.clone() {
            if run.target[k].is_finite() {
                free_run_errors.push(simulated[k] - run.target[k]);
            }
        }
    }
    let rms = |sum: f64, n: usize| if n == 0 { f64::NAN } else { (sum / n as f64).sqrt() };
    let free_run_sq: f64 = free_run_errors.iter().map(|e| e * e).sum();
    HeldoutScore {
        one_step_rms: rms(one_step_sq, n_one_step),
        free_run_rms: Some(rms(free_run_sq, free_run_errors.len())),
        n_samples: effective_samples(free_run_errors.len(), lag_one_autocorrelation(&free_run_errors)),
    }
}

/// Open-loop simulation of an increment model from rest over the first `end` samples: the
/// core's plant ([`Plant::step_by`]) in f64 on the recorded Cmu, its next moment the present
/// one plus the model's increment. From the first step the core would reset (a state beyond
/// +-1, [`DIVERGED`]) the candidate counts as diverged: NaN.
fn simulate_increments(
    library: &Library,
    coefficients: &[f64],
    signals: &RunSignals,
    side: usize,
    shape: Shape,
    end: usize,
) -> Vec<f64> {
    let mut plant = Plant::<f64>::new();
    let mut diverged = false;
    (0..end.min(signals.len()))
        .map(|k| {
            let alpha_rad = signals.alpha_deg[k].to_radians();
            let (current, reset) =
                plant.step_by(shape.slow_pole, shape.cmu_max, signals.cmu[side][k], alpha_rad, |vars| {
                    vars[plant_var::CL_AFC] + library.predict(coefficients, vars).unwrap_or(f64::NAN)
                });
            let value = if diverged { f64::NAN } else { current };
            diverged |= reset;
            value
        })
        .collect()
}

/// The starboard model mirrored from the port one, for datasets that blow one side only: the
/// mirror image of the wing gives `C_stbd[k+1] = -f_port(-C_stbd[k], Cmu, dCmu, alpha,
/// -C_slow[k])`, so a term with an even total power of `C_l,AFC` and `C_l,slow` changes sign and
/// one with an odd power keeps it.
#[must_use]
pub fn mirrored(port: &PlantParams) -> PlantParams {
    let mut starboard = *port;
    for term in starboard.model.terms.iter_mut() {
        let powers = term.monomial.powers();
        if (powers[plant_var::CL_AFC] + powers[plant_var::CL_SLOW]) % 2 == 0 {
            term.coeff = -term.coeff;
        }
    }
    starboard
}

/// Time constants of the first-order responses of [`initial_split`], s: a fast rise and a slow
/// settling, the two time scales of a jet's response.
const SPLIT_TAU_S: [f64; 2] = [0.02, 0.1];

/// A first guess of each jet's moment in runs where both jets blow: the balance regressed
/// jointly on both jets' Cmu, its square and its cube, each through first-order lags (a
/// Hammerstein model linear in its parameters), fitted on the training samples and split into
/// the two jets' parts; `None` when the regression has too few samples.
///
/// Why: the equation-error regression of one jet needs that jet's own moment as its state,
/// and the balance carries the sum of both. Backfitting from a zero guess for the other jet
/// starts from a state polluted by the other jet's whole moment, and it does not recover.
#[must_use]
pub fn initial_split(runs: &[(&RunSignals, Range<usize>)], sample_hz: f64) -> Option<Vec<[Vec<f64>; 2]>> {
    let scale = runs
        .iter()
        .flat_map(|(signals, _)| signals.cmu.iter().flat_map(|side| side.iter().copied()))
        .filter(|cmu| cmu.is_finite())
        .fold(0.0, f64::max);
    if scale <= 0.0 {
        return None;
    }
    let per_side = 3 * SPLIT_TAU_S.len();
    // Every run's columns: per side, each power through each lag; then the constant.
    let columns: Vec<Vec<Vec<f64>>> = runs
        .iter()
        .map(|(signals, _)| {
            let mut columns = Vec::with_capacity(2 * per_side + 1);
            for cmu in &signals.cmu {
                for power in 1..=3 {
                    let input: Vec<f64> = cmu.iter().map(|c| (c.max(0.0) / scale).powi(power)).collect();
                    for tau_s in SPLIT_TAU_S {
                        columns.push(first_order_lag(&input, tau_s, 1.0 / sample_hz));
                    }
                }
            }
            columns.push(vec![1.0; signals.len()]);
            columns
        })
        .collect();
    let n_columns = 2 * per_side + 1;
    let (mut rows, mut targets) = (Vec::new(), Vec::new());
    for ((signals, train), run_columns) in runs.iter().zip(&columns) {
        for k in train.clone() {
            if signals.cl[k].is_finite() {
                rows.extend(run_columns.iter().map(|column| column[k]));
                targets.push(signals.cl[k]);
            }
        }
    }
    if targets.len() < 10 * n_columns {
        return None;
    }
    let design = DMatrix::from_row_slice(targets.len(), n_columns, &rows);
    let beta = design.svd(true, true).solve(&DVector::from_vec(targets), 1e-12).ok()?;
    Some(
        columns
            .iter()
            .map(|run_columns| {
                [0, 1].map(|side| {
                    let n = run_columns[0].len();
                    (0..n)
                        .map(|k| {
                            (0..per_side)
                                .map(|col| beta[side * per_side + col] * run_columns[side * per_side + col][k])
                                .sum()
                        })
                        .collect()
                })
            })
            .collect(),
    )
}

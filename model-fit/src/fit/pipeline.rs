//! The whole fit of a dataset, block by block, in the paper's order (sections III and V): the
//! disturbance model (eGK, pressure path, fusion) on roll runs, the plant on actuation runs,
//! then the coupling operator on roll+actuation runs with the fitted models' outputs; finally
//! the held-out part of every run is replayed through the fitted core.

use std::time::Instant;

use estimator_core::coeffs::{CoefficientSet, N_ALPHA, PlantParams, RateFilter};
use estimator_core::coupling::CouplingInput;
use estimator_core::egk::params_at;
use estimator_core::prior::PRIOR;
use estimator_core::sparse::SparseModel;
use firmware_sim::dataset::{Dataset, Run, RunKind};
use rayon::prelude::*;
use serde::Serialize;

use super::FitError;
use super::actuator::{ActuatorFit, fit_actuators};
use super::coupling::{CouplingConfig, CouplingRun, coupling_library, fit_coupling};
use super::egk::{EgkData, EgkFit, fit_at, linear_map_rms, simulate};
use super::envelope::{EnvelopeFit, fit_envelope};
use super::fusion::{FusionData, FusionFit, fit_fusion};
use super::heldout::{HeldoutReport, evaluate_heldout};
use super::plant::{PlantConfig, PlantRun, fit_plant, mirrored};
use super::pressure::{PressureFitConfig, PressureFitReport, PressureRun, fit_pressure_model, run_pressure_filter};
use super::prior::{EgkPrior, Geometry};
use super::signals::RunSignals;
use super::sparse_fit::SparseFit;
use super::split::Split;
use crate::replay::replay_run;

/// Corners of the roll-rate differentiator tried, Hz: a higher corner lags less, a lower one
/// passes less encoder quantisation noise; the data decide.
pub const RATE_CORNERS_HZ: [f64; 6] = [20.0, 30.0, 45.0, 65.0, 90.0, 130.0];
/// Corners of the roll-acceleration differentiator tried, Hz.
pub const ACCEL_CORNERS_HZ: [f64; 6] = [15.0, 20.0, 30.0, 45.0, 65.0, 90.0];

/// Settings of the whole fit.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FitConfig {
    /// The training/held-out split.
    pub split: Split,
    /// The plant fit.
    pub plant: PlantConfig,
    /// The coupling fit.
    pub coupling: CouplingConfig,
    /// The pressure-model fit.
    pub pressure: PressureFitConfig,
}

/// Everything a fit produced: the tables and the report.
#[derive(Debug, Clone)]
pub struct FitOutcome {
    /// The coefficient set.
    pub set: CoefficientSet,
    /// The report behind the model card and `model.json`.
    pub report: FitReport,
}

/// The numbers of a fit.
#[derive(Debug, Clone, Serialize)]
pub struct FitReport {
    /// The split.
    pub split: String,
    /// Fixed step, s.
    pub dt_s: f64,
    /// eGK fits per angle of attack.
    pub egk: Vec<EgkReport>,
    /// The pressure path.
    pub pressure: PressureFitReport,
    /// The fusion.
    pub fusion: FusionFit,
    /// The plant of the port and starboard jets; `None` when mirrored from the other.
    pub plant: [Option<SparseFit>; 2],
    /// The coupling operator; `None` without roll+actuation runs (the operator is zero).
    pub coupling: Option<SparseFit>,
    /// Indicator thresholds of the coupling operator (Cmu, roll angle in rad).
    pub coupling_gates: [f64; 2],
    /// The jets' actuator responses (demand to Cmu).
    pub actuator: [ActuatorFit; 2],
    /// The estimate envelope.
    pub envelope: EnvelopeFit,
    /// Held-out errors of the fitted core, per block and angle of attack.
    pub heldout: HeldoutReport,
    /// Notes (blocks left at their prior, mirrored jets).
    pub notes: Vec<String>,
    /// Seconds spent per stage.
    pub timing_s: Vec<(String, f64)>,
}

/// The eGK at one angle of attack, for the report.
#[derive(Debug, Clone, Serialize)]
pub struct EgkReport {
    /// Angle of attack, deg.
    pub alpha_deg: f64,
    /// Training RMS of the prior (after its linear output map).
    pub rms_prior: f64,
    /// Training RMS of the fit.
    pub rms_fit: f64,
    /// Training samples.
    pub n_samples: usize,
    /// Optimiser termination.
    pub termination: String,
    /// Parameters: tau1, tau2, a*, k, kb, C_l,beta, C_l,p, C_l,pdot, K_v, C_l,0.
    pub params: [f64; 11],
}

impl From<&EgkFit> for EgkReport {
    fn from(fit: &EgkFit) -> Self {
        let p = &fit.params;
        Self {
            alpha_deg: fit.alpha_deg,
            rms_prior: fit.rms_prior,
            rms_fit: fit.rms_fit,
            n_samples: fit.n_samples,
            termination: fit.termination.clone(),
            params: [
                p.tau1_s,
                p.tau2_s,
                p.breakdown_deg,
                p.steepness_per_deg,
                p.sideslip_gain,
                p.clbeta_per_rad,
                p.clp,
                p.clpdot,
                p.clpp,
                p.vortex_gain,
                p.bias,
            ]
            .map(f64::from),
        }
    }
}

/// Progress of a fit: called with the name of each stage as it starts.
pub type Progress<'a> = &'a (dyn Fn(&str) + Sync);

/// Fits every block of `dataset` on its training part and evaluates the result on the held-out
/// part.
pub fn fit_dataset(dataset: &Dataset, config: &FitConfig, progress: Progress<'_>) -> Result<FitOutcome, FitError> {
    let mut timing = Vec::new();
    let mut notes = Vec::new();
    let sample_hz = common_rate(dataset)?;
    let dt_s = 1.0 / sample_hz;
    let roll =
        indices_of(dataset, RunKind::Roll, "the disturbance model (eGK and pressure map) is fitted on roll runs")?;
    let clock = Instant::now();
    progress("roll-rate differentiator");
    let rate_filter = choose_rate_filter(dataset, &roll, &config.split, dt_s);
    let mut set = CoefficientSet { dt_s: dt_s as f32, rate_filter, ..PRIOR };
    timing.push(("rate filter".to_owned(), clock.elapsed().as_secs_f64()));

    let clock = Instant::now();
    progress("actuator response and envelope");
    let actuator = fit_actuators(dataset, &config.split, &mut notes);
    set.actuator = [0, 1].map(|side| actuator[side].response());
    let envelope = fit_envelope(dataset, &config.split, &PRIOR.envelope, &mut notes);
    set.envelope = envelope.envelope();
    timing.push(("actuator and envelope".to_owned(), clock.elapsed().as_secs_f64()));
    let signals: Vec<RunSignals> =
        dataset.runs.par_iter().map(|run| RunSignals::new(run, &set.rate_filter, dt_s)).collect();

    let clock = Instant::now();
    progress("eGK (Levenberg-Marquardt per angle of attack)");
    let egk = fit_egk(dataset, &signals, &roll, config, &mut set)?;
    timing.push(("egk".to_owned(), clock.elapsed().as_secs_f64()));

    let clock = Instant::now();
    progress("pressure model (time-shifted DMDc, DARE, map to C_l)");
    let pressure = fit_pressure(dataset, &signals, config, &set)?;
    set.pressure = pressure.model;
    timing.push(("pressure".to_owned(), clock.elapsed().as_secs_f64()));

    let clock = Instant::now();
    progress("fusion");
    let fusion = fit_fusion_on(dataset, &signals, &roll, &set, &pressure.table, config)?;
    set.fusion = fusion.params();
    timing.push(("fusion".to_owned(), clock.elapsed().as_secs_f64()));

    let clock = Instant::now();
    progress("plant (SINDy, eq. 5)");
    let plant = fit_plants(dataset, &signals, config, sample_hz, &mut set, &mut notes)?;
    timing.push(("plant".to_owned(), clock.elapsed().as_secs_f64()));

    let clock = Instant::now();
    progress("coupling operator (SINDy, eqs. 9-11)");
    let (coupling, coupling_gates) = fit_coupling_on(dataset, &signals, config, &mut set, &mut notes)?;
    timing.push(("coupling".to_owned(), clock.elapsed().as_secs_f64()));

    estimator_core::blob::validate(&set).map_err(FitError::Invalid)?;
    let clock = Instant::now();
    progress("held-out replay through the fitted core");
    let heldout = evaluate_heldout(dataset, &set, &config.split);
    timing.push(("heldout".to_owned(), clock.elapsed().as_secs_f64()));
    let report = FitReport {
        split: config.split.describe(),
        dt_s,
        egk: egk.iter().map(EgkReport::from).collect(),
        pressure: pressure.report,
        fusion,
        plant,
        coupling,
        coupling_gates,
        actuator,
        envelope,
        heldout,
        notes,
        timing_s: timing,
    };
    Ok(FitOutcome { set, report })
}

/// The core's differentiators at step `dt_s` with the given corners: poles `exp(-2 pi f dt)`.
#[must_use]
pub fn rate_filter(dt_s: f64, rate_corner_hz: f64, accel_corner_hz: f64) -> RateFilter {
    let pole = |corner_hz: f64| (-std::f64::consts::TAU * corner_hz * dt_s).exp() as f32;
    RateFilter { rate_pole: pole(rate_corner_hz), accel_pole: pole(accel_corner_hz) }
}

/// The differentiator corners that let the eGK (prior dynamics, least-squares output map) fit
/// the training part of the roll runs best, pooled over the angles of attack by the sum of the
/// logarithms of each run's mean square error: every run counts by its relative improvement,
/// so that the runs with the largest errors (high alpha, buffeting) do not choose the filter
/// for all the others alone.
fn choose_rate_filter(dataset: &Dataset, roll: &[usize], split: &Split, dt_s: f64) -> RateFilter {
    let geometry = Geometry::new(&dataset.wing, &dataset.tunnel);
    let candidates: Vec<RateFilter> = RATE_CORNERS_HZ
        .iter()
        .flat_map(|&rate| ACCEL_CORNERS_HZ.iter().map(move |&accel| (rate, accel)))
        .map(|(rate, accel)| rate_filter(dt_s, rate, accel))
        .collect();
    let scores: Vec<f64> = candidates
        .par_iter()
        .map(|filter| {
            let mut sum_log_mse = 0.0;
            for &idx in roll {
                let run = &dataset.runs[idx];
                let signals = RunSignals::new(run, filter, dt_s);
                let data = [EgkData { signals: &signals, range: split.training(signals.len()) }];
                let prior = EgkPrior::new(&geometry, run.meta.alpha_deg);
                sum_log_mse += linear_map_rms(run.meta.alpha_deg, dt_s, &prior, &data).powi(2).ln();
            }
            sum_log_mse
        })
        .collect();
    let best =
        (0..candidates.len()).filter(|&idx| scores[idx].is_finite()).min_by(|&a, &b| scores[a].total_cmp(&scores[b]));
    best.map_or_else(|| rate_filter(dt_s, RATE_CORNERS_HZ[1], ACCEL_CORNERS_HZ[1]), |idx| candidates[idx])
}

fn common_rate(dataset: &Dataset) -> Result<f64, FitError> {
    let first = dataset
        .runs
        .first()
        .map(|run| run.meta.sample_hz)
        .ok_or(FitError::MissingRuns { kind: RunKind::Roll, needed_for: "the dataset has no runs at all" })?;
    match dataset.runs.iter().find(|run| (run.meta.sample_hz - first).abs() > 1e-9 * first) {
        Some(run) => Err(FitError::MixedRates {
            first_hz: first,
            other_hz: run.meta.sample_hz,
            file: run.meta.file.display().to_string(),
        }),
        None => Ok(first),
    }
}

fn indices_of(dataset: &Dataset, kind: RunKind, needed_for: &'static str) -> Result<Vec<usize>, FitError> {
    let indices: Vec<usize> = (0..dataset.runs.len()).filter(|&idx| dataset.runs[idx].meta.kind == kind).collect();
    if indices.is_empty() { Err(FitError::MissingRuns { kind, needed_for }) } else { Ok(indices) }
}

/// eGK per distinct alpha of the roll runs, in parallel; fills the schedule of `set`.
fn fit_egk(
    dataset: &Dataset,
    signals: &[RunSignals],
    roll: &[usize],
    config: &FitConfig,
    set: &mut CoefficientSet,
) -> Result<Vec<EgkFit>, FitError> {
    let mut alphas: Vec<f64> = roll.iter().map(|&idx| dataset.runs[idx].meta.alpha_deg).collect();
    alphas.sort_by(f64::total_cmp);
    alphas.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    if alphas.len() > N_ALPHA {
        let list = alphas.iter().map(|a| format!("{a}")).collect::<Vec<_>>().join(", ");
        return Err(FitError::TooManyAlphas { found: alphas.len(), alphas: list, max: N_ALPHA });
    }
    let geometry = Geometry::new(&dataset.wing, &dataset.tunnel);
    let dt_s = f64::from(set.dt_s);
    let fits: Vec<EgkFit> = alphas
        .par_iter()
        .map(|&alpha_deg| {
            let data: Vec<EgkData<'_>> = roll
                .iter()
                .filter(|&&idx| (dataset.runs[idx].meta.alpha_deg - alpha_deg).abs() < 1e-6)
                .map(|&idx| EgkData { signals: &signals[idx], range: config.split.training(signals[idx].len()) })
                .collect();
            fit_at(alpha_deg, dt_s, &EgkPrior::new(&geometry, alpha_deg), &data)
        })
        .collect();
    set.n_alpha = fits.len() as u8;
    for (slot, fit) in fits.iter().enumerate() {
        set.alpha_schedule_deg[slot] = fit.alpha_deg as f32;
        set.egk[slot] = fit.params;
    }
    for slot in fits.len()..N_ALPHA {
        set.alpha_schedule_deg[slot] = set.alpha_schedule_deg[fits.len() - 1] + (slot - fits.len() + 1) as f32;
        set.egk[slot] = set.egk[fits.len() - 1];
    }
    Ok(fits)
}

/// Every run's pressure-fit samples. The disturbance moment that fits the map to `C_l` is the
/// balance in roll runs and the fitted eGK's moment in actuation runs (`held`, by run index):
/// the jets change the pressures as well, and without the actuation runs the map read that
/// change as roll moment (on a tunnel whose taps see the blowing, the fused estimate of a blown
/// run was off by about ten times the balance noise).
fn pressure_runs<'a>(
    dataset: &'a Dataset,
    signals: &'a [RunSignals],
    held: &'a [Option<Vec<f64>>],
    split: &Split,
) -> Result<Vec<PressureRun<'a>>, FitError> {
    dataset
        .runs
        .iter()
        .zip(signals)
        .zip(held)
        .map(|((run, signals), held)| {
            let disturbance = match run.meta.kind {
                RunKind::Roll => Some(run.channels.cl.as_slice()),
                _ => held.as_deref(),
            };
            Ok(PressureRun::from_signals(signals, &run.channels, split.training(signals.len()), disturbance)?)
        })
        .collect()
}

/// The pressure path, its map to `C_l` tabulated at the alpha schedule of `set` (the eGK's).
fn fit_pressure(
    dataset: &Dataset,
    signals: &[RunSignals],
    config: &FitConfig,
    set: &CoefficientSet,
) -> Result<super::pressure::PressureFit, FitError> {
    let held: Vec<Option<Vec<f64>>> = dataset
        .runs
        .iter()
        .zip(signals)
        .map(|(run, signals)| (run.meta.kind == RunKind::Actuation).then(|| egk_moment(set, run, signals)))
        .collect();
    let runs = pressure_runs(dataset, signals, &held, &config.split)?;
    let n_alpha = usize::from(set.n_alpha).clamp(1, N_ALPHA);
    let breakpoints: Vec<f64> = set.alpha_schedule_deg[..n_alpha].iter().map(|&deg| f64::from(deg)).collect();
    Ok(fit_pressure_model(&runs, &config.pressure, &breakpoints)?)
}

/// The fitted eGK's moment over a whole run (f64), at the run's angle of attack.
fn egk_moment(set: &CoefficientSet, run: &Run, signals: &RunSignals) -> Vec<f64> {
    let alpha_deg = run.meta.alpha_deg;
    simulate(&params_at(set, alpha_deg as f32), alpha_deg, f64::from(set.dt_s), signals)
}

/// Fusion on the training part of the roll runs, from the f64 eGK and pressure path.
fn fit_fusion_on(
    dataset: &Dataset,
    signals: &[RunSignals],
    roll: &[usize],
    set: &CoefficientSet,
    pressure: &super::pressure::PressureTable,
    config: &FitConfig,
) -> Result<FusionFit, FitError> {
    let mut outputs = Vec::new();
    for &idx in roll {
        let run = &dataset.runs[idx];
        let egk = egk_moment(set, run, &signals[idx]);
        let full =
            PressureRun::from_signals(&signals[idx], &run.channels, 0..signals[idx].len(), Some(&run.channels.cl))?;
        let pressure = run_pressure_filter(pressure, &full)?;
        outputs.push((idx, egk, pressure));
    }
    let data: Vec<FusionData<'_>> = outputs
        .iter()
        .map(|(idx, egk, pressure)| FusionData {
            cl_egk: egk,
            cl_pressure: pressure,
            cl: &signals[*idx].cl,
            range: config.split.training(signals[*idx].len()),
        })
        .collect();
    Ok(fit_fusion(f64::from(set.dt_s), &data))
}

/// Whether a jet blows in a run (its Cmu leaves zero).
fn blows(signals: &RunSignals, side: usize) -> bool {
    signals.cmu[side].iter().any(|&cmu| cmu > 0.0)
}

/// Passes over the two jets when both blow in one run (backfitting: each jet's model is fitted
/// to the balance less the other's modelled moment; Hastie & Tibshirani, Generalized Additive
/// Models, 1990, section 4.3). The jets' sequences are independent, so two passes settle.
const BACKFIT_PASSES: usize = 2;

/// The moment a plant model gives for one jet of a run, stepped as the core steps it.
fn plant_moment(params: &PlantParams, signals: &RunSignals, side: usize) -> Vec<f64> {
    let mut plant = estimator_core::plant::Plant::new();
    (0..signals.len())
        .map(|k| {
            let alpha_rad = signals.alpha_deg[k].to_radians() as f32;
            f64::from(plant.step(params, signals.cmu[side][k] as f32, alpha_rad).0)
        })
        .collect()
}

/// Plants of both jets; a jet that never blows in the actuation runs is mirrored from the other.
/// When both jets blow in the same runs, each is fitted to the balance less the other's
/// modelled moment, alternately ([`BACKFIT_PASSES`]).
fn fit_plants(
    dataset: &Dataset,
    signals: &[RunSignals],
    config: &FitConfig,
    sample_hz: f64,
    set: &mut CoefficientSet,
    notes: &mut Vec<String>,
) -> Result<[Option<SparseFit>; 2], FitError> {
    let actuation = indices_of(dataset, RunKind::Actuation, "the plant model (eq. 5) is fitted on actuation runs")?;
    let mut reports: [Option<SparseFit>; 2] = [None, None];
    let mut models: [Option<PlantParams>; 2] = [None, None];
    let blowing: [Vec<usize>; 2] =
        [0, 1].map(|side| actuation.iter().copied().filter(|&idx| blows(&signals[idx], side)).collect());
    let together = blowing[0].iter().any(|idx| blowing[1].contains(idx));
    // Per side, per run index: that jet's modelled moment (absent until its model exists),
    // started from a joint linear split of the runs where both blow.
    let mut modelled: [std::collections::BTreeMap<usize, Vec<f64>>; 2] = Default::default();
    if together {
        let shared: Vec<usize> = blowing[0].iter().copied().filter(|idx| blowing[1].contains(idx)).collect();
        let runs: Vec<(&RunSignals, std::ops::Range<usize>)> =
            shared.iter().map(|&idx| (&signals[idx], config.split.training(signals[idx].len()))).collect();
        if let Some(split) = super::plant::initial_split(&runs, sample_hz) {
            for (&idx, [port, starboard]) in shared.iter().zip(split) {
                modelled[0].insert(idx, port);
                modelled[1].insert(idx, starboard);
            }
        }
    }
    for _ in 0..if together { BACKFIT_PASSES } else { 1 } {
        for side in 0..2 {
            if blowing[side].is_empty() {
                continue;
            }
            let runs: Vec<PlantRun<'_>> = blowing[side]
                .iter()
                .map(|&idx| {
                    let other = modelled[1 - side].get(&idx);
                    let target = signals[idx]
                        .cl
                        .iter()
                        .enumerate()
                        .map(|(k, cl)| cl - other.map_or(0.0, |moment| moment[k]))
                        .collect();
                    PlantRun {
                        signals: &signals[idx],
                        train: config.split.fitting(signals[idx].len()),
                        validation: config.split.validation(signals[idx].len()),
                        target,
                    }
                })
                .collect();
            let (model, report) = fit_plant(&runs, side, sample_hz, &config.plant)?;
            if together {
                modelled[side] =
                    blowing[side].iter().map(|&idx| (idx, plant_moment(&model, &signals[idx], side))).collect();
            }
            models[side] = Some(model);
            reports[side] = Some(report);
        }
    }
    match models {
        [Some(port), Some(starboard)] => set.plant = [port, starboard],
        [Some(port), None] => {
            set.plant = [port, mirrored(&port)];
            notes.push(
                "the starboard jet never blows in the actuation runs: its plant is the port plant mirrored".into(),
            );
        }
        [None, Some(starboard)] => {
            set.plant = [mirrored(&starboard), starboard];
            notes.push(
                "the port jet never blows in the actuation runs: its plant is the starboard plant mirrored".into(),
            );
        }
        [None, None] => {
            return Err(FitError::MissingRuns {
                kind: RunKind::Actuation,
                needed_for: "no jet blows in any actuation run",
            });
        }
    }
    Ok(reports)
}

/// Refits only the coupling operator of `set` on `dataset` (its disturbance and plant models
/// stay): the paper's noise-robustness test refits the operator on noisy data.
pub fn refit_coupling(dataset: &Dataset, set: &CoefficientSet, config: &FitConfig) -> Result<CoefficientSet, FitError> {
    let dt_s = f64::from(set.dt_s);
    let signals: Vec<RunSignals> =
        dataset.runs.par_iter().map(|run| RunSignals::new(run, &set.rate_filter, dt_s)).collect();
    let mut refitted = *set;
    let _ = fit_coupling_on(dataset, &signals, config, &mut refitted, &mut Vec::new())?;
    Ok(refitted)
}

/// The coupling operator on the roll+actuation runs, from the core's replay with a zero
/// operator. Without such runs the operator stays zero (the linear superposition).
fn fit_coupling_on(
    dataset: &Dataset,
    signals: &[RunSignals],
    config: &FitConfig,
    set: &mut CoefficientSet,
    notes: &mut Vec<String>,
) -> Result<(Option<SparseFit>, [f64; 2]), FitError> {
    set.coupling = SparseModel::ZERO;
    let both: Vec<usize> =
        (0..dataset.runs.len()).filter(|&idx| dataset.runs[idx].meta.kind == RunKind::RollActuation).collect();
    let gates = gate_thresholds(dataset, signals, &config.split);
    if both.is_empty() {
        notes.push("no roll+actuation runs: the coupling operator is zero (linear superposition)".into());
        return Ok((None, gates));
    }
    let runs: Vec<CouplingRun> =
        both.par_iter().map(|&idx| coupling_run(&dataset.runs[idx], &signals[idx], set, &config.split)).collect();
    let library = coupling_library(config.coupling.degree, gates[0] as f32, gates[1] as f32)?;
    let (model, report) = fit_coupling(&library, &runs, &config.coupling)?;
    set.coupling = model;
    Ok((Some(report), gates))
}

/// The operator's variables and target at every sample of a run, from the core's replay.
fn coupling_run(run: &Run, signals: &RunSignals, set: &CoefficientSet, split: &Split) -> CouplingRun {
    let outputs = replay_run(set, run);
    let mut last_cmu = 0.0;
    let variables = outputs
        .iter()
        .enumerate()
        .map(|(k, output)| {
            let cmu = signals.cmu[0][k] + signals.cmu[1][k];
            let input = CouplingInput {
                cl_roll: f64::from(output.cl_roll),
                cl_afc: f64::from(output.cl_afc),
                alpha_rad: signals.alpha_deg[k].to_radians(),
                cmu,
                dcmu: cmu - last_cmu,
                phi_rad: signals.phi_rad[k],
                phi_dot_rad_s: f64::from(output.phi_dot_rad_s),
            };
            last_cmu = cmu;
            input.variables()
        })
        .collect();
    let target = outputs.iter().zip(&signals.cl).map(|(output, cl)| cl - f64::from(output.cl_linear)).collect();
    CouplingRun { variables, target, train: split.fitting(signals.len()), validation: split.validation(signals.len()) }
}

/// Indicator thresholds from the data: twice the largest Cmu seen in the roll runs (where no
/// jet blows) and twice the largest |roll angle| in the actuation runs (where the wing is held
/// level), with floors of 1 % of the largest Cmu and 0.25 deg; over the training samples only.
fn gate_thresholds(dataset: &Dataset, signals: &[RunSignals], split: &Split) -> [f64; 2] {
    let largest = |kind: RunKind, value: &dyn Fn(&RunSignals) -> f64| -> f64 {
        dataset
            .runs
            .iter()
            .zip(signals)
            .filter(|(run, _)| run.meta.kind == kind)
            .map(|(_, s)| value(s))
            .fold(0.0, f64::max)
    };
    let max_cmu = |s: &RunSignals| {
        let training = split.training(s.len());
        s.cmu[0][training.clone()].iter().chain(&s.cmu[1][training]).fold(0.0f64, |m, &v| m.max(v))
    };
    let max_phi = |s: &RunSignals| s.phi_rad[split.training(s.len())].iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let cmu_max_anywhere = dataset.runs.iter().zip(signals).map(|(_, s)| max_cmu(s)).fold(0.0, f64::max);
    let cmu = (2.0 * largest(RunKind::Roll, &max_cmu)).max(0.01 * cmu_max_anywhere);
    let phi = (2.0 * largest(RunKind::Actuation, &max_phi)).max(0.25f64.to_radians());
    [cmu, phi]
}

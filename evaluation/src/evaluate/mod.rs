//! Evaluation on held-out data: the paper's tables (1: validity of superposition, 2: error
//! with and without the coupling operator, 3: correlation), its noise-robustness test and a
//! sweep over noise levels, every block's errors per angle of attack, and plots like the
//! paper's Figs. 7 to 13.
//!
//! Everything is computed on the held-out part of every run (the part a fit never sees),
//! replaying the recorded channels through the estimator that flies (estimator-core, f32).

pub mod bootstrap;
mod figures;
mod metrics;
mod pressure_information;
mod report;

use estimator_core::{CoefficientSet, Output};
use firmware_sim::dataset::{Dataset, RunKind};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use serde::Serialize;

use crate::analysis::superposition::{SuperpositionRow, superposition_over};
pub use figures::figures;
use metrics::{correlation, norm_and_count, rms};
use model_fit::fit::FitError;
use model_fit::fit::heldout::noise_rms;
use model_fit::fit::pipeline::{FitConfig, refit_coupling};
use model_fit::fit::split::Split;
use model_fit::replay::replay_run;
pub use pressure_information::{PressureInformationRow, pressure_information};
pub use report::evaluation_report;

/// Settings of an evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct EvaluationConfig {
    /// The split (the held-out part is evaluated).
    pub split: Split,
    /// Standard deviations of the Gaussian noise added to the balance for the robustness
    /// sweep (the paper's test is 0.001).
    pub noise_levels: Vec<f64>,
    /// Seed of that noise.
    pub seed: u64,
    /// Standard deviation of the balance noise of the figure that shows the operator refitted
    /// on noisy data (the paper's robustness figure uses 0.001).
    pub figure_noise: f64,
}

impl Default for EvaluationConfig {
    fn default() -> Self {
        Self {
            split: Split::default(),
            noise_levels: vec![0.00025, 0.0005, 0.001, 0.002, 0.004],
            seed: 1,
            figure_noise: 0.001,
        }
    }
}

/// Table 2 and Table 3 at one angle of attack (paper eqs. 13 and 14).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CouplingRow {
    /// Angle of attack, deg.
    pub alpha_deg: f64,
    /// `E_lin = ||C_l,RollAFC - C_l,Roll^model - C_l,AFC^model||_2` over the held-out samples.
    pub e_lin: f64,
    /// `E_SINDy`: the same with the coupling operator's correction.
    pub e_sindy: f64,
    /// `E_SINDy / E_lin`.
    pub ratio: f64,
    /// Correlation of the measured moment with the linear superposition.
    pub corr_linear: f64,
    /// Correlation with the operator's prediction.
    pub corr_operator: f64,
    /// 95 % moving-block bootstrap interval of `ratio` ([`bootstrap`]).
    pub ratio_ci95: Option<bootstrap::Interval>,
    /// 95 % moving-block bootstrap interval of `corr_operator - corr_linear`.
    pub corr_change_ci95: Option<bootstrap::Interval>,
    /// Block length of the bootstrap, samples (from the operator's error's autocorrelation).
    pub bootstrap_block: usize,
    /// Held-out samples.
    pub n_samples: usize,
}

/// One block's held-out error at one angle of attack.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BlockRow {
    /// Angle of attack, deg.
    pub alpha_deg: f64,
    /// Block: `egk`, `pressure`, `fused`, `plant`, `linear`, `coupled`.
    pub block: String,
    /// Kind of the runs it is scored on.
    pub runs: String,
    /// RMS error against the balance.
    pub rms: f64,
    /// Correlation with the balance.
    pub correlation: f64,
    /// RMS error over the balance's white-noise RMS.
    pub rms_over_noise: f64,
}

/// The noise-robustness test at one noise level: the coupling operator refitted on data with
/// added noise, scored on the noisy held-out data.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NoiseRow {
    /// Standard deviation of the added noise, in C_l.
    pub sigma: f64,
    /// Table 2 and 3 per angle of attack on the noisy data.
    pub per_alpha: Vec<CouplingRow>,
}

/// Everything an evaluation measured.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Evaluation {
    /// The split.
    pub split: String,
    /// Table 1 on the held-out samples.
    pub table1: Vec<SuperpositionRow>,
    /// Tables 2 and 3.
    pub coupling: Vec<CouplingRow>,
    /// Every block per angle of attack.
    pub blocks: Vec<BlockRow>,
    /// The fused estimate against the eGK and the pressure path alone.
    pub fusion: Vec<FusionRow>,
    /// The balance's white-noise RMS per angle of attack.
    pub noise_rms: Vec<(f64, f64)>,
    /// The noise-robustness sweep.
    pub noise_robustness: Vec<NoiseRow>,
    /// What the pressures can tell about the eGK's error (the room a fusion has), per alpha.
    pub pressure_information: Vec<PressureInformationRow>,
    /// What could not be evaluated and why.
    pub notes: Vec<String>,
}

/// The fusion against its two sources at one angle of attack (roll runs, held out): held-out
/// RMS of the fused estimate divided by each source's, with 95 % moving-block bootstrap
/// intervals of the ratios over the same resampled samples, so that a small gain can be told
/// from a tie.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FusionRow {
    /// Angle of attack, deg.
    pub alpha_deg: f64,
    /// RMS of the fused estimate over the eGK's.
    pub over_egk: f64,
    /// Its 95 % interval.
    pub over_egk_ci95: Option<bootstrap::Interval>,
    /// RMS of the fused estimate over the pressure path's.
    pub over_pressure: f64,
    /// Its 95 % interval.
    pub over_pressure_ci95: Option<bootstrap::Interval>,
    /// Held-out samples.
    pub n_samples: usize,
}

/// The replayed estimates of every run.
pub struct Replayed {
    /// Per run, per sample.
    pub outputs: Vec<Vec<Output>>,
}

impl Replayed {
    /// Replays every run of `dataset` through the core with `set`.
    #[must_use]
    pub fn new(dataset: &Dataset, set: &CoefficientSet) -> Self {
        Self { outputs: dataset.runs.par_iter().map(|run| replay_run(set, run)).collect() }
    }
}

/// Evaluates `set` on the held-out part of `dataset`.
pub fn evaluate(
    dataset: &Dataset,
    set: &CoefficientSet,
    config: &EvaluationConfig,
) -> Result<(Evaluation, Replayed), FitError> {
    let replayed = Replayed::new(dataset, set);
    let split = &config.split;
    let mut notes = Vec::new();
    let alphas = dataset.alphas_deg();
    let table1: Vec<SuperpositionRow> =
        alphas.iter().filter_map(|&alpha| superposition_over(dataset, alpha, &|n| split.heldout(n)).ok()).collect();
    if table1.is_empty() {
        notes.push("Table 1 needs roll, actuation and roll+actuation runs at one angle of attack".into());
    }
    let coupling: Vec<CouplingRow> =
        alphas.iter().filter_map(|&alpha| coupling_row(dataset, &replayed, split, alpha, Some(config.seed))).collect();
    let noise: Vec<(f64, f64)> = alphas
        .iter()
        .filter_map(|&alpha| noise_rms(dataset, &runs_at(dataset, None, alpha), split).map(|rms| (alpha, rms)))
        .collect();
    let blocks = block_rows(dataset, &replayed, split, &noise);
    let fusion = alphas.iter().filter_map(|&alpha| fusion_row(dataset, &replayed, split, alpha, config.seed)).collect();
    let pressure_information = pressure_information(dataset, &replayed, split, &alphas);
    let noise_robustness = if coupling.is_empty() {
        notes.push("no roll+actuation runs: no coupling tables and no noise-robustness test".into());
        Vec::new()
    } else {
        noise_sweep(dataset, set, config)?
    };
    let evaluation = Evaluation {
        split: split.describe(),
        table1,
        coupling,
        blocks,
        fusion,
        noise_rms: noise,
        noise_robustness,
        pressure_information,
        notes,
    };
    Ok((evaluation, replayed))
}

/// Indices of the runs of `kind` (any kind when `None`) at `alpha_deg`.
fn runs_at(dataset: &Dataset, kind: Option<RunKind>, alpha_deg: f64) -> Vec<usize> {
    (0..dataset.runs.len())
        .filter(|&idx| {
            let meta = &dataset.runs[idx].meta;
            kind.is_none_or(|kind| meta.kind == kind) && (meta.alpha_deg - alpha_deg).abs() < 1e-6
        })
        .collect()
}

/// Pairs (estimate, measured) over the held-out samples of `runs`.
fn pairs(
    dataset: &Dataset,
    replayed: &Replayed,
    split: &Split,
    runs: &[usize],
    pick: fn(&Output) -> f32,
) -> (Vec<f64>, Vec<f64>) {
    let (mut estimates, mut measured) = (Vec::new(), Vec::new());
    for &idx in runs {
        let cl = &dataset.runs[idx].channels.cl;
        for k in split.heldout(cl.len()) {
            let estimate = f64::from(pick(&replayed.outputs[idx][k]));
            if cl[k].is_finite() && estimate.is_finite() {
                estimates.push(estimate);
                measured.push(cl[k]);
            }
        }
    }
    (estimates, measured)
}

/// Tables 2 and 3 at `alpha_deg`, with bootstrap intervals drawn from `seed` when given (the
/// noise sweep's rows go without: its table shows none, and they would cost more than the rest
/// of the sweep).
fn coupling_row(
    dataset: &Dataset,
    replayed: &Replayed,
    split: &Split,
    alpha_deg: f64,
    seed: Option<u64>,
) -> Option<CouplingRow> {
    let runs = runs_at(dataset, Some(RunKind::RollActuation), alpha_deg);
    if runs.is_empty() {
        return None;
    }
    let (linear, measured) = pairs(dataset, replayed, split, &runs, |o| o.cl_linear);
    let (operator, _) = pairs(dataset, replayed, split, &runs, |o| o.cl);
    let (e_lin, n_samples) = norm_and_count(&linear, &measured);
    let (e_sindy, _) = norm_and_count(&operator, &measured);
    let errors: Vec<f64> = operator.iter().zip(&measured).map(|(o, m)| o - m).collect();
    let block = bootstrap::block_length(&errors);
    let ratio_ci95 = seed.and_then(|seed| {
        bootstrap::interval(measured.len(), block, seed, |idx| {
            let measured = bootstrap::gather(&measured, idx);
            norm_and_count(&bootstrap::gather(&operator, idx), &measured).0
                / norm_and_count(&bootstrap::gather(&linear, idx), &measured).0
        })
    });
    let corr_change_ci95 = seed.and_then(|seed| {
        bootstrap::interval(measured.len(), block, seed, |idx| {
            let measured = bootstrap::gather(&measured, idx);
            correlation(&bootstrap::gather(&operator, idx), &measured)
                - correlation(&bootstrap::gather(&linear, idx), &measured)
        })
    });
    Some(CouplingRow {
        alpha_deg,
        e_lin,
        e_sindy,
        ratio: e_sindy / e_lin,
        corr_linear: correlation(&linear, &measured),
        corr_operator: correlation(&operator, &measured),
        ratio_ci95,
        corr_change_ci95,
        bootstrap_block: block,
        n_samples,
    })
}

fn fusion_row(dataset: &Dataset, replayed: &Replayed, split: &Split, alpha_deg: f64, seed: u64) -> Option<FusionRow> {
    let runs = runs_at(dataset, Some(RunKind::Roll), alpha_deg);
    // Samples where the balance and all three estimates are finite, so the ratios compare the
    // same samples.
    let (mut fused, mut egk, mut pressure, mut measured) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for &idx in &runs {
        let cl = &dataset.runs[idx].channels.cl;
        for k in split.heldout(cl.len()) {
            let output = &replayed.outputs[idx][k];
            let values = [f64::from(output.cl_roll), f64::from(output.cl_egk), f64::from(output.cl_pressure), cl[k]];
            if values.iter().all(|value| value.is_finite()) {
                fused.push(values[0]);
                egk.push(values[1]);
                pressure.push(values[2]);
                measured.push(values[3]);
            }
        }
    }
    if measured.is_empty() {
        return None;
    }
    let errors: Vec<f64> = fused.iter().zip(&measured).map(|(f, m)| f - m).collect();
    let block = bootstrap::block_length(&errors);
    let ratio_over = |other: &[f64]| {
        let ratio = |idx: &[usize]| {
            let measured = bootstrap::gather(&measured, idx);
            rms(&bootstrap::gather(&fused, idx), &measured) / rms(&bootstrap::gather(other, idx), &measured)
        };
        (rms(&fused, &measured) / rms(other, &measured), bootstrap::interval(measured.len(), block, seed, ratio))
    };
    let (over_egk, over_egk_ci95) = ratio_over(&egk);
    let (over_pressure, over_pressure_ci95) = ratio_over(&pressure);
    Some(FusionRow { alpha_deg, over_egk, over_egk_ci95, over_pressure, over_pressure_ci95, n_samples: measured.len() })
}

/// Picks one estimate from a step's outputs.
type Pick = fn(&Output) -> f32;

fn block_rows(dataset: &Dataset, replayed: &Replayed, split: &Split, noise: &[(f64, f64)]) -> Vec<BlockRow> {
    let blocks: [(&str, RunKind, Pick); 6] = [
        ("egk", RunKind::Roll, |o| o.cl_egk),
        ("pressure", RunKind::Roll, |o| o.cl_pressure),
        ("fused", RunKind::Roll, |o| o.cl_roll),
        ("plant", RunKind::Actuation, |o| o.cl_afc),
        ("linear", RunKind::RollActuation, |o| o.cl_linear),
        ("coupled", RunKind::RollActuation, |o| o.cl),
    ];
    let mut rows = Vec::new();
    for &(alpha_deg, noise_rms) in noise {
        for (block, kind, pick) in blocks {
            let runs = runs_at(dataset, Some(kind), alpha_deg);
            let (estimate, measured) = pairs(dataset, replayed, split, &runs, pick);
            if estimate.is_empty() {
                continue;
            }
            let error = rms(&estimate, &measured);
            rows.push(BlockRow {
                alpha_deg,
                block: block.to_owned(),
                runs: kind.to_string(),
                rms: error,
                correlation: correlation(&estimate, &measured),
                rms_over_noise: error / noise_rms,
            });
        }
    }
    rows
}

/// The paper's noise test: Gaussian noise added to the balance of every run, the coupling
/// operator refitted on the noisy training part and scored on the noisy held-out part.
fn noise_sweep(dataset: &Dataset, set: &CoefficientSet, config: &EvaluationConfig) -> Result<Vec<NoiseRow>, FitError> {
    let fit_config = FitConfig { split: config.split, ..FitConfig::default() };
    config
        .noise_levels
        .iter()
        .enumerate()
        .map(|(level_idx, &sigma)| {
            let noisy = with_balance_noise(dataset, sigma, config.seed.wrapping_add(level_idx as u64));
            let refitted = refit_coupling(&noisy, set, &fit_config)?;
            let replayed = Replayed::new(&noisy, &refitted);
            let per_alpha = noisy
                .alphas_deg()
                .iter()
                .filter_map(|&alpha| coupling_row(&noisy, &replayed, &config.split, alpha, None))
                .collect();
            Ok(NoiseRow { sigma, per_alpha })
        })
        .collect()
}

/// A copy of `dataset` with white Gaussian noise of standard deviation `sigma` added to the
/// balance roll moment (missing samples stay missing).
#[must_use]
pub fn with_balance_noise(dataset: &Dataset, sigma: f64, seed: u64) -> Dataset {
    let mut noisy = dataset.clone();
    let Ok(normal) = Normal::new(0.0, sigma.max(0.0)) else { return noisy };
    for (run_idx, run) in noisy.runs.iter_mut().enumerate() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed.wrapping_mul(1_000_003).wrapping_add(run_idx as u64));
        for value in run.channels.cl.iter_mut() {
            let draw: f64 = normal.sample(&mut rng);
            *value += draw;
        }
    }
    noisy
}

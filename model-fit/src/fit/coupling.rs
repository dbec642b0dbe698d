//! Fit of the coupling operator, the paper's eqs. 9-11: on the roll+actuation runs, the
//! difference between the measured moment and the linear superposition of the fitted
//! disturbance and plant models, `C_l - C_l,roll - C_l,AFC`, regressed on a sparse library of
//! the models' outputs and the inputs.
//!
//! Admissibility (paper section V): the operator must vanish without blowing and without roll,
//! so every term is gated by the anti-Dirac indicators of Cmu and of the roll angle; terms
//! that are polynomials of alpha alone (the constant among them), pure squares of `C_l,roll` or
//! `C_l,AFC`, and terms without a roll-moment factor are excluded. The roll angle may also be a
//! factor of a roll-moment term, which the paper's pool used in the indicator only: blowing
//! raises the blown half-wing's incidence (docs/equations.md, "The synthetic tunnel's model")
//! and the roll changes it through the sideslip `~ sin alpha sin phi`, so the jet's moment
//! carries a product of the blowing and the roll angle that the models' outputs alone do not.
//! Such a term still vanishes without roll. For the same reason the roll rate is a variable, and
//! the products of the blowing and the roll rate are admitted without a roll-moment factor: the
//! roll rate moves each half-wing's incidence by up to `+-p b / 2U`, so the jet's moment on a
//! rolling wing changes with `Cmu p`, a product that neither model's output carries (the eGK's
//! moment is a mix of the sideslip, the rate and the vortex state, in proportions that change
//! with the motion). Such a term vanishes without blowing and without roll by its own factors.
//! The rate enters as that incidence does: to the first power, and only beside a blowing
//! factor (Cmu or the jets' moment), which also keeps the pool from growing by a third with
//! terms that no mechanism asks for. The models' outputs come from replaying the core, as the
//! paper used its models' estimates.

use std::ops::Range;

use estimator_core::coeffs::{MAX_TERMS, MAX_VARS, coupling_var};
use estimator_core::sparse::SparseModel;

use super::FitError;
use super::sparse_fit::{
    SelectBy, SparseFit, effective_samples, lag_one_autocorrelation, refit_support, select_index, sparse_fit,
};
use sindy::{HeldoutScore, Library, Normalisation, QrProblem, SelectionConfig, StlsConfig, log_thresholds, sweep};

/// Variable names of the coupling library, in the core's order
/// (`estimator_core::coeffs::coupling_var`).
pub const COUPLING_VARIABLES: [&str; 7] = ["cl_roll", "cl_afc", "alpha", "cmu", "dcmu", "phi", "phi_dot"];

/// Settings of the coupling fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CouplingConfig {
    /// Largest total degree of a term.
    pub degree: u8,
    /// Number of swept thresholds.
    pub n_thresholds: usize,
    /// Smallest threshold as a fraction of the largest normalised least-squares coefficient.
    pub min_fraction: f64,
}

impl Default for CouplingConfig {
    fn default() -> Self {
        Self { degree: 3, n_thresholds: 40, min_fraction: 1e-4 }
    }
}

/// One roll+actuation run's samples: the coupling variables and the target at every sample.
#[derive(Debug, Clone)]
pub struct CouplingRun {
    /// Variables in the order of [`COUPLING_VARIABLES`].
    pub variables: Vec<[f64; MAX_VARS]>,
    /// `C_l - C_l,roll - C_l,AFC` (NaN where the balance is missing).
    pub target: Vec<f64>,
    /// Samples the candidates are fitted on (the training part less its validation part).
    pub train: Range<usize>,
    /// Samples the operator's terms are chosen on (the end of the training part); the chosen
    /// terms are then refitted on `train` and `validation` together.
    pub validation: Range<usize>,
}

impl CouplingRun {
    /// The whole training part: `train` and `validation` together.
    fn training(&self) -> Range<usize> {
        self.train.start..self.validation.end.max(self.train.end)
    }
}

/// The admissible library with indicator thresholds for Cmu and the roll angle (the rules in
/// the module's doc).
pub fn coupling_library(degree: u8, cmu_threshold: f32, phi_threshold_rad: f32) -> Result<Library, FitError> {
    let mut library = Library::polynomial(&COUPLING_VARIABLES, degree, false)?;
    let (roll, afc) = (coupling_var::CL_ROLL, coupling_var::CL_AFC);
    let (cmu, rate) = (coupling_var::CMU, coupling_var::PHI_DOT);
    library.exclude_where(|term| {
        let p = &term.powers();
        let has_moment = p[roll] > 0 || p[afc] > 0;
        let pure_square = (p[roll] == 2 || p[afc] == 2) && term.degree() == 2;
        let rate_as_incidence = match p[rate] {
            0 => true,
            1 => p[cmu] > 0 || p[afc] > 0,
            _ => false,
        };
        let admissible = (has_moment || (p[cmu] > 0 && p[rate] > 0)) && !pure_square && rate_as_incidence;
        !admissible
    });
    library.gate_all("cmu")?;
    library.gate_all("phi")?;
    library.set_gate_threshold("cmu", cmu_threshold)?;
    library.set_gate_threshold("phi", phi_threshold_rad)?;
    Ok(library)
}

/// Fits the operator on `runs` with `library`: the threshold sweep on the `train` samples, the
/// terms chosen on the `validation` samples, and those terms refitted on both.
pub fn fit_coupling(
    library: &Library,
    runs: &[CouplingRun],
    config: &CouplingConfig,
) -> Result<(SparseModel, SparseFit), FitError> {
    let (samples, targets) = rows(runs, |run| run.train.clone());
    let problem = QrProblem::new(&library.theta(&samples)?, &targets)?;
    let stls = StlsConfig { threshold: 0.0, alpha: 0.0, max_iter: 20, unbias: true, normalisation: Normalisation::Rms };
    let thresholds = log_thresholds(&problem, Normalisation::Rms, config.n_thresholds, config.min_fraction)?;
    let swept = sweep(&problem, &stls, &thresholds)?;
    let mut scored =
        swept.select(|coefficients: &[f64]| score(library, runs, coefficients), &SelectionConfig::default())?;
    // The operator without terms (the linear superposition) is always a candidate.
    scored.selected =
        select_index(&scored, SelectBy::OneStep, MAX_TERMS).ok_or(FitError::Internal("no coupling model eligible"))?;
    let support: Vec<bool> = scored.selected().point.coefficients.iter().map(|&c| c != 0.0).collect();
    let (samples, targets) = rows(runs, CouplingRun::training);
    let coefficients = refit_support(&library.theta(&samples)?, &targets, &support)?;
    let model = library.to_sparse_model(&coefficients)?;
    let report =
        sparse_fit(library, &scored, SelectBy::OneStep, MAX_TERMS, scored.selected, &coefficients, targets.len());
    Ok((model, report))
}

/// The finite samples and targets of `runs` over the range `samples_of` picks.
fn rows(runs: &[CouplingRun], samples_of: impl Fn(&CouplingRun) -> Range<usize>) -> (Vec<[f64; MAX_VARS]>, Vec<f64>) {
    let (mut samples, mut targets) = (Vec::new(), Vec::new());
    for run in runs {
        for k in samples_of(run) {
            if run.target[k].is_finite() {
                samples.push(run.variables[k]);
                targets.push(run.target[k]);
            }
        }
    }
    (samples, targets)
}

/// The one-step error of an operator on the validation samples.
fn score(library: &Library, runs: &[CouplingRun], coefficients: &[f64]) -> HeldoutScore {
    let mut errors = Vec::new();
    for run in runs {
        for k in run.validation.clone() {
            if run.target[k].is_finite() {
                let predicted = library.predict(coefficients, &run.variables[k]).unwrap_or(f64::NAN);
                errors.push(predicted - run.target[k]);
            }
        }
    }
    let rms = if errors.is_empty() {
        f64::NAN
    } else {
        (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt()
    };
    HeldoutScore {
        one_step_rms: rms,
        free_run_rms: None,
        n_samples: effective_samples(errors.len(), lag_one_autocorrelation(&errors)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every term has a roll-moment factor or is blowing times the roll rate; the rate appears
    /// to the first power and only beside a blowing factor; no pure square of a moment.
    #[test]
    fn the_roll_rate_enters_linearly_and_only_beside_the_blowing() {
        let library = coupling_library(3, 1e-4, 4e-3).expect("the library builds");
        let (roll, afc, cmu, rate) =
            (coupling_var::CL_ROLL, coupling_var::CL_AFC, coupling_var::CMU, coupling_var::PHI_DOT);
        let powers: Vec<[u8; MAX_VARS]> = library.terms().iter().map(|term| term.powers()).collect();
        for p in &powers {
            assert!(p[roll] > 0 || p[afc] > 0 || (p[cmu] > 0 && p[rate] > 0), "{p:?}");
            assert!(p[rate] <= 1, "{p:?}");
            assert!(p[rate] == 0 || p[cmu] > 0 || p[afc] > 0, "{p:?}");
        }
        let has = |want: &[(usize, u8)]| {
            powers.iter().any(|p| (0..MAX_VARS).all(|v| p[v] == want.iter().find(|w| w.0 == v).map_or(0, |w| w.1)))
        };
        assert!(has(&[(cmu, 1), (rate, 1)]), "Cmu p, the jet's moment through the roll rate");
        assert!(has(&[(roll, 1), (afc, 1)]), "the paper's C_l,roll C_l,AFC");
        assert!(!has(&[(roll, 1), (rate, 1)]), "the rate without blowing is the disturbance's, not the coupling's");
        assert!(!has(&[(cmu, 1), (rate, 2)]), "the rate to the second power");
    }
}

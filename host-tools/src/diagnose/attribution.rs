//! Attribution on the balance stream: every candidate profiled over its grid on the training
//! part, compared by a complexity-penalised criterion (BIC on the effective number of samples,
//! gap-diagnosis.md sections 1.12 and 4.3), forward selection of further effects on the
//! remainder, a structure probe of what no candidate explains, and the held-out gap with each
//! effect added.

use rayon::prelude::*;

use super::candidates::{self, Candidate, Context, Form};
use super::regression::{self, Fit, HeldoutGap, Segment};
use super::sensor::delta_bic;
use super::streams::RunStreams;

/// A candidate profiled over its grid.
#[derive(Debug, Clone)]
pub struct Profiled {
    /// The candidate.
    pub candidate: Candidate,
    /// The form with the most evidence.
    pub form: Form,
    /// The fit at that point.
    pub fit: Fit,
    /// Complexity-penalised evidence against no effect.
    pub delta_bic: f64,
    /// Profile: the criterion's residual sum of squares at each grid point (for the report).
    pub profile: Vec<(f64, f64)>,
    /// Gap on the selection part before and after the effect (with the training part's fit).
    pub selection: HeldoutGap,
    /// Held-out gap before and after the effect.
    pub heldout: HeldoutGap,
}

impl Profiled {
    /// Mean square explained per touched training sample.
    #[must_use]
    pub fn explained(&self) -> f64 {
        self.fit.explained_per_sample()
    }

    /// Mean square the effect, fitted on the training part, removes on the selection part: the
    /// evidence the decisions rest on (out of sample, so the sim's recording-to-recording
    /// scatter that no effect predicts does not count).
    #[must_use]
    pub fn selected(&self) -> f64 {
        self.selection.removed()
    }
}

/// Columns of a candidate in one form, for every run.
#[must_use]
pub fn all_columns(
    candidate: Candidate,
    form: &Form,
    runs: &[RunStreams],
    context: &Context<'_>,
) -> Vec<Vec<Vec<f64>>> {
    runs.iter().enumerate().map(|(idx, run)| candidates::columns(candidate, form, run, idx, context)).collect()
}

/// Profiles `candidate` on the residuals `residuals[run]`.
#[must_use]
pub fn profile(
    candidate: Candidate,
    runs: &[RunStreams],
    residuals: &[Vec<f64>],
    context: &Context<'_>,
    autocorrelation_time: f64,
) -> Option<Profiled> {
    let segments = segments(runs, residuals);
    let sample_hz = runs.first()?.sample_hz;
    let forms = candidates::forms(candidate, sample_hz, context);
    // Each form of the family with its evidence: the best form is the one with the most evidence
    // (its columns and profiled parameters penalised), so a richer form wins only by its fit.
    let fits: Vec<(Form, Fit, f64)> = forms
        .par_iter()
        .filter_map(|form| {
            let columns = all_columns(candidate, form, runs, context);
            regression::fit_through_origin(&segments, &columns).map(|fit| {
                let k = fit.beta.len() + form.n_profiled();
                let evidence = delta_bic(&fit, autocorrelation_time, k);
                (*form, fit, evidence)
            })
        })
        .collect();
    let profile = fits.iter().map(|(form, fit, _)| (form.coordinate().map_or(0.0, |(_, v)| v), fit.ssr)).collect();
    let (form, fit, delta_bic) = fits.into_iter().max_by(|a, b| a.2.total_cmp(&b.2))?;
    let columns = all_columns(candidate, &form, runs, context);
    let selection = regression::selection_gap(&segments, &columns, &fit.beta, &fit.touched);
    let heldout = regression::heldout_gap(&segments, &columns, &fit.beta, &fit.touched);
    Some(Profiled { candidate, form, fit, delta_bic, profile, selection, heldout })
}

/// The segments of the residual stream.
#[must_use]
pub fn segments<'a>(runs: &[RunStreams], residuals: &'a [Vec<f64>]) -> Vec<Segment<'a>> {
    runs.iter()
        .zip(residuals)
        .map(|(run, residual)| Segment {
            residual,
            training: run.training.clone(),
            select: run.select,
            heldout: run.heldout.clone(),
        })
        .collect()
}

/// Subtracts a profiled effect from the residuals (over whole runs).
#[must_use]
pub fn subtract(
    profiled: &Profiled,
    runs: &[RunStreams],
    residuals: &[Vec<f64>],
    context: &Context<'_>,
) -> Vec<Vec<f64>> {
    let columns = all_columns(profiled.candidate, &profiled.form, runs, context);
    residuals
        .iter()
        .zip(&columns)
        .map(|(residual, cols)| {
            residual
                .iter()
                .enumerate()
                .map(|(idx, r)| r - cols.iter().zip(&profiled.fit.beta).map(|(col, b)| b * col[idx]).sum::<f64>())
                .collect()
        })
        .collect()
}

/// Groups of the structure probe: shapes outside every candidate's span that a real gap often
/// has. Used only to say that something remains, never to name it; each group is compared
/// with its own floor in the sim's signature.
pub const PROBE_GROUPS: [&str; 3] = ["static_nonlinearity", "slow_gain", "input_dynamics"];

/// The probe groups also asked of the remainder after a named effect: shapes no candidate
/// spans. `input_dynamics` spans much of what the candidates do and asks only whether the
/// residual holds input-driven structure when nothing is named.
pub const REMAINDER_PROBE_GROUPS: [&str; 2] = ["static_nonlinearity", "slow_gain"];

/// Time constants of the `input_dynamics` probe, s: fast, middle and slow, a decade apart.
const PROBE_TAUS_S: [f64; 3] = [0.02, 0.2, 2.0];

/// Columns of one probe group (see [`PROBE_GROUPS`]): odd powers of the roll angle, rate
/// nonlinearity and the eGK moment's growth with the angle (`static_nonlinearity`); the sim's
/// moment times Legendre polynomials of time per run, a slowly varying gain (`slow_gain`); the
/// roll angle, reduced roll rate, total blowing and the sim's moment through first-order lags of
/// three time scales (`input_dynamics`: any linear dynamics the sim lacks).
#[must_use]
pub fn probe_columns(runs: &[RunStreams], group: &str) -> Vec<Vec<Vec<f64>>> {
    let n_runs = runs.len();
    runs.iter()
        .enumerate()
        .map(|(run_idx, run)| {
            let n = run.len();
            if group == "input_dynamics" {
                let dt_s = 1.0 / run.sample_hz;
                let blowing: Vec<f64> = (0..n).map(|idx| run.cmu[0][idx] + run.cmu[1][idx]).collect();
                let sim = run.cl_sim();
                let mut cols = Vec::new();
                for signal in [&run.phi_rad, &run.phi_dot_rad_s, &blowing, &sim] {
                    for tau_s in PROBE_TAUS_S {
                        cols.push(candidates::first_order_lag(signal, tau_s, dt_s));
                    }
                }
                return cols;
            }
            if group == "static_nonlinearity" {
                return vec![
                    run.phi_rad.iter().map(|phi| phi.powi(3)).collect::<Vec<f64>>(),
                    run.phi_rad.iter().map(|phi| phi.powi(5)).collect(),
                    run.phi_dot_rad_s.iter().map(|rate| rate * rate.abs()).collect(),
                    run.phi_dot_rad_s.iter().map(|rate| (rate / 0.2).tanh()).collect(),
                    run.phi_rad.iter().zip(&run.cl_egk).map(|(phi, cl)| cl * phi * phi).collect(),
                ];
            }
            let sim = run.cl_sim();
            let duration = run.t_s.last().copied().unwrap_or(1.0).max(f64::MIN_POSITIVE);
            let mut cols = Vec::new();
            for run_slot in 0..n_runs {
                for degree in 1..=4 {
                    cols.push(if run_slot == run_idx {
                        (0..n).map(|idx| sim[idx] * legendre(degree, 2.0 * run.t_s[idx] / duration - 1.0)).collect()
                    } else {
                        vec![0.0; n]
                    });
                }
            }
            cols
        })
        .collect()
}

/// Legendre polynomial `P_degree(x)` by the three-term recurrence.
#[must_use]
pub fn legendre(degree: usize, x: f64) -> f64 {
    let (mut previous, mut current) = (1.0, x);
    if degree == 0 {
        return 1.0;
    }
    for n in 1..degree {
        let next = ((2 * n + 1) as f64 * x * current - n as f64 * previous) / (n + 1) as f64;
        previous = current;
        current = next;
    }
    current
}

//! The map from the filtered pressures to `C_l` (step 8 of [`super`]), one per breakpoint of
//! the alpha schedule, by ridge regression.

use estimator_core::coeffs::N_TAPS;
use estimator_core::pressure::PressureFilter;
use nalgebra::{Cholesky, DMatrix, DVector};
use rayon::prelude::*;

use super::*;

/// The breakpoint nearest to `alpha_deg` (the first of a tie).
pub(super) fn nearest_breakpoint(breakpoints_deg: &[f64], alpha_deg: f64) -> usize {
    (0..breakpoints_deg.len())
        .min_by(|&a, &b| (breakpoints_deg[a] - alpha_deg).abs().total_cmp(&(breakpoints_deg[b] - alpha_deg).abs()))
        .unwrap_or(0)
}

/// The map `C_l,p = w . Cp_filtered + w0` and its training fit.
#[derive(Debug, Clone)]
pub(super) struct ClMap {
    /// Weights of the taps at each breakpoint.
    pub(super) weights: Vec<[f64; N_TAPS]>,
    /// Offset at each breakpoint.
    pub(super) offsets: Vec<f64>,
    pub(super) rms: f64,
    pub(super) cl_std: f64,
    pub(super) n_samples: usize,
}

/// Ridge least squares of `cl` on the filtered pressures of the disturbance runs (step 8), one
/// map per breakpoint of the alpha schedule from the samples nearest to it. A breakpoint
/// without enough samples of its own takes the map of the nearest breakpoint that has them.
pub(super) fn fit_cl_map(
    runs: &[PressureRun<'_>],
    table: &PressureTable,
    config: &PressureFitConfig,
) -> Result<ClMap, PressureFitError> {
    let samples = cl_samples(runs, table, config.warmup_samples);
    let n_samples = samples.targets.len();
    if n_samples <= N_TAPS + 1 {
        return Err(PressureFitError::TooFewSamples {
            stage: "C_l map (disturbance runs)",
            found: n_samples,
            needed: N_TAPS + 2,
        });
    }
    let breakpoints = &table.breakpoints_deg;
    let group: Vec<usize> = samples.alpha_deg.iter().map(|&alpha| nearest_breakpoint(breakpoints, alpha)).collect();
    let mut maps: Vec<Option<([f64; N_TAPS], f64)>> = Vec::with_capacity(breakpoints.len());
    for idx in 0..breakpoints.len() {
        let members: Vec<usize> = (0..n_samples).filter(|&row| group[row] == idx).collect();
        if members.len() <= N_TAPS + 1 {
            maps.push(None);
            continue;
        }
        let rows: Vec<[f64; N_TAPS]> = members.iter().map(|&row| samples.rows[row]).collect();
        let targets: Vec<f64> = members.iter().map(|&row| samples.targets[row]).collect();
        maps.push(Some(ridge_regression(&rows, &targets, config.ridge)?));
    }
    let fitted: Vec<usize> = (0..maps.len()).filter(|&idx| maps[idx].is_some()).collect();
    if fitted.is_empty() {
        // No breakpoint has enough samples of its own: one map from all of them.
        let map = ridge_regression(&samples.rows, &samples.targets, config.ridge)?;
        maps = vec![Some(map); breakpoints.len()];
    } else {
        for idx in 0..maps.len() {
            if maps[idx].is_none() {
                let nearest = fitted
                    .iter()
                    .copied()
                    .min_by(|&a, &b| {
                        (breakpoints[a] - breakpoints[idx]).abs().total_cmp(&(breakpoints[b] - breakpoints[idx]).abs())
                    })
                    .unwrap_or(fitted[0]);
                maps[idx] = maps[nearest];
            }
        }
    }
    let (weights, offsets): (Vec<[f64; N_TAPS]>, Vec<f64>) = maps.into_iter().flatten().unzip();
    // The training error of the map as the core applies it: each neighbouring breakpoint's
    // map, then linear interpolation of the two values.
    let mapped = |row: &[f64; N_TAPS], alpha_deg: f64| {
        let map = |idx: usize| weights[idx].iter().zip(row).map(|(w, cp)| w * cp).sum::<f64>() + offsets[idx];
        let at = table.position(alpha_deg);
        let low = map(at.lower);
        if at.weight == 0.0 { low } else { low + at.weight * (map(at.upper) - low) }
    };
    let n = n_samples as f64;
    let sq_error: f64 = (0..n_samples)
        .map(|row| (samples.targets[row] - mapped(&samples.rows[row], samples.alpha_deg[row])).powi(2))
        .sum();
    let y_mean = samples.targets.iter().sum::<f64>() / n;
    let cl_std = (samples.targets.iter().map(|y| (y - y_mean).powi(2)).sum::<f64>() / n).sqrt();
    let rms = (sq_error / n).sqrt();
    let finite = weights.iter().flatten().chain(&offsets).all(|value| value.is_finite());
    if !(rms.is_finite() && finite) {
        return Err(PressureFitError::NonFinite("C_l map"));
    }
    Ok(ClMap { weights, offsets, rms, cl_std, n_samples })
}

/// `y ~ w . x + w0` by ridge regression (Hoerl & Kennard 1970): the columns are centred and
/// scaled to unit variance, `(X^T X / n + ridge I) w_s = X^T y / n`, and the intercept is not
/// penalised. Returns `w` in the original units and `w0`.
pub(super) fn ridge_regression(
    rows: &[[f64; N_TAPS]],
    targets: &[f64],
    ridge: f64,
) -> Result<([f64; N_TAPS], f64), PressureFitError> {
    let n = targets.len().max(1) as f64;
    let x_mean: [f64; N_TAPS] = std::array::from_fn(|tap| rows.iter().map(|row| row[tap]).sum::<f64>() / n);
    let y_mean = targets.iter().sum::<f64>() / n;
    let x_std: [f64; N_TAPS] = std::array::from_fn(|tap| {
        let var = rows.iter().map(|row| (row[tap] - x_mean[tap]).powi(2)).sum::<f64>() / n;
        if var > 0.0 { var.sqrt() } else { 1.0 }
    });
    let mut normal = DMatrix::identity(N_TAPS, N_TAPS) * ridge;
    let mut rhs = DVector::zeros(N_TAPS);
    for (row, &y) in rows.iter().zip(targets) {
        let x = DVector::from_fn(N_TAPS, |tap, _| (row[tap] - x_mean[tap]) / x_std[tap]);
        normal.ger(1.0 / n, &x, &x, 1.0);
        rhs.axpy((y - y_mean) / n, &x, 1.0);
    }
    let solution = solve_spd(normal, &rhs)?;
    let weights: [f64; N_TAPS] = std::array::from_fn(|tap| solution[tap] / x_std[tap]);
    let offset = y_mean - weights.iter().zip(&x_mean).map(|(w, x)| w * x).sum::<f64>();
    Ok((weights, offset))
}

/// Solves a symmetric positive-definite system by Cholesky.
pub(super) fn solve_spd(matrix: DMatrix<f64>, rhs: &DVector<f64>) -> Result<DVector<f64>, PressureFitError> {
    Cholesky::new(matrix)
        .map(|chol| chol.solve(rhs))
        .ok_or(PressureFitError::Decomposition("Cholesky factorisation of the C_l normal equations"))
}

/// The filtered pressures, measured `cl` and alpha of every disturbance-run sample after the
/// warm-up where `cl` is finite.
pub(super) struct ClSamples {
    pub(super) rows: Vec<[f64; N_TAPS]>,
    pub(super) targets: Vec<f64>,
    pub(super) alpha_deg: Vec<f64>,
}

pub(super) fn cl_samples(runs: &[PressureRun<'_>], table: &PressureTable, warmup: usize) -> ClSamples {
    let per_run: Vec<ClSamples> = runs
        .par_iter()
        .filter_map(|run| Some((run, run.disturbance?)))
        .map(|(run, disturbance)| {
            let mut samples =
                ClSamples { rows: Vec::with_capacity(run.len()), targets: Vec::new(), alpha_deg: Vec::new() };
            let mut filter = PressureFilter::at_start(&table.model);
            let mut inputs = HeldInputs::default();
            for (k, &target) in disturbance.iter().enumerate().take(run.len()) {
                let step =
                    filter_step(&mut filter, table, &inputs.hold(run.inputs(k)), &run.cp_at(k), run.alpha_deg[k]);
                if k >= warmup && target.is_finite() {
                    samples.rows.push(step.filtered_cp);
                    samples.targets.push(target);
                    samples.alpha_deg.push(run.alpha_deg[k]);
                }
            }
            samples
        })
        .collect();
    per_run.into_iter().fold(
        ClSamples { rows: Vec::new(), targets: Vec::new(), alpha_deg: Vec::new() },
        |mut all, run| {
            all.rows.extend(run.rows);
            all.targets.extend(run.targets);
            all.alpha_deg.extend(run.alpha_deg);
            all
        },
    )
}

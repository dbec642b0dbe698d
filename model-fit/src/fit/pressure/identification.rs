//! Identification of the pressure dynamics (steps 1-5 of [`super`]): the delay embedding,
//! its proper orthogonal decomposition and the DMD-with-control fit of the reduced dynamics.

use estimator_core::coeffs::{N_ALPHA, N_PRESSURE_INPUTS, N_TAPS, PRESSURE_RANK, PressureModel};
use nalgebra::{DMatrix, DVector, SVD, Schur};
use rayon::prelude::*;

use super::*;

/// Iteration cap of the dense decompositions (SVD, Schur); they converge in far fewer.
pub(super) const DECOMPOSITION_ITERATIONS: usize = 10_000;

/// Eigenvalues of the snapshot Gram matrix below this fraction of the largest are round-off:
/// the Gram matrix squares the singular values, so `1e-12` is `sigma / sigma_max = 1e-6`.
pub(super) const GRAM_RANK_TOLERANCE: f64 = 1e-12;

/// Singular values of the scaled regressor below this fraction of the largest are treated as
/// zero (a column without excitation, such as `Cmu` in roll-only data, gets a zero input column).
pub(super) const REGRESSION_RANK_TOLERANCE: f64 = 1e-10;

/// Covariance of the reduced state over the training samples (the POD coordinates are centred,
/// so their mean is zero).
pub(super) fn state_covariance(reduced: &[ReducedRun]) -> DMatrix<f64> {
    let rank = reduced.first().map_or(0, |run| run.coords.nrows());
    let mut sum = DMatrix::zeros(rank, rank);
    let mut count = 0usize;
    for run in reduced {
        sum += &run.coords * run.coords.transpose();
        count += run.coords.ncols();
    }
    sum / count.max(1) as f64
}

/// The model before the filter is tuned: `A`, `B`, `C` and `cp_mean` fitted, no gain, no map,
/// scheduled on `breakpoints_deg` (none is one map at 0 deg; at most [`N_ALPHA`] are kept).
pub(super) fn untuned_model(
    pod: &Pod,
    dynamics: &Dynamics,
    config: &PressureFitConfig,
    breakpoints_deg: &[f64],
) -> Result<PressureTable, PressureFitError> {
    let rank = pod.rank;
    if rank > PRESSURE_RANK || dynamics.a.shape() != (rank, rank) || dynamics.b.shape() != (rank, N_PRESSURE_INPUTS) {
        return Err(PressureFitError::InvalidModel("the rank exceeds PRESSURE_RANK or A, B do not match it"));
    }
    let padded = |matrix: &DMatrix<f64>, row: usize, col: usize| {
        if row < matrix.nrows() && col < matrix.ncols() { matrix[(row, col)] } else { 0.0 }
    };
    let c = pod.basis.rows(0, N_TAPS).into_owned();
    let model = PressureModel {
        rank: u8::try_from(rank).map_err(|_| PressureFitError::InvalidModel("the rank does not fit in u8"))?,
        a: std::array::from_fn(|row| std::array::from_fn(|col| padded(&dynamics.a, row, col))),
        b: std::array::from_fn(|row| std::array::from_fn(|col| padded(&dynamics.b, row, col))),
        c: std::array::from_fn(|tap| std::array::from_fn(|mode| padded(&c, tap, mode))),
        cp_mean: std::array::from_fn(|tap| pod.mean[tap]),
        gain: [[0.0; N_TAPS]; PRESSURE_RANK],
        innovation_std: [1.0; N_TAPS],
        gate_sigma: config.gate_sigma,
        isolate_after: config.isolate_after,
        settle_steps: 0,
        cl_weights: [[0.0; N_TAPS]; N_ALPHA],
        cl_offset: [0.0; N_ALPHA],
    };
    let breakpoints_deg = if breakpoints_deg.is_empty() {
        vec![0.0]
    } else {
        breakpoints_deg[..breakpoints_deg.len().min(N_ALPHA)].to_vec()
    };
    Ok(PressureTable { model, breakpoints_deg })
}

/// The delay embedding `z_k = [x_k; x_{k-s}; ...; x_{k-(h-1)s}]`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Embedding {
    pub(super) delays: usize,
    pub(super) spacing: usize,
}

impl Embedding {
    /// Length of a snapshot, `12 h`.
    pub(super) fn dim(&self) -> usize {
        N_TAPS * self.delays
    }

    /// Samples before the newest one that a snapshot reaches back.
    pub(super) fn span(&self) -> usize {
        (self.delays - 1) * self.spacing
    }

    /// Fills `out` with `z_k` of `run` and returns true, or returns false when the snapshot
    /// reaches before the run's start or needs a non-finite tap.
    pub(super) fn snapshot(&self, run: &PressureRun<'_>, k: usize, out: &mut [f64]) -> bool {
        if k < self.span() || k >= run.len() {
            return false;
        }
        for block in 0..self.delays {
            let sample = k - block * self.spacing;
            for (tap, values) in run.cp.iter().enumerate() {
                let value = values[sample];
                if !value.is_finite() {
                    return false;
                }
                out[block * N_TAPS + tap] = value;
            }
        }
        true
    }

    /// The snapshots of `run` minus `mean`, as columns, and the sample index of each.
    pub(super) fn centred_snapshots(&self, run: &PressureRun<'_>, mean: &DVector<f64>) -> (DMatrix<f64>, Vec<usize>) {
        let mut values = Vec::with_capacity(run.len() * self.dim());
        let mut samples = Vec::with_capacity(run.len());
        let mut z = vec![0.0; self.dim()];
        for k in 0..run.len() {
            if self.snapshot(run, k, &mut z) {
                values.extend(z.iter().zip(mean.iter()).map(|(value, mean)| value - mean));
                samples.push(k);
            }
        }
        (DMatrix::from_vec(self.dim(), samples.len(), values), samples)
    }
}

/// The truncated POD basis of the centred snapshots.
#[derive(Debug, Clone)]
pub(super) struct Pod {
    /// `zbar`.
    pub(super) mean: DVector<f64>,
    /// `U_r` (`12 h x r`).
    pub(super) basis: DMatrix<f64>,
    pub(super) rank: usize,
    pub(super) data_rank: usize,
    pub(super) energy_kept: f64,
    pub(super) n_snapshots: usize,
}

impl Pod {
    /// Mean, Gram matrix and its eigen-decomposition; the rank rule of step 2.
    pub(super) fn fit(
        runs: &[PressureRun<'_>],
        embedding: &Embedding,
        energy_fraction: f64,
    ) -> Result<Self, PressureFitError> {
        // Per-run parts in parallel, summed in run order: a parallel reduction's grouping
        // depends on work stealing, and floating-point sums on their grouping, which would make
        // the fit differ from run to run.
        let zero = DVector::zeros(embedding.dim());
        let parts: Vec<(DVector<f64>, usize)> = runs
            .par_iter()
            .map(|run| {
                let (snapshots, samples) = embedding.centred_snapshots(run, &zero);
                (snapshots.column_sum(), samples.len())
            })
            .collect();
        let (sum, n_snapshots) =
            parts.into_iter().fold((zero.clone(), 0), |(sum_a, n_a), (sum_b, n_b)| (sum_a + sum_b, n_a + n_b));
        let needed = embedding.dim() + 1;
        if n_snapshots < needed {
            return Err(PressureFitError::TooFewSamples { stage: "snapshot POD", found: n_snapshots, needed });
        }
        let mean = sum / n_snapshots as f64;
        let dim = embedding.dim();
        let grams: Vec<DMatrix<f64>> = runs
            .par_iter()
            .map(|run| {
                let (centred, _) = embedding.centred_snapshots(run, &mean);
                &centred * centred.transpose()
            })
            .collect();
        let gram = grams.into_iter().fold(DMatrix::zeros(dim, dim), |a, b| a + b);
        let svd = SVD::try_new(gram, true, false, f64::EPSILON, DECOMPOSITION_ITERATIONS)
            .ok_or(PressureFitError::Decomposition("SVD of the snapshot Gram matrix"))?;
        let u = svd.u.ok_or(PressureFitError::Decomposition("SVD of the snapshot Gram matrix"))?;
        let (rank, data_rank, energy_kept) = choose_rank(svd.singular_values.as_slice(), energy_fraction)?;
        Ok(Self { mean, basis: u.columns(0, rank).into_owned(), rank, data_rank, energy_kept, n_snapshots })
    }

    /// The reduced coordinates of every snapshot of `run`.
    pub(super) fn reduce(&self, run: &PressureRun<'_>, embedding: &Embedding) -> ReducedRun {
        let (centred, samples) = embedding.centred_snapshots(run, &self.mean);
        ReducedRun { coords: self.basis.transpose() * centred, samples }
    }
}

/// The smallest rank keeping `energy_fraction` of `sum sigma^2`, capped at [`PRESSURE_RANK`]
/// and at the data's rank, from the Gram eigenvalues `sigma^2` (descending). Returns the rank,
/// the data's rank and the energy kept.
pub(super) fn choose_rank(eigenvalues: &[f64], energy_fraction: f64) -> Result<(usize, usize, f64), PressureFitError> {
    let largest = eigenvalues.first().copied().unwrap_or(0.0);
    let data_rank = eigenvalues.iter().take_while(|&&value| value > largest * GRAM_RANK_TOLERANCE).count();
    if largest <= 0.0 || data_rank == 0 {
        return Err(PressureFitError::TooFewSamples { stage: "POD (the pressures are constant)", found: 0, needed: 1 });
    }
    let total: f64 = eigenvalues.iter().take(data_rank).sum();
    let mut kept = 0.0;
    let mut rank = 0;
    for &value in eigenvalues.iter().take(data_rank.min(PRESSURE_RANK)) {
        kept += value;
        rank += 1;
        if kept >= energy_fraction * total {
            break;
        }
    }
    Ok((rank, data_rank, kept / total))
}

/// The reduced coordinates `a_k` (columns) of one run and the sample index of each.
#[derive(Debug, Clone)]
pub(super) struct ReducedRun {
    pub(super) coords: DMatrix<f64>,
    pub(super) samples: Vec<usize>,
}

impl ReducedRun {
    /// Column pairs `(j - 1, j)` of consecutive samples whose inputs at `j` are finite.
    pub(super) fn pairs<'r>(&'r self, run: &'r PressureRun<'_>) -> impl Iterator<Item = (usize, usize)> + 'r {
        (1..self.samples.len())
            .filter(move |&j| {
                let k = self.samples[j];
                self.samples[j - 1] + 1 == k && run.inputs(k).iter().all(|value| value.is_finite())
            })
            .map(|j| (j - 1, j))
    }
}

/// The fitted dynamics `a_k = A a_{k-1} + B u_k` and its residual covariance.
#[derive(Debug, Clone)]
pub(super) struct Dynamics {
    pub(super) a: DMatrix<f64>,
    pub(super) b: DMatrix<f64>,
    pub(super) residual_cov: DMatrix<f64>,
    pub(super) radius_fitted: f64,
    pub(super) radius: f64,
    pub(super) n_samples: usize,
}

impl Dynamics {
    /// DMDc least squares (step 4), stabilisation (step 5) and the residual covariance.
    pub(super) fn fit(
        runs: &[PressureRun<'_>],
        reduced: &[ReducedRun],
        max_radius: f64,
    ) -> Result<Self, PressureFitError> {
        let rank = reduced.first().map_or(0, |run| run.coords.nrows());
        let (previous, inputs, targets) = regression_rows(runs, reduced, rank);
        let n_samples = targets.nrows();
        let needed = 2 * (rank + N_PRESSURE_INPUTS);
        if n_samples < needed {
            return Err(PressureFitError::TooFewSamples { stage: "dynamics fit", found: n_samples, needed });
        }
        let regressors = concat_columns(&previous, &inputs);
        let theta = scaled_least_squares(&regressors, &targets)?;
        let mut a = theta.rows(0, rank).transpose();
        let mut b = theta.rows(rank, N_PRESSURE_INPUTS).transpose();
        let radius_fitted = spectral_radius(&a)?;
        let mut radius = radius_fitted;
        if radius_fitted > max_radius {
            a *= max_radius / radius_fitted;
            radius = spectral_radius(&a)?;
            // Refit B with the scaled A: the input absorbs what the scaling took away.
            b = scaled_least_squares(&inputs, &(&targets - &previous * a.transpose()))?.transpose();
        }
        let residual = targets - previous * a.transpose() - &inputs * b.transpose();
        let residual_cov = residual.transpose() * &residual / n_samples as f64;
        let all_finite = a.iter().chain(b.iter()).chain(residual_cov.iter()).all(|value| value.is_finite());
        if !all_finite {
            return Err(PressureFitError::NonFinite("dynamics fit"));
        }
        Ok(Self { a, b, residual_cov, radius_fitted, radius, n_samples })
    }
}

/// The rows `a_{k-1}^T`, `u_k^T` and `a_k^T` of every usable consecutive pair of every run.
pub(super) fn regression_rows(
    runs: &[PressureRun<'_>],
    reduced: &[ReducedRun],
    rank: usize,
) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let mut previous = Vec::new();
    let mut inputs = Vec::new();
    let mut targets = Vec::new();
    for (run, coords) in runs.iter().zip(reduced) {
        for (before, after) in coords.pairs(run) {
            previous.extend(coords.coords.column(before).iter());
            inputs.extend(run.inputs(coords.samples[after]));
            targets.extend(coords.coords.column(after).iter());
        }
    }
    let n = targets.len() / rank.max(1);
    // Column-major storage of the transposes is row-major storage of the row matrices.
    let rows = |values: Vec<f64>, cols: usize| DMatrix::from_vec(cols, n, values).transpose();
    (rows(previous, rank), rows(inputs, N_PRESSURE_INPUTS), rows(targets, rank))
}

/// `[left right]`.
pub(super) fn concat_columns(left: &DMatrix<f64>, right: &DMatrix<f64>) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(left.nrows(), left.ncols() + right.ncols());
    out.columns_mut(0, left.ncols()).copy_from(left);
    out.columns_mut(left.ncols(), right.ncols()).copy_from(right);
    out
}

/// Least squares `X theta ~ Y` by an SVD of `X` with unit-RMS columns; singular values below
/// [`REGRESSION_RANK_TOLERANCE`] of the largest are dropped (minimum-norm solution, so an
/// unexcited column gets zero coefficients).
pub(super) fn scaled_least_squares(x: &DMatrix<f64>, y: &DMatrix<f64>) -> Result<DMatrix<f64>, PressureFitError> {
    let n = x.nrows().max(1) as f64;
    let scales: Vec<f64> = x
        .column_iter()
        .map(|column| {
            let rms = (column.norm_squared() / n).sqrt();
            if rms > 0.0 { rms } else { 1.0 }
        })
        .collect();
    let mut scaled = x.clone();
    for (mut column, scale) in scaled.column_iter_mut().zip(&scales) {
        column /= *scale;
    }
    let svd = SVD::try_new(scaled, true, true, f64::EPSILON, DECOMPOSITION_ITERATIONS)
        .ok_or(PressureFitError::Decomposition("SVD of the dynamics regressors"))?;
    let largest = svd.singular_values.max();
    let mut theta = svd
        .solve(y, largest * REGRESSION_RANK_TOLERANCE)
        .map_err(|_| PressureFitError::Decomposition("least squares of the dynamics"))?;
    for (mut row, scale) in theta.row_iter_mut().zip(&scales) {
        row /= *scale;
    }
    Ok(theta)
}

/// Largest eigenvalue magnitude of a square matrix (real Schur form).
pub(super) fn spectral_radius(matrix: &DMatrix<f64>) -> Result<f64, PressureFitError> {
    if matrix.is_empty() {
        return Ok(0.0);
    }
    let schur = Schur::try_new(matrix.clone(), f64::EPSILON, DECOMPOSITION_ITERATIONS)
        .ok_or(PressureFitError::Decomposition("Schur decomposition of A"))?;
    Ok(schur.complex_eigenvalues().iter().map(|value| value.norm()).fold(0.0, f64::max))
}

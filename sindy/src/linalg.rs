//! The dense linear algebra of the engine: a tall-skinny QR of `[Theta | y]` and the small
//! (ridge) least-squares solves on a subset of columns.
//!
//! Everything goes through Householder QR (Golub & Van Loan, *Matrix Computations*, 4th ed.,
//! section 5.2), so the normal equations, whose condition number is the square of the
//! library's, are never formed.

use nalgebra::{DMatrix, DVector, SVD};
use rayon::prelude::*;

use super::error::SindyError;

/// Rows per block of the tall-skinny QR. A block of 15 columns is 120 KB, which stays in a
/// core's L2 cache; the block size does not depend on the thread count, so the result is
/// deterministic.
const BLOCK_ROWS: usize = 1024;

/// Back substitution is used when the smallest |diagonal| of the triangular factor exceeds
/// this fraction of the largest (a condition number below about 1e10); otherwise the
/// minimum-norm solution comes from an SVD of the small factor.
const TRIANGULAR_RCOND: f64 = 1e-10;

/// The upper-triangular factor `R_aug` ((p + k) x (p + k)) of `[Theta | y_1 ... y_k] = Q R_aug`.
///
/// Its leading p x p block is the R of Theta; the column of target j holds `Q^T y_j` in its
/// first p rows and, below them, a vector whose norm is the residual `|y_j - Q Q^T y_j|`
/// (Golub & Van Loan, section 5.3.2: least squares via QR of the augmented matrix; one
/// target gives the single residual entry). Householder reflections act column by column, so
/// in exact arithmetic a target's column does not depend on the others. Blocks of rows are
/// reduced independently and their factors are stacked and reduced again (the TSQR of
/// Demmel, Grigori, Hoemmen & Langou, SIAM J. Sci. Comput. 34(1), 2012), which is exact
/// because `[A1; A2] = diag(Q1, Q2) [R1; R2]`.
pub(crate) fn tsqr_augmented(theta: &DMatrix<f64>, targets: &[&[f64]]) -> DMatrix<f64> {
    let n_rows = theta.nrows();
    let n_features = theta.ncols();
    let width = n_features + targets.len();
    let starts: Vec<usize> = (0..n_rows).step_by(BLOCK_ROWS).collect();
    let factors: Vec<DMatrix<f64>> = starts
        .par_iter()
        .map(|&start| {
            let rows = BLOCK_ROWS.min(n_rows - start);
            let block = DMatrix::from_fn(rows, width, |row, col| {
                if col < n_features { theta[(start + row, col)] } else { targets[col - n_features][start + row] }
            });
            block.qr().r()
        })
        .collect();
    let stacked_rows: usize = factors.iter().map(DMatrix::nrows).sum();
    let mut stacked = DMatrix::zeros(stacked_rows.max(width), width);
    let mut offset = 0;
    for factor in &factors {
        stacked.view_mut((offset, 0), factor.shape()).copy_from(factor);
        offset += factor.nrows();
    }
    stacked.qr().r()
}

/// The (ridge) least-squares solution on the columns `cols` of `a`:
/// `argmin_w |a[:, cols] w - b|^2 + ridge |w|^2`, solved as the ordinary least-squares
/// problem of the stacked matrix `[a[:, cols]; sqrt(ridge) I]` against `[b; 0]` (the
/// augmented form of Tikhonov regularisation, Golub & Van Loan, section 6.1.4). With
/// `ridge = 0` and a rank-deficient subset, the minimum-norm solution is returned, as
/// LAPACK's `gelsd` (used by `numpy.linalg.lstsq`) does.
pub(crate) fn solve_columns(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    cols: &[usize],
    ridge: f64,
) -> Result<Vec<f64>, SindyError> {
    let n_cols = cols.len();
    if n_cols == 0 {
        return Ok(Vec::new());
    }
    let extra = if ridge > 0.0 { n_cols } else { 0 };
    let n_rows = a.nrows() + extra;
    let mut stacked = DMatrix::zeros(n_rows, n_cols);
    for (k, &col) in cols.iter().enumerate() {
        stacked.view_mut((0, k), (a.nrows(), 1)).copy_from(&a.column(col));
    }
    let root = ridge.sqrt();
    for k in 0..extra {
        stacked[(a.nrows() + k, k)] = root;
    }
    let mut rhs = DVector::zeros(n_rows);
    rhs.rows_mut(0, b.len()).copy_from(b);
    least_squares(stacked, rhs)
}

/// Minimum-norm least squares `argmin |m x - rhs|` by Householder QR, with back substitution
/// when the triangular factor is well conditioned and an SVD of the small factor otherwise.
fn least_squares(m: DMatrix<f64>, mut rhs: DVector<f64>) -> Result<Vec<f64>, SindyError> {
    let (n_rows, n_cols) = m.shape();
    let qr = m.qr();
    qr.q_tr_mul(&mut rhs);
    let r = qr.r();
    let rank_rows = r.nrows();
    let top = rhs.rows(0, rank_rows).into_owned();
    if rank_rows == n_cols
        && well_conditioned(&r)
        && let Some(solution) = r.solve_upper_triangular(&top)
        && solution.iter().all(|value| value.is_finite())
    {
        return Ok(solution.as_slice().to_vec());
    }
    min_norm_svd(r, &top, n_rows.max(n_cols))
}

/// Whether the smallest |diagonal| of a triangular factor exceeds [`TRIANGULAR_RCOND`] times
/// the largest.
fn well_conditioned(r: &DMatrix<f64>) -> bool {
    let diagonal = r.diagonal();
    let largest = diagonal.iter().fold(0.0f64, |acc, value| acc.max(value.abs()));
    let smallest = diagonal.iter().fold(f64::INFINITY, |acc, value| acc.min(value.abs()));
    largest > 0.0 && smallest > TRIANGULAR_RCOND * largest
}

/// Minimum-norm solution of `r x = c` by SVD, treating singular values below
/// `eps * max(M, N) * sigma_max` as zero: the default `rcond` of `numpy.linalg.lstsq`.
/// The singular values of `r` are those of the original matrix (`Q` is orthonormal).
fn min_norm_svd(r: DMatrix<f64>, c: &DVector<f64>, size_for_rcond: usize) -> Result<Vec<f64>, SindyError> {
    let n_cols = r.ncols();
    let max_iterations = 200 * (n_cols + 1);
    let svd = SVD::try_new(r, true, true, f64::EPSILON, max_iterations)
        .ok_or(SindyError::NumericalFailure("the SVD of the small least-squares problem did not converge"))?;
    let largest = svd.singular_values.iter().fold(0.0f64, |acc, value| acc.max(*value));
    let cutoff = f64::EPSILON * size_for_rcond as f64 * largest;
    let solution = svd.solve(c, cutoff).map_err(SindyError::NumericalFailure)?;
    if largest == 0.0 {
        return Ok(vec![0.0; n_cols]);
    }
    Ok(solution.as_slice().to_vec())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tsqr_matches_a_direct_qr_up_to_row_signs() {
        let n_rows = 3 * BLOCK_ROWS + 17;
        let theta = DMatrix::from_fn(n_rows, 4, |row, col| ((row * (col + 3)) as f64 * 0.37).sin() + col as f64);
        let y: Vec<f64> = (0..n_rows).map(|row| (row as f64 * 0.11).cos()).collect();
        let r_blocks = tsqr_augmented(&theta, &[&y]);
        let direct = DMatrix::from_fn(n_rows, 5, |row, col| if col < 4 { theta[(row, col)] } else { y[row] }).qr().r();
        for row in 0..5 {
            let sign = r_blocks[(row, row)].signum() * direct[(row, row)].signum();
            for col in 0..5 {
                assert!((r_blocks[(row, col)] - sign * direct[(row, col)]).abs() < 1e-9 * direct.norm());
            }
        }
    }

    #[test]
    fn rank_deficient_columns_give_the_minimum_norm_solution() {
        // Two identical columns: the minimum-norm solution splits the weight evenly.
        let a = DMatrix::from_fn(20, 3, |row, col| if col == 2 { 1.0 } else { row as f64 });
        let b = DVector::from_fn(20, |row, _| 4.0 * row as f64 + 1.0);
        let solution = solve_columns(&a, &b, &[0, 1, 2], 0.0).unwrap();
        assert!((solution[0] - 2.0).abs() < 1e-9 && (solution[1] - 2.0).abs() < 1e-9, "{solution:?}");
        assert!((solution[2] - 1.0).abs() < 1e-9);
        let zero = DMatrix::zeros(5, 2);
        assert_eq!(solve_columns(&zero, &DVector::from_element(5, 1.0), &[0, 1], 0.0).unwrap(), [0.0, 0.0]);
        assert!(solve_columns(&a, &b, &[], 0.0).unwrap().is_empty());
    }

    #[test]
    fn ridge_matches_the_normal_equations() {
        let a = DMatrix::from_fn(30, 3, |row, col| ((row + 1) as f64).powi(col as i32 % 2) * (1.0 + col as f64));
        let b = DVector::from_fn(30, |row, _| (row as f64).sqrt());
        let alpha = 0.7;
        let ours = solve_columns(&a, &b, &[0, 2], alpha).unwrap();
        let sub = DMatrix::from_columns(&[a.column(0), a.column(2)]);
        let normal = sub.transpose() * &sub + DMatrix::identity(2, 2) * alpha;
        let expected = normal.lu().solve(&(sub.transpose() * &b)).unwrap();
        assert!((ours[0] - expected[0]).abs() < 1e-10 && (ours[1] - expected[1]).abs() < 1e-10);
    }
}

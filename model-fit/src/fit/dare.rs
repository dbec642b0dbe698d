//! The discrete algebraic Riccati equation (DARE) of the steady-state Kalman filter, in the
//! filter form
//!
//! `P = A P A^T - A P C^T (C P C^T + R)^-1 C P A^T + Q`,
//!
//! where `P` is the steady-state prior (predicted) covariance (Anderson & Moore, Optimal
//! Filtering, 1979, ch. 4, eq. 4.4). It is solved with the structured doubling algorithm (SDA) of
//! E. K.-W. Chu, H.-Y. Fan and W.-W. Lin, "A structure-preserving doubling algorithm for
//! continuous-time algebraic Riccati equations", Linear Algebra Appl. 396, 2005, in its
//! discrete-time form (Chu, Fan, Lin, Wang, "Structure-preserving algorithms for periodic
//! discrete-time algebraic Riccati equations", Int. J. Control 77, 2004): with `G = C^T R^-1 C`
//! the filter DARE is `P = A P (I + G P)^-1 A^T + Q` (matrix inversion lemma), which is the
//! control-form DARE `X = Ab^T X (I + G X)^-1 Ab + H` for `Ab = A^T`, `H = Q`, and the iteration
//!
//! ```text
//! W_k     = I + G_k H_k
//! A_{k+1} = A_k W_k^-1 A_k
//! G_{k+1} = G_k + A_k W_k^-1 G_k A_k^T
//! H_{k+1} = H_k + A_k^T H_k W_k^-1 A_k
//! ```
//!
//! from `(A_0, G_0, H_0) = (A^T, C^T R^-1 C, Q)` converges quadratically, `H_k -> P`, when
//! `(A, C)` is detectable and `(A, Q^(1/2))` is stabilisable. After `k` steps `H_k` is the
//! Riccati-difference iterate after `2^k` steps from `P_0 = Q`.

use nalgebra::{Cholesky, DMatrix, LU};

/// Convergence test and iteration cap of [`solve_filter_dare`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DareOptions {
    /// The iteration stops when `||H_{k+1} - H_k||_F <= tolerance * ||H_{k+1}||_F`.
    pub tolerance: f64,
    /// Largest number of doubling steps (step `k` covers `2^k` Riccati-difference steps).
    pub max_iterations: usize,
}

impl Default for DareOptions {
    /// A relative change of 1e-12 (the iteration converges quadratically, so the next step would
    /// be at round-off) and 100 doubling steps, far more than any detectable system needs.
    fn default() -> Self {
        Self { tolerance: 1e-12, max_iterations: 100 }
    }
}

/// The stabilising solution of the filter DARE and the steady-state Kalman filter built on it.
#[derive(Debug, Clone, PartialEq)]
pub struct DareSolution {
    /// Steady-state prior covariance `P` (`n x n`, symmetric).
    pub p: DMatrix<f64>,
    /// Steady-state gain `K = P C^T (C P C^T + R)^-1` (`n x m`), applied to the predicted state:
    /// `a = a_pred + K (y - C a_pred)` (Anderson & Moore, eq. 4.1.11).
    pub gain: DMatrix<f64>,
    /// Innovation covariance `S = C P C^T + R` (`m x m`).
    pub innovation_cov: DMatrix<f64>,
    /// Doubling steps taken.
    pub iterations: usize,
    /// `||P - (A P A^T - A P C^T S^-1 C P A^T + Q)||_F / ||P||_F` at the solution.
    pub relative_residual: f64,
}

/// Why the DARE could not be solved.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DareError {
    /// A matrix has the wrong shape.
    #[error("{name} is {rows}x{cols}, expected {expected_rows}x{expected_cols}")]
    Dimension {
        /// Which matrix (`"A"`, `"C"`, `"Q"` or `"R"`).
        name: &'static str,
        /// Its rows.
        rows: usize,
        /// Its columns.
        cols: usize,
        /// Rows it must have.
        expected_rows: usize,
        /// Columns it must have.
        expected_cols: usize,
    },
    /// A matrix holds a NaN or an infinity.
    #[error("{0} has a non-finite entry")]
    NonFinite(&'static str),
    /// `R` has no Cholesky factor, so `G = C^T R^-1 C` does not exist.
    #[error("the measurement noise covariance R is not positive definite")]
    NoiseNotPositiveDefinite,
    /// `C P C^T + R` has no Cholesky factor at the solution.
    #[error("the innovation covariance C P C^T + R is not positive definite")]
    InnovationNotPositiveDefinite,
    /// `I + G_k H_k` could not be factorised.
    #[error("the doubling step {iteration} met a singular I + G H")]
    Singular {
        /// Doubling step at which it happened.
        iteration: usize,
    },
    /// The iterates became non-finite (an undetectable unstable mode makes `H_k` grow without
    /// bound).
    #[error("the doubling iteration diverged at step {iteration}")]
    Diverged {
        /// Doubling step at which it happened.
        iteration: usize,
    },
    /// The relative change did not fall below the tolerance within the iteration cap.
    #[error("no convergence after {iterations} doubling steps (relative change {relative_change:e})")]
    NotConverged {
        /// Doubling steps taken.
        iterations: usize,
        /// Relative change of the last step.
        relative_change: f64,
    },
}

/// Solves the filter-form DARE with the structured doubling algorithm (module docs) and returns
/// `P`, the steady-state gain `K = P C^T S^-1` and `S = C P C^T + R`.
///
/// Sized for the pressure model (`n <= 10` states, `m <= 12` outputs) but valid for any sizes.
/// `Q` (`n x n`) and `R` (`m x m`) are symmetrised; `R` must be positive definite, `Q` positive
/// semi-definite.
///
/// # Errors
///
/// [`DareError`] for wrong shapes, non-finite inputs, an `R` or `S` that is not positive
/// definite, a singular or diverging doubling step, or no convergence within the cap.
pub fn solve_filter_dare(
    a: &DMatrix<f64>,
    c: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    options: &DareOptions,
) -> Result<DareSolution, DareError> {
    check_inputs(a, c, q, r)?;
    let q = symmetrised(q);
    let r = symmetrised(r);
    let r_chol = Cholesky::new(r.clone()).ok_or(DareError::NoiseNotPositiveDefinite)?;
    let g = symmetrised(&(c.transpose() * r_chol.solve(c)));
    let (p, iterations) = doubling(a.transpose(), g, q.clone(), options)?;
    let innovation_cov = symmetrised(&(c * &p * c.transpose() + &r));
    let s_chol = Cholesky::new(innovation_cov.clone()).ok_or(DareError::InnovationNotPositiveDefinite)?;
    // `K = P C^T S^-1 = (S^-1 C P)^T`, as `S` and `P` are symmetric.
    let gain = s_chol.solve(&(c * &p)).transpose();
    let relative_residual = residual(a, c, &q, &p, &s_chol);
    Ok(DareSolution { p, gain, innovation_cov, iterations, relative_residual })
}

/// The relative residual of the filter DARE at `p`, given the Cholesky factor of
/// `S = C P C^T + R`.
fn residual(
    a: &DMatrix<f64>,
    c: &DMatrix<f64>,
    q: &DMatrix<f64>,
    p: &DMatrix<f64>,
    s_chol: &Cholesky<f64, nalgebra::Dyn>,
) -> f64 {
    let m = a * p * c.transpose();
    let rhs = a * p * a.transpose() - &m * s_chol.solve(&m.transpose()) + q;
    (p - rhs).norm() / p.norm().max(f64::MIN_POSITIVE)
}

/// The doubling iteration (module docs): returns the converged `H` and the steps taken.
fn doubling(
    mut ak: DMatrix<f64>,
    mut gk: DMatrix<f64>,
    mut hk: DMatrix<f64>,
    options: &DareOptions,
) -> Result<(DMatrix<f64>, usize), DareError> {
    let n = ak.nrows();
    let mut relative_change = f64::INFINITY;
    for iteration in 1..=options.max_iterations {
        let w = DMatrix::identity(n, n) + &gk * &hk;
        let lu = LU::new(w);
        let w_inv_a = lu.solve(&ak).ok_or(DareError::Singular { iteration })?;
        let w_inv_g = lu.solve(&gk).ok_or(DareError::Singular { iteration })?;
        let h_next = symmetrised(&(&hk + ak.transpose() * &hk * &w_inv_a));
        let g_next = symmetrised(&(&gk + &ak * w_inv_g * ak.transpose()));
        ak = &ak * w_inv_a;
        if !(h_next.iter().all(|v| v.is_finite()) && g_next.iter().all(|v| v.is_finite())) {
            return Err(DareError::Diverged { iteration });
        }
        relative_change = (&h_next - &hk).norm() / h_next.norm().max(f64::MIN_POSITIVE);
        hk = h_next;
        gk = g_next;
        if relative_change <= options.tolerance {
            return Ok((hk, iteration));
        }
    }
    Err(DareError::NotConverged { iterations: options.max_iterations, relative_change })
}

/// Checks shapes (`A` square `n x n`, `C` `m x n`, `Q` `n x n`, `R` `m x m`) and finiteness.
fn check_inputs(a: &DMatrix<f64>, c: &DMatrix<f64>, q: &DMatrix<f64>, r: &DMatrix<f64>) -> Result<(), DareError> {
    let n = a.nrows();
    let m = c.nrows();
    for (name, matrix, rows, cols) in [("A", a, n, n), ("C", c, m, n), ("Q", q, n, n), ("R", r, m, m)] {
        if matrix.shape() != (rows, cols) {
            let (actual_rows, actual_cols) = matrix.shape();
            return Err(DareError::Dimension {
                name,
                rows: actual_rows,
                cols: actual_cols,
                expected_rows: rows,
                expected_cols: cols,
            });
        }
        if !matrix.iter().all(|value| value.is_finite()) {
            return Err(DareError::NonFinite(name));
        }
    }
    Ok(())
}

/// `(M + M^T) / 2`.
fn symmetrised(matrix: &DMatrix<f64>) -> DMatrix<f64> {
    (matrix + matrix.transpose()) * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::test_noise::Noise;
    use nalgebra::Schur;

    fn spectral_radius(matrix: &DMatrix<f64>) -> f64 {
        let schur = Schur::try_new(matrix.clone(), 1e-14, 10_000).unwrap();
        schur.complex_eigenvalues().iter().map(|value| value.norm()).fold(0.0, f64::max)
    }

    /// The Riccati difference equation (the time-varying filter's prior covariance) iterated a
    /// fixed number of steps from `P_0 = Q`.
    fn riccati_difference(
        a: &DMatrix<f64>,
        c: &DMatrix<f64>,
        q: &DMatrix<f64>,
        r: &DMatrix<f64>,
        steps: usize,
    ) -> DMatrix<f64> {
        let mut p = q.clone();
        for _ in 0..steps {
            let s = c * &p * c.transpose() + r;
            let m = a * &p * c.transpose();
            p = a * &p * a.transpose() - &m * s.try_inverse().unwrap() * m.transpose() + q;
            p = (&p + p.transpose()) * 0.5;
        }
        p
    }

    /// The closed-form solution of the scalar DARE: `c^2 p^2 + (r (1 - a^2) - q c^2) p - q r = 0`,
    /// positive root.
    fn scalar_solution(a: f64, c: f64, q: f64, r: f64) -> f64 {
        let linear = r * (1.0 - a * a) - q * c * c;
        (-linear + (linear * linear + 4.0 * c * c * q * r).sqrt()) / (2.0 * c * c)
    }

    #[test]
    fn scalar_case_matches_the_closed_form() {
        for (a, c, q, r) in [(0.9, 1.0, 0.01, 0.1), (1.5, 0.5, 2.0, 0.3), (0.0, 2.0, 1.0, 1.0), (-0.99, 1.0, 1e-6, 1.0)]
        {
            let one = |value: f64| DMatrix::from_element(1, 1, value);
            let solution = solve_filter_dare(&one(a), &one(c), &one(q), &one(r), &DareOptions::default()).unwrap();
            let expected = scalar_solution(a, c, q, r);
            let p = solution.p[(0, 0)];
            assert!((p - expected).abs() <= 1e-12 * expected, "a={a}: {p} vs {expected}");
            let gain = expected * c / (c * c * expected + r);
            assert!((solution.gain[(0, 0)] - gain).abs() <= 1e-12 * gain.abs().max(1e-300));
            assert!((solution.innovation_cov[(0, 0)] - (c * c * expected + r)).abs() <= 1e-12 * (c * c * expected + r));
        }
    }

    #[test]
    fn random_stable_system_satisfies_the_dare_and_matches_the_difference_iteration() {
        let mut noise = Noise(0x5eed_da7e_0000_0001);
        let (n, m) = (10, 12);
        let raw = noise.matrix(n, n);
        let a = &raw * (0.97 / spectral_radius(&raw));
        let c = noise.matrix(m, n) * 0.3;
        let root = noise.matrix(n, n) * 0.05;
        let q = &root * root.transpose() + DMatrix::identity(n, n) * 1e-4;
        let r = DMatrix::from_diagonal(&nalgebra::DVector::from_fn(m, |i, _| 0.01 * (1.0 + 0.1 * i as f64)));
        let solution = solve_filter_dare(&a, &c, &q, &r, &DareOptions::default()).unwrap();
        assert!(solution.relative_residual < 1e-10, "{}", solution.relative_residual);
        let reference = riccati_difference(&a, &c, &q, &r, 5000);
        let difference = (&solution.p - &reference).norm() / reference.norm();
        assert!(difference < 1e-9, "{difference}");
        // The predictor `a_pred' = A (I - K C) a_pred` of the steady-state filter is stable.
        let closed_loop = &a * (DMatrix::identity(n, n) - &solution.gain * &c);
        assert!(spectral_radius(&closed_loop) < 1.0);
    }

    #[test]
    fn unstable_but_detectable_system_converges_to_a_stabilising_solution() {
        let a = DMatrix::from_row_slice(3, 3, &[1.1, 0.3, 0.0, 0.0, 0.7, 0.2, 0.0, -0.2, 0.7]);
        let c = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.0, 0.0, 1.0, 1.0]);
        let q = DMatrix::identity(3, 3) * 0.01;
        let r = DMatrix::identity(2, 2) * 0.1;
        let solution = solve_filter_dare(&a, &c, &q, &r, &DareOptions::default()).unwrap();
        assert!(solution.relative_residual < 1e-10, "{}", solution.relative_residual);
        let closed_loop = &a * (DMatrix::identity(3, 3) - &solution.gain * &c);
        assert!(spectral_radius(&closed_loop) < 1.0);
        let reference = riccati_difference(&a, &c, &q, &r, 5000);
        assert!((&solution.p - &reference).norm() / reference.norm() < 1e-9);
    }

    #[test]
    fn undetectable_unstable_mode_is_an_error() {
        // The unstable mode is not observed (C sees only the second state) and is driven by Q.
        let a = DMatrix::from_row_slice(2, 2, &[1.2, 0.0, 0.0, 0.5]);
        let c = DMatrix::from_row_slice(1, 2, &[0.0, 1.0]);
        let q = DMatrix::identity(2, 2);
        let r = DMatrix::identity(1, 1);
        let error = solve_filter_dare(&a, &c, &q, &r, &DareOptions::default()).unwrap_err();
        assert!(matches!(error, DareError::Diverged { .. } | DareError::NotConverged { .. }), "{error}");
    }

    #[test]
    fn non_finite_and_malformed_inputs_are_errors() {
        let a = DMatrix::identity(2, 2) * 0.5;
        let c = DMatrix::identity(2, 2);
        let q = DMatrix::identity(2, 2);
        let r = DMatrix::identity(2, 2);
        let options = DareOptions::default();
        let mut bad = a.clone();
        bad[(1, 0)] = f64::NAN;
        assert_eq!(solve_filter_dare(&bad, &c, &q, &r, &options), Err(DareError::NonFinite("A")));
        let mut bad = q.clone();
        bad[(0, 0)] = f64::INFINITY;
        assert_eq!(solve_filter_dare(&a, &c, &bad, &r, &options), Err(DareError::NonFinite("Q")));
        let mut bad = r.clone();
        bad[(1, 1)] = f64::NAN;
        assert_eq!(solve_filter_dare(&a, &c, &q, &bad, &options), Err(DareError::NonFinite("R")));
        let singular_r = DMatrix::from_diagonal(&nalgebra::DVector::from_row_slice(&[1.0, 0.0]));
        assert_eq!(solve_filter_dare(&a, &c, &q, &singular_r, &options), Err(DareError::NoiseNotPositiveDefinite));
        let wrong = DMatrix::identity(3, 3);
        assert!(matches!(solve_filter_dare(&a, &c, &wrong, &r, &options), Err(DareError::Dimension { name: "Q", .. })));
    }

    #[test]
    fn iteration_cap_is_reported() {
        let a = DMatrix::from_element(1, 1, 0.999_999);
        let one = DMatrix::from_element(1, 1, 1.0);
        let options = DareOptions { tolerance: 1e-12, max_iterations: 2 };
        let error = solve_filter_dare(&a, &one, &one, &one, &options).unwrap_err();
        assert!(matches!(error, DareError::NotConverged { iterations: 2, .. }), "{error}");
    }
}

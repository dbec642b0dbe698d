//! The threshold (lambda) sweep: STLS at many thresholds on one QR-reduced problem, with the
//! models deduplicated by support (docs/equations.md, Sparse regression: sampling, threshold sweep,
//! excitation).

use std::collections::HashMap;

use rayon::prelude::*;

use super::error::SindyError;
use super::qr::{Normalisation, QrProblem};
use super::stls::{StlsConfig, StlsFit, System, run};

/// One distinct model of a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepPoint {
    /// The first threshold (in sweep order) that gave this support.
    pub threshold: f64,
    /// Every threshold of the sweep that gave this support, in sweep order.
    pub thresholds: Vec<f64>,
    /// Which terms are non-zero.
    pub support: Vec<bool>,
    /// Coefficients in physical units (from the fit at [`SweepPoint::threshold`]).
    pub coefficients: Vec<f64>,
    /// The number of non-zero terms.
    pub n_terms: usize,
    /// The training residual sum of squares `|y - Theta w|^2`.
    pub train_rss: f64,
    /// Whether STLS converged before `max_iter` at [`SweepPoint::threshold`].
    pub converged: bool,
}

/// The result of a sweep: the distinct models and, for every swept threshold, its model.
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep {
    /// Distinct supports, in the order they first appear along the sweep.
    pub points: Vec<SweepPoint>,
    /// The swept thresholds, in the caller's order.
    pub thresholds: Vec<f64>,
    /// For each swept threshold, the index of its point in [`Sweep::points`].
    pub point_of_threshold: Vec<usize>,
    /// The training target's root mean square (the scale of the selection's error floor).
    pub target_rms: f64,
    /// The number of training samples.
    pub n_train: usize,
}

/// `n` thresholds spaced evenly in logarithm from `min_fraction * c_max` to `c_max`, where
/// `c_max` is the largest |normalised least-squares coefficient| of the full library
/// (docs/equations.md, Sparse regression: "sweep lambda log-spaced, 1e-4...1 x max|Xi_LS| on
/// normalised columns"). Ascending.
pub fn log_thresholds(
    problem: &QrProblem,
    normalisation: Normalisation,
    n: usize,
    min_fraction: f64,
) -> Result<Vec<f64>, SindyError> {
    if n == 0 {
        return Err(SindyError::EmptyData { what: "thresholds" });
    }
    if !(min_fraction > 0.0 && min_fraction <= 1.0) {
        return Err(SindyError::InvalidConfig("min_fraction must be in (0, 1]"));
    }
    let least_squares = System::from_qr(problem, normalisation, 0.0).least_squares()?;
    let c_max = least_squares.iter().fold(0.0f64, |acc, c| acc.max(c.abs()));
    if c_max == 0.0 {
        return Err(SindyError::InvalidConfig("the least-squares coefficients are all zero"));
    }
    if n == 1 {
        return Ok(vec![c_max]);
    }
    let step = -min_fraction.ln() / (n - 1) as f64;
    Ok((0..n).map(|k| c_max * min_fraction * (step * k as f64).exp()).collect())
}

/// Runs STLS with `config` at every threshold (its `threshold` field is replaced) on the
/// QR-reduced problem, in parallel over thresholds with the results collected in order, and
/// groups the fits by support. The result does not depend on the number of threads.
pub fn sweep(problem: &QrProblem, config: &StlsConfig, thresholds: &[f64]) -> Result<Sweep, SindyError> {
    if thresholds.is_empty() {
        return Err(SindyError::EmptyData { what: "thresholds" });
    }
    config.validate()?;
    let system = System::from_qr(problem, config.normalisation, config.alpha);
    let fits: Vec<_> = thresholds
        .par_iter()
        .map(|&threshold| {
            let point_config = StlsConfig { threshold, ..*config };
            point_config.validate()?;
            run(&system, &point_config)
        })
        .collect::<Result<_, SindyError>>()?;
    let (points, point_of_threshold) = group_by_support(problem, fits, thresholds)?;
    let thresholds = thresholds.to_vec();
    Ok(Sweep { points, thresholds, point_of_threshold, target_rms: problem.target_rms(), n_train: problem.n_samples() })
}

/// Groups fits with equal supports into one point (the first fit in sweep order gives the
/// coefficients) and maps each threshold to its point.
fn group_by_support(
    problem: &QrProblem,
    fits: Vec<StlsFit>,
    thresholds: &[f64],
) -> Result<(Vec<SweepPoint>, Vec<usize>), SindyError> {
    let mut points: Vec<SweepPoint> = Vec::new();
    let mut index_of: HashMap<Vec<bool>, usize> = HashMap::new();
    let mut point_of_threshold = Vec::with_capacity(fits.len());
    for (fit, &threshold) in fits.into_iter().zip(thresholds) {
        let index = match index_of.get(&fit.support) {
            Some(&index) => index,
            None => {
                index_of.insert(fit.support.clone(), points.len());
                points.push(SweepPoint {
                    threshold,
                    thresholds: Vec::new(),
                    train_rss: problem.rss(&fit.coefficients)?,
                    n_terms: fit.n_terms(),
                    support: fit.support,
                    coefficients: fit.coefficients,
                    converged: fit.converged,
                });
                points.len() - 1
            }
        };
        points[index].thresholds.push(threshold);
        point_of_threshold.push(index);
    }
    Ok((points, point_of_threshold))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::library::Library;
    use crate::stls::stls;
    use crate::testdata::static_regression;

    fn problem() -> QrProblem {
        let (samples, y) = static_regression(2000, 0.05, 3);
        let theta = Library::polynomial(&["x0", "x1"], 3, true).unwrap().theta(&samples).unwrap();
        QrProblem::new(&theta, &y).unwrap()
    }

    #[test]
    fn sweep_points_are_distinct_stls_fits_and_do_not_depend_on_threads() {
        let problem = problem();
        let config = StlsConfig::default();
        let thresholds = log_thresholds(&problem, config.normalisation, 40, 1e-4).unwrap();
        assert_eq!(thresholds.len(), 40);
        assert!(thresholds.windows(2).all(|pair| pair[0] < pair[1]));
        let parallel = sweep(&problem, &config, &thresholds).unwrap();
        let single = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| sweep(&problem, &config, &thresholds).unwrap());
        assert_eq!(parallel, single);
        assert!(parallel.points.len() > 2 && parallel.points.len() < 40, "{}", parallel.points.len());
        for (threshold, &index) in thresholds.iter().zip(&parallel.point_of_threshold) {
            let fit = stls(&problem, &StlsConfig { threshold: *threshold, ..config }).unwrap();
            assert_eq!(fit.support, parallel.points[index].support);
        }
        for (idx, point) in parallel.points.iter().enumerate() {
            assert!(parallel.points[..idx].iter().all(|other| other.support != point.support));
            assert_eq!(point.threshold, point.thresholds[0]);
            assert!((point.train_rss - problem.rss(&point.coefficients).unwrap()).abs() <= 1e-12 * point.train_rss);
        }
        let last = parallel.points.last().unwrap();
        assert!(last.n_terms <= 1, "the largest threshold keeps at most the largest term");
    }

    #[test]
    fn sweep_rejects_bad_input() {
        let problem = problem();
        let config = StlsConfig::default();
        assert!(matches!(sweep(&problem, &config, &[]), Err(SindyError::EmptyData { .. })));
        assert!(matches!(sweep(&problem, &config, &[0.1, -1.0]), Err(SindyError::InvalidConfig(_))));
        assert!(log_thresholds(&problem, config.normalisation, 5, 0.0).is_err());
    }
}

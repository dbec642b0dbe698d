//! What the balance reads besides the aerodynamics (G1, G2): the wing's inertial reaction to
//! the roll acceleration and the weight moment of a centre of gravity off the roll axis, when
//! the tares were not subtracted (docs/diagnosis.md, Inertial and gravity tares).

use firmware_sim::effect::Effect;

use super::{BalanceCandidate, Context, Params, Shape, gains, log_grid, lowpass2};
use crate::diagnose::streams::RunStreams;

/// Standard gravity, m/s^2.
const G_MPS2: f64 = 9.806_65;

/// `inertial_tare`: `-I phi_ddot / (q S b)` left in the balance, with one inertia or one per run
/// (a model remounted between runs), seen directly or through the balance's own second-order
/// low-pass (corner 5 Hz to 0.35 of the sample rate).
#[derive(Debug, Clone, Copy)]
pub struct InertialTare;

/// `gravity_tare`: `m g d sin(phi + phase) / (q S b)` (the weight moment about the roll axis,
/// with the offset it leaves at `phi = 0`), one size or one per angle of attack (a centre of
/// gravity whose arm about the roll axis turns with the pitch, e.g. with cos alpha).
#[derive(Debug, Clone, Copy)]
pub struct GravityTare;

impl BalanceCandidate for InertialTare {
    fn regressors(&self) -> &'static str {
        "the roll acceleration over q S b (an inertia left in the balance)"
    }

    fn effect(&self) -> Option<Effect> {
        Some(Effect::InertialTare)
    }

    fn separating_experiment(&self) -> &'static str {
        "wind-off runs with the same roll motion (the inertial reaction stays, the aerodynamics vanish)"
    }

    fn shapes(&self, sample_hz: f64, _context: &Context<'_>) -> Vec<Shape> {
        let corners = log_grid(TARE_CORNER_LOW_HZ, (0.35 * sample_hz).min(TARE_CORNER_HIGH_HZ), TARE_CORNERS);
        [false, true]
            .into_iter()
            .flat_map(|per_run| {
                std::iter::once(Shape::Tare { per_run, corner_hz: None }).chain(
                    corners
                        .clone()
                        .into_iter()
                        .map(move |corner_hz| Shape::Tare { per_run, corner_hz: Some(corner_hz) }),
                )
            })
            .collect()
    }

    fn columns(&self, shape: &Shape, run: &RunStreams, run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>> {
        let Shape::Tare { per_run, corner_hz } = *shape else { return Vec::new() };
        let seen = match corner_hz {
            Some(corner_hz) => lowpass2(&run.phi_ddot_rad_s2, corner_hz, 1.0 / run.sample_hz),
            None => run.phi_ddot_rad_s2.clone(),
        };
        if !per_run {
            return vec![seen];
        }
        // One column per run, zero in the other runs.
        let mut out = vec![vec![0.0; run.len()]; context.n_runs];
        out[run_idx] = seen;
        out
    }

    /// With one inertia per run, the median of the runs that roll (the others have no
    /// acceleration and a zero gain), and its spread.
    fn params(&self, shape: &Shape, beta: &[f64], context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        // Balance = aero - I phi_ddot: the column's coefficient is -I / (q S b).
        let inertia: Vec<f64> = beta.iter().map(|b| -b * context.moment_scale_nm).collect();
        let mut out = match shape {
            Shape::Tare { per_run: true, .. } => {
                let mut rolling: Vec<f64> = inertia.iter().copied().filter(|i| *i != 0.0).collect();
                rolling.sort_by(f64::total_cmp);
                let median = rolling.get(rolling.len() / 2).copied().unwrap_or(0.0);
                let spread = rolling.last().copied().unwrap_or(0.0) - rolling.first().copied().unwrap_or(0.0);
                vec![("ixx_kgm2".to_owned(), median), ("ixx_spread_kgm2".to_owned(), spread)]
            }
            _ => gains(&["ixx_kgm2"], &inertia),
        };
        if let Shape::Tare { corner_hz: Some(corner_hz), .. } = shape {
            out.push(("balance_corner_hz".to_owned(), *corner_hz));
        }
        out
    }
}

/// The balance low-pass corners the inertial tare may be seen through, Hz: from 5 Hz (a balance
/// filtered just above a slow motion) to 200 Hz, capped at 0.35 of the sample rate.
const TARE_CORNER_LOW_HZ: f64 = 5.0;
const TARE_CORNER_HIGH_HZ: f64 = 200.0;
const TARE_CORNERS: usize = 10;

impl BalanceCandidate for GravityTare {
    fn regressors(&self) -> &'static str {
        "sin(phi) and cos(phi) - 1 over q S b (a centre of gravity off the axis both ways)"
    }

    fn effect(&self) -> Option<Effect> {
        Some(Effect::GravityTare)
    }

    fn separating_experiment(&self) -> &'static str {
        "wind-off runs at held roll angles (the weight moment stays) or a second free-stream speed"
    }

    fn schedulable(&self) -> bool {
        true
    }

    fn shapes(&self, _sample_hz: f64, _context: &Context<'_>) -> Vec<Shape> {
        vec![Shape::Fixed]
    }

    fn columns(&self, _shape: &Shape, run: &RunStreams, _run_idx: usize, _context: &Context<'_>) -> Vec<Vec<f64>> {
        vec![run.phi_rad.iter().map(|phi| phi.sin()).collect(), run.phi_rad.iter().map(|phi| phi.cos()).collect()]
    }

    fn params(&self, _shape: &Shape, beta: &[f64], context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        // m g d sin(phi + p) = m g d cos p sin(phi) + m g d sin p cos(phi).
        let (b0, b1) = (beta.first().copied().unwrap_or(0.0), beta.get(1).copied().unwrap_or(0.0));
        let moment_nm = context.moment_scale_nm * b0.hypot(b1);
        vec![
            ("weight_moment_nm".into(), moment_nm),
            ("mass_offset_kgm".into(), moment_nm / G_MPS2),
            ("phase_deg".into(), b1.atan2(b0).to_degrees()),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::candidates::{test_context, test_fit};
    use crate::diagnose::streams::synthetic_run;

    /// A balance that keeps `-I phi_ddot` gives back `I`: the column is the roll acceleration
    /// and the coefficient's sign and scale are undone (`q S b` = 2 N m in the test context).
    #[test]
    fn inertial_tare_recovers_the_inertia() {
        let context = test_context();
        let ixx_kgm2 = 3.0e-4;
        let mut run = synthetic_run(1000.0, vec![vec![0.0; 2000]], vec![vec![0.0; 2000]]);
        run.phi_ddot_rad_s2 = (0..2000).map(|i| 40.0 * (i as f64 * 0.013).sin()).collect();
        let residual: Vec<f64> = run.phi_ddot_rad_s2.iter().map(|a| -ixx_kgm2 * a / context.moment_scale_nm).collect();
        let shape = Shape::Tare { per_run: false, corner_hz: None };
        let columns = InertialTare.columns(&shape, &run, 0, &context);
        let beta = test_fit(&columns, &residual);
        let params = InertialTare.params(&shape, &beta, &context, &[columns]);
        assert_eq!(params[0].0, "ixx_kgm2");
        assert!((params[0].1 / ixx_kgm2 - 1.0).abs() < 1e-9, "{params:?}");
    }

    /// A weight moment `m g d sin(phi + 30 deg)` gives back `m g d`, `m d` and the 30 deg
    /// phase from the sine and cosine columns.
    #[test]
    fn gravity_tare_recovers_moment_offset_and_phase() {
        let context = test_context();
        let (moment_nm, phase) = (0.12, 30f64.to_radians());
        let mut run = synthetic_run(1000.0, vec![vec![0.0; 3000]], vec![vec![0.0; 3000]]);
        run.phi_rad = (0..3000).map(|i| 0.6 * (i as f64 * 0.004).sin()).collect();
        let residual: Vec<f64> =
            run.phi_rad.iter().map(|phi| moment_nm * (phi + phase).sin() / context.moment_scale_nm).collect();
        let columns = GravityTare.columns(&Shape::Fixed, &run, 0, &context);
        let beta = test_fit(&columns, &residual);
        let params = GravityTare.params(&Shape::Fixed, &beta, &context, &[columns]);
        let get = |name: &str| params.iter().find(|(n, _)| n == name).map(|(_, v)| *v).unwrap();
        assert!((get("weight_moment_nm") - moment_nm).abs() < 1e-9);
        assert!((get("mass_offset_kgm") - moment_nm / 9.806_65).abs() < 1e-9);
        assert!((get("phase_deg") - 30.0).abs() < 1e-6);
    }

    /// A tare seen through the balance's 20 Hz low-pass with a different inertia per run is
    /// found in the per-run low-pass form, with each run's inertia, and fits better than the
    /// direct form of one inertia.
    #[test]
    fn inertial_tare_through_the_balance_filter_per_run_is_recovered() {
        let context = test_context();
        let n = 3000;
        let runs: Vec<RunStreams> = (0..2)
            .map(|k| {
                let mut run = synthetic_run(1000.0, vec![vec![0.0; n]], vec![vec![0.0; n]]);
                run.phi_ddot_rad_s2 = (0..n)
                    .map(|i| 40.0 * (i as f64 * 0.013 + k as f64).sin() + 9.0 * (i as f64 * 0.05).sin())
                    .collect();
                run
            })
            .collect();
        let inertia = [3.0e-4, 4.0e-4];
        let truth: Vec<f64> = runs
            .iter()
            .zip(inertia)
            .flat_map(|(run, ixx)| lowpass2(&run.phi_ddot_rad_s2, 20.0, 1e-3).into_iter().map(move |a| -ixx * a / 2.0))
            .collect();
        let fit = |shape: &Shape| {
            let per_run: Vec<Vec<Vec<f64>>> =
                runs.iter().enumerate().map(|(k, run)| InertialTare.columns(shape, run, k, &context)).collect();
            let columns: Vec<Vec<f64>> =
                (0..per_run[0].len()).map(|c| per_run.iter().flat_map(|cols| cols[c].clone()).collect()).collect();
            let beta = test_fit(&columns, &truth);
            let sse: f64 = (0..truth.len())
                .map(|i| (truth[i] - columns.iter().zip(&beta).map(|(c, b)| c[i] * b).sum::<f64>()).powi(2))
                .sum();
            (sse, beta)
        };
        let filtered = Shape::Tare { per_run: true, corner_hz: Some(20.0) };
        let (sse, beta) = fit(&filtered);
        let (direct_sse, _) = fit(&Shape::Tare { per_run: false, corner_hz: None });
        assert!(sse < 1e-6 * direct_sse, "{sse} vs {direct_sse}");
        let params = InertialTare.params(&filtered, &beta, &context, &[]);
        assert_eq!(params[0].0, "ixx_kgm2");
        assert!((params[1].1 - 1.0e-4).abs() < 1e-9, "{params:?}");
        assert_eq!(params[2], ("balance_corner_hz".to_owned(), 20.0));
    }
}

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
/// with the offset it leaves at `phi = 0`), the same at every angle of attack, or turned by the
/// pitch as a centre of gravity fixed in the wing is: the part in `sin(phi)` (the offset normal
/// to the wing) `a cos(alpha) + b sin(alpha)`, the part in `cos(phi)` (the offset along the
/// span) `c + d cos(alpha)`, whether the wing rolls about its own axis or the wind's
/// (docs/diagnosis.md, Inertial and gravity tares, derives both).
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

    /// One inertia per run only where every run that rolls has an inertia of one sign: a wing
    /// remounted between runs changes how much of its inertia the balance reads, not the sign
    /// of its reaction to the roll acceleration (docs/spec/diagnosis.md, What each name covers:
    /// a gain constant or changing per mounting). Gains of both signs are per-run columns
    /// spanning the sim's own error at the roll acceleration's time scale: on a clean recording
    /// of the second tunnel they fitted -6.5e-6 kg m^2 in the median, spread 7.2e-5.
    fn admits(&self, shape: &Shape, beta: &[f64]) -> bool {
        let Shape::Tare { per_run: true, .. } = *shape else { return true };
        rolling(beta).all(|gain| gain > 0.0) || rolling(beta).all(|gain| gain < 0.0)
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
                let mut rolling: Vec<f64> = rolling(&inertia).collect();
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

/// The per-run gains of the runs that roll: a run without roll acceleration has a zero column
/// and a zero gain.
fn rolling(gains: &[f64]) -> impl Iterator<Item = f64> + '_ {
    gains.iter().copied().filter(|gain| *gain != 0.0)
}

/// The balance low-pass corners the inertial tare may be seen through, Hz: from 5 Hz (a balance
/// filtered just above a slow motion) to 200 Hz, capped at 0.35 of the sample rate.
const TARE_CORNER_LOW_HZ: f64 = 5.0;
const TARE_CORNER_HIGH_HZ: f64 = 200.0;
const TARE_CORNERS: usize = 10;

impl BalanceCandidate for GravityTare {
    fn regressors(&self) -> &'static str {
        "sin(phi) and cos(phi) over q S b (a centre of gravity off the axis both ways), the same at every angle of attack or each times cos(alpha) and sin(alpha) (the arm turned by the pitch)"
    }

    fn effect(&self) -> Option<Effect> {
        Some(Effect::GravityTare)
    }

    fn separating_experiment(&self) -> &'static str {
        "wind-off runs at held roll angles (the weight moment stays) or a second free-stream speed"
    }

    /// The pitched form only with two angles of attack or more: at one, `cos(alpha)` and
    /// `sin(alpha)` are one column.
    fn shapes(&self, _sample_hz: f64, context: &Context<'_>) -> Vec<Shape> {
        let mut shapes = vec![Shape::Weight { pitched: false }];
        if context.alphas_deg.len() >= 2 {
            shapes.push(Shape::Weight { pitched: true });
        }
        shapes
    }

    fn columns(&self, shape: &Shape, run: &RunStreams, _run_idx: usize, _context: &Context<'_>) -> Vec<Vec<f64>> {
        let sin_phi: Vec<f64> = run.phi_rad.iter().map(|phi| phi.sin()).collect();
        let cos_phi: Vec<f64> = run.phi_rad.iter().map(|phi| phi.cos()).collect();
        if !matches!(shape, Shape::Weight { pitched: true }) {
            return vec![sin_phi, cos_phi];
        }
        let (sin_alpha, cos_alpha) = run.alpha_deg.to_radians().sin_cos();
        let scaled = |column: &[f64], by: f64| column.iter().map(|v| v * by).collect::<Vec<f64>>();
        vec![scaled(&sin_phi, cos_alpha), scaled(&cos_phi, cos_alpha), scaled(&sin_phi, sin_alpha), cos_phi]
    }

    /// The weight moment, mass offset and phase; in the pitched form, at each angle of attack of
    /// the recording (`weight_moment_nm@12.2`).
    fn params(&self, shape: &Shape, beta: &[f64], context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        let coefficient = |idx: usize| beta.get(idx).copied().unwrap_or(0.0);
        // m g d sin(phi + p) = m g d cos p sin(phi) + m g d sin p cos(phi).
        let weight = |b0: f64, b1: f64, suffix: &str| {
            let moment_nm = context.moment_scale_nm * b0.hypot(b1);
            vec![
                (format!("weight_moment_nm{suffix}"), moment_nm),
                (format!("mass_offset_kgm{suffix}"), moment_nm / G_MPS2),
                (format!("phase_deg{suffix}"), b1.atan2(b0).to_degrees()),
            ]
        };
        if !matches!(shape, Shape::Weight { pitched: true }) {
            return weight(coefficient(0), coefficient(1), "");
        }
        context
            .alphas_deg
            .iter()
            .flat_map(|alpha_deg| {
                let (sin_alpha, cos_alpha) = alpha_deg.to_radians().sin_cos();
                weight(
                    coefficient(0) * cos_alpha + coefficient(2) * sin_alpha,
                    coefficient(1) * cos_alpha + coefficient(3),
                    &format!("@{alpha_deg}"),
                )
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::candidates::{test_context, test_fit, test_fit_runs, test_left};
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
        let shape = Shape::Weight { pitched: false };
        let columns = GravityTare.columns(&shape, &run, 0, &context);
        let beta = test_fit(&columns, &residual);
        let params = GravityTare.params(&shape, &beta, &context, &[columns]);
        let get = |name: &str| params.iter().find(|(n, _)| n == name).map(|(_, v)| *v).unwrap();
        assert!((get("weight_moment_nm") - moment_nm).abs() < 1e-9);
        assert!((get("mass_offset_kgm") - moment_nm / 9.806_65).abs() < 1e-9);
        assert!((get("phase_deg") - 30.0).abs() < 1e-6);
    }

    /// Three runs at 3, 12 and 18 deg rolling alike, each moment from `at_alpha`, and the
    /// pitched form's columns and fit of every run together: `(runs' alphas, beta, residual
    /// variance over the target's)`.
    fn pitched_fit(at_alpha: impl Fn(f64, f64) -> f64) -> (Vec<f64>, Vec<f64>, f64) {
        let mut context = test_context();
        context.alphas_deg = vec![3.0, 12.0, 18.0];
        let shape = Shape::Weight { pitched: true };
        let (mut columns, mut target) = (vec![Vec::new(); 4], Vec::new());
        for &alpha_deg in &context.alphas_deg {
            let mut run = synthetic_run(1000.0, vec![vec![0.0; 3000]], vec![vec![0.0; 3000]]);
            run.alpha_deg = alpha_deg;
            run.phi_rad = (0..3000).map(|i| 0.6 * (i as f64 * 0.004).sin()).collect();
            for (all, column) in columns.iter_mut().zip(GravityTare.columns(&shape, &run, 0, &context)) {
                all.extend(column);
            }
            target.extend(run.phi_rad.iter().map(|phi| at_alpha(*phi, alpha_deg)));
        }
        let beta = test_fit(&columns, &target);
        let left = test_left(&columns, &beta, &target);
        let total: f64 = target.iter().map(|v| v * v).sum();
        (context.alphas_deg, beta, left / total)
    }

    /// A wing rolled about the wind's axis, its centre of gravity ahead of the axis on the
    /// wing's chord, above it and to one side: the offset normal to the wing turns with the
    /// pitch (`0.05 cos(alpha) + 0.4 sin(alpha)`), the one along the span does not (0.1). The
    /// pitched form spans it and gives each angle's moment and phase back.
    #[test]
    fn gravity_tare_pitched_form_recovers_an_arm_that_turns_with_the_pitch() {
        let normal = |alpha_deg: f64| 0.05 * alpha_deg.to_radians().cos() + 0.4 * alpha_deg.to_radians().sin();
        let truth = |phi: f64, alpha_deg: f64| (normal(alpha_deg) * phi.sin() + 0.1 * phi.cos()) / 2.0;
        let (alphas_deg, beta, left) = pitched_fit(truth);
        assert!(left < 1e-12, "{left}");
        let mut context = test_context();
        context.alphas_deg = alphas_deg;
        let params = GravityTare.params(&Shape::Weight { pitched: true }, &beta, &context, &[]);
        let get = |name: &str| params.iter().find(|(n, _)| n == name).map(|(_, v)| *v).unwrap();
        for alpha_deg in [3.0, 12.0, 18.0] {
            let moment_nm = normal(alpha_deg).hypot(0.1);
            assert!((get(&format!("weight_moment_nm@{alpha_deg}")) - moment_nm).abs() < 1e-9);
            let phase_deg = 0.1f64.atan2(normal(alpha_deg)).to_degrees();
            assert!((get(&format!("phase_deg@{alpha_deg}")) - phase_deg).abs() < 1e-6);
        }
    }

    /// A moment at one angle of attack alone is no weight: a centre of gravity fixed in the wing
    /// weighs at every pitch, so the pitched form leaves most of it.
    #[test]
    fn gravity_tare_pitched_form_does_not_span_a_moment_at_one_angle_only() {
        let (_, _, left) = pitched_fit(|phi, alpha_deg| if alpha_deg == 12.0 { phi.sin() } else { 0.0 });
        assert!(left > 0.3, "{left}");
    }

    /// Inertias of one sign per run are a remounted wing's tare, with or without runs that do
    /// not roll (zero gain); inertias of both signs are no tare. One inertia for every run is
    /// a tare of either sign.
    #[test]
    fn per_run_inertias_are_a_tare_only_with_one_sign() {
        let per_run = Shape::Tare { per_run: true, corner_hz: Some(20.0) };
        assert!(InertialTare.admits(&per_run, &[-1.0e-4, 0.0, -3.0e-4]));
        assert!(InertialTare.admits(&per_run, &[2.0e-4, 0.5e-4]));
        assert!(!InertialTare.admits(&per_run, &[2.0e-4, 0.0, -0.1e-4]));
        assert!(InertialTare.admits(&Shape::Tare { per_run: false, corner_hz: None }, &[-2.0e-4]));
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
            test_fit_runs(&per_run, &truth)
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

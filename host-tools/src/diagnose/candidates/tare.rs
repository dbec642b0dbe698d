//! What the balance reads besides the aerodynamics (G1, G2): the wing's inertial reaction to
//! the roll acceleration and the weight moment of a centre of gravity off the roll axis, when
//! the tares were not subtracted (docs/diagnosis.md, Inertial and gravity tares).

use firmware_sim::effect::Effect;

use super::{BalanceCandidate, Context, Params, Shape, gains};
use crate::diagnose::streams::RunStreams;

/// Standard gravity, m/s^2.
const G_MPS2: f64 = 9.806_65;

/// `inertial_tare`: `-I phi_ddot / (q S b)` left in the balance.
#[derive(Debug, Clone, Copy)]
pub struct InertialTare;

/// `gravity_tare`: `m g d sin(phi + phase) / (q S b)` (the weight moment about the roll axis,
/// with the offset it leaves at `phi = 0`).
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

    fn shapes(&self, _sample_hz: f64, _context: &Context<'_>) -> Vec<Shape> {
        vec![Shape::Fixed]
    }

    fn columns(&self, _shape: &Shape, run: &RunStreams, _run_idx: usize, _context: &Context<'_>) -> Vec<Vec<f64>> {
        vec![run.phi_ddot_rad_s2.clone()]
    }

    fn params(&self, _shape: &Shape, beta: &[f64], context: &Context<'_>, _columns: &[Vec<Vec<f64>>]) -> Params {
        // Balance = aero - I phi_ddot: the column's coefficient is -I / (q S b).
        gains(&["ixx_kgm2"], &beta.iter().map(|b| -b * context.moment_scale_nm).collect::<Vec<_>>())
    }
}

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
        let columns = InertialTare.columns(&Shape::Fixed, &run, 0, &context);
        let beta = test_fit(&columns, &residual);
        let params = InertialTare.params(&Shape::Fixed, &beta, &context, &[columns]);
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
}

//! The pressure path's table in f64 and the core's filter run on it: what the fit tunes and
//! scores, the evaluation replays and the diagnosis reads its innovations from.

use estimator_core::coeffs::{CoefficientSet, N_ALPHA, N_PRESSURE_INPUTS, N_TAPS, PRESSURE_RANK, PressureModel};
use estimator_core::health::Health;
use estimator_core::pressure::PressureFilter;
use estimator_core::schedule::{SchedulePosition, position_in};
use nalgebra::DMatrix;

use super::*;

/// The pressure path in f64: the core's table ([`PressureModel<f64>`], run by the core's own
/// filter in f64) and the alpha breakpoints of its map to `C_l` (the set's first `n_alpha`).
#[derive(Debug, Clone, PartialEq)]
pub struct PressureTable {
    /// The core's table in f64: entries past the rank are exactly zero.
    pub model: PressureModel<f64>,
    /// Breakpoints of the map to `C_l`, deg, ascending (at least one; at most [`N_ALPHA`]).
    pub breakpoints_deg: Vec<f64>,
}

impl PressureTable {
    /// A coefficient set's pressure path in f64 (exact).
    #[must_use]
    pub fn from_set(set: &CoefficientSet) -> Self {
        let n = usize::from(set.n_alpha).clamp(1, N_ALPHA);
        Self {
            model: set.pressure.cast(),
            breakpoints_deg: set.alpha_schedule_deg[..n].iter().map(|&deg| f64::from(deg)).collect(),
        }
    }

    /// Number of modes `r`.
    #[must_use]
    pub fn rank(&self) -> usize {
        usize::from(self.model.rank).min(PRESSURE_RANK)
    }

    /// `A`, `C` and `K` at the model's rank, for the fit's matrix algebra.
    pub(super) fn matrices(&self) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
        let (rank, m) = (self.rank(), &self.model);
        (
            DMatrix::from_fn(rank, rank, |row, col| m.a[row][col]),
            DMatrix::from_fn(N_TAPS, rank, |tap, mode| m.c[tap][mode]),
            DMatrix::from_fn(rank, N_TAPS, |mode, tap| m.gain[mode][tap]),
        )
    }

    /// Where `alpha_deg` lies in the map's schedule (`estimator_core::schedule`).
    #[must_use]
    pub fn position(&self, alpha_deg: f64) -> SchedulePosition<f64> {
        position_in(&self.breakpoints_deg, alpha_deg)
    }

    /// The core's f32 table.
    ///
    /// # Errors
    ///
    /// [`PressureFitError::NonFinite`] when a value is not finite in f32.
    pub fn to_core(&self) -> Result<PressureModel, PressureFitError> {
        let model: PressureModel = self.model.cast();
        core_is_finite(&model).then_some(model).ok_or(PressureFitError::NonFinite("pressure model in f32"))
    }
}

/// Every f32 of a pressure table is finite.
pub(super) fn core_is_finite(model: &PressureModel) -> bool {
    let scalars = [model.gate_sigma];
    model
        .a
        .as_flattened()
        .iter()
        .chain(model.b.as_flattened())
        .chain(model.c.as_flattened())
        .chain(&model.cp_mean)
        .chain(model.gain.as_flattened())
        .chain(&model.innovation_std)
        .chain(model.cl_weights.as_flattened())
        .chain(&model.cl_offset)
        .chain(&scalars)
        .all(|value| value.is_finite())
}

/// The inputs the core would see: a non-finite input holds its last finite value (zero before
/// the first), as `estimator_core::estimator` holds missing measurements.
#[derive(Debug, Clone, Copy)]
pub(super) struct HeldInputs([f64; N_PRESSURE_INPUTS]);

impl Default for HeldInputs {
    fn default() -> Self {
        Self([0.0, 0.0, 0.0, 0.0, 1.0])
    }
}

impl HeldInputs {
    pub(super) fn hold(&mut self, inputs: [f64; N_PRESSURE_INPUTS]) -> [f64; N_PRESSURE_INPUTS] {
        for (held, value) in self.0.iter_mut().zip(inputs) {
            if value.is_finite() {
                *held = value;
            }
        }
        self.0
    }
}

/// Result of one step of the core's pressure filter in f64, with what the fit scores.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PressureStep {
    /// `C_l,p` of the filtered pressures at the step's alpha.
    pub cl: f64,
    /// True when at least one channel corrected the prediction.
    pub measured: bool,
    /// One-step prediction `C (A a + B u) + cp_mean` of every tap.
    pub predicted_cp: [f64; N_TAPS],
    /// Filtered pressures `C a + cp_mean` after the update.
    pub filtered_cp: [f64; N_TAPS],
}

/// One step of the core's pressure filter (`estimator_core::pressure`) in f64 on `table`, the
/// map to `C_l` at `alpha_deg`.
pub fn filter_step(
    filter: &mut PressureFilter<f64>,
    table: &PressureTable,
    inputs: &[f64; N_PRESSURE_INPUTS],
    cp: &[f64; N_TAPS],
    alpha_deg: f64,
) -> PressureStep {
    let mut predicted_cp = [f64::NAN; N_TAPS];
    let estimate =
        filter.step_observed(&table.model, table.position(alpha_deg), inputs, cp, &mut Health::default(), |expected| {
            predicted_cp = *expected
        });
    PressureStep {
        cl: estimate.cl,
        measured: estimate.measured,
        predicted_cp,
        filtered_cp: filter.filtered_cp(&table.model),
    }
}

/// Runs the core's filter in f64 over a run from rest and returns `C_l,p` of every sample (the held-out
/// evaluation of the pressure path: pass the whole run and score the held-out part, so the
/// filter has settled when it starts). Non-finite inputs hold their last finite value.
///
/// # Errors
///
/// [`PressureFitError::LengthMismatch`] when the run's channels differ in length.
pub fn run_pressure_filter(table: &PressureTable, run: &PressureRun<'_>) -> Result<Vec<f64>, PressureFitError> {
    run.check(0)?;
    let mut filter = PressureFilter::at_start(&table.model);
    let mut inputs = HeldInputs::default();
    Ok((0..run.len())
        .map(|k| filter_step(&mut filter, table, &inputs.hold(run.inputs(k)), &run.cp_at(k), run.alpha_deg[k]).cl)
        .collect())
}

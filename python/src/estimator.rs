//! `Estimator`: estimator-core's f32 estimator in a Python object, stepped one sample at a time
//! (`step`) or over whole arrays (`run`, without the GIL and without a Python loop per sample),
//! exactly as `host-tools replay` steps it: the step on the recorded input, then the recorded
//! demand noted (`model_fit::replay::replay_step`).

use std::sync::Arc;

use estimator_core::coeffs::N_TAPS;
use estimator_core::{CoefficientSet, Input, Output};
use model_fit::replay::{ESTIMATE_COLUMNS, HEALTH_COLUMNS, health_at};
use numpy::{PyArray1, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::model::Model;

/// Steps of `run` between two checks for a pending signal (Ctrl-C): about 15 ms of stepping, so
/// an interrupt is prompt and the checks (each takes the GIL) cost nothing measurable.
const SIGNAL_CHECK_STEPS: usize = 1 << 16;

/// The estimator over a borrowed set, as the self-referential pair needs it named.
type Borrowing<'a> = estimator_core::Estimator<'a>;

self_cell::self_cell!(
    /// A coefficient set and the estimator that borrows it, owned together.
    struct Owned {
        owner: Arc<CoefficientSet>,
        #[covariant]
        dependent: Borrowing,
    }
);

/// Every stage's outputs of a run as arrays by the replay file's names: the estimates as float32
/// (the estimator's precision), the health fields as uint16.
pub(crate) fn outputs_dict<'py>(py: Python<'py>, outputs: &[Output]) -> PyResult<Bound<'py, PyDict>> {
    let columns = PyDict::new(py);
    for (idx, name) in ESTIMATE_COLUMNS.iter().enumerate() {
        let values: Vec<f32> = outputs.iter().map(|output| output.estimates()[idx]).collect();
        columns.set_item(*name, PyArray1::from_vec(py, values))?;
    }
    for (idx, name) in HEALTH_COLUMNS.iter().enumerate() {
        let values: Vec<u16> = outputs.iter().map(|output| health_at(output)[idx]).collect();
        columns.set_item(*name, PyArray1::from_vec(py, values))?;
    }
    Ok(columns)
}

/// The estimator (the Python package's `Estimator` wraps it).
#[pyclass(module = "rollest._rollest")]
pub struct Estimator {
    owned: Owned,
}

/// A contiguous array's values, or a `ValueError` naming the argument.
fn values<'a>(array: &'a PyReadonlyArray1<'_, f64>, name: &str) -> PyResult<&'a [f64]> {
    array.as_slice().map_err(|_| PyValueError::new_err(format!("{name}: expected a contiguous float64 array")))
}

#[pymethods]
impl Estimator {
    /// A fresh estimator over `model`'s tables (the built-in tables when None).
    #[new]
    #[pyo3(signature = (model = None))]
    fn new(model: Option<&Model>) -> Self {
        let set = model.map_or_else(|| Arc::new(estimator_core::coeffs::DEFAULT), |model| Arc::clone(&model.set));
        Self { owned: Owned::new(set, |set| estimator_core::Estimator::new(set)) }
    }

    /// The fixed step, s.
    #[getter]
    fn dt_s(&self) -> f32 {
        self.owned.borrow_owner().dt_s
    }

    /// Back to the state of a fresh estimator.
    fn reset(&mut self) {
        self.owned.with_dependent_mut(|_, estimator| estimator.reset());
    }

    /// Notes the controller's demand after a step (a missing Cmu is then predicted from it).
    fn note_demand(&mut self, cmu_port: f64, cmu_stbd: f64) {
        self.owned.with_dependent_mut(|_, estimator| estimator.note_demand([cmu_port as f32, cmu_stbd as f32]));
    }

    /// One step; then, when given, the demand `(port, stbd)` is noted. Returns the estimates
    /// and health fields by the replay file's names.
    #[pyo3(signature = (phi_deg, alpha_deg, cmu_port, cmu_stbd, cp, demand = None))]
    #[allow(clippy::too_many_arguments)] // One sample's channels, by name, as the Python call reads.
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        phi_deg: f64,
        alpha_deg: f64,
        cmu_port: f64,
        cmu_stbd: f64,
        cp: Vec<f64>,
        demand: Option<(f64, f64)>,
    ) -> PyResult<Bound<'py, PyDict>> {
        if cp.len() != N_TAPS {
            return Err(PyValueError::new_err(format!("cp: expected {N_TAPS} values, found {}", cp.len())));
        }
        let input = Input {
            phi_deg: phi_deg as f32,
            alpha_deg: alpha_deg as f32,
            cmu_port: cmu_port as f32,
            cmu_stbd: cmu_stbd as f32,
            cp: core::array::from_fn(|tap| cp[tap] as f32),
        };
        let output = self.owned.with_dependent_mut(|_, estimator| {
            let output = estimator.step(&input);
            if let Some((port, stbd)) = demand {
                estimator.note_demand([port as f32, stbd as f32]);
            }
            output
        });
        let result = PyDict::new(py);
        for (name, value) in ESTIMATE_COLUMNS.iter().zip(output.estimates()) {
            result.set_item(*name, value)?;
        }
        for (name, value) in HEALTH_COLUMNS.iter().zip(health_at(&output)) {
            result.set_item(*name, value)?;
        }
        Ok(result)
    }

    /// Steps over whole arrays (`cp` of shape `(n, 12)`), continuing from the present state,
    /// without the GIL; a signal (Ctrl-C) stops it between chunks of steps and is raised. A
    /// recorded demand (either command array) is noted after each step, the other jet's command
    /// 0 when only one is given.
    #[pyo3(signature = (phi_deg, alpha_deg, cmu_port, cmu_stbd, cp, cmu_port_cmd = None, cmu_stbd_cmd = None))]
    #[allow(clippy::too_many_arguments)] // The run's channels, by name, as the Python call reads.
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        phi_deg: PyReadonlyArray1<'py, f64>,
        alpha_deg: PyReadonlyArray1<'py, f64>,
        cmu_port: PyReadonlyArray1<'py, f64>,
        cmu_stbd: PyReadonlyArray1<'py, f64>,
        cp: PyReadonlyArray2<'py, f64>,
        cmu_port_cmd: Option<PyReadonlyArray1<'py, f64>>,
        cmu_stbd_cmd: Option<PyReadonlyArray1<'py, f64>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let phi = values(&phi_deg, "phi_deg")?;
        let n = phi.len();
        let same = |array: &[f64], name: &str| {
            if array.len() == n {
                Ok(())
            } else {
                Err(PyValueError::new_err(format!("{name}: expected {n} samples like phi_deg, found {}", array.len())))
            }
        };
        let (alpha, port, stbd) =
            (values(&alpha_deg, "alpha_deg")?, values(&cmu_port, "cmu_port")?, values(&cmu_stbd, "cmu_stbd")?);
        same(alpha, "alpha_deg")?;
        same(port, "cmu_port")?;
        same(stbd, "cmu_stbd")?;
        if cp.shape() != [n, N_TAPS] {
            return Err(PyValueError::new_err(format!("cp: expected shape ({n}, {N_TAPS}), found {:?}", cp.shape())));
        }
        let cp = cp.as_slice().map_err(|_| PyValueError::new_err("cp: expected a C-contiguous float64 array"))?;
        let port_cmd = cmu_port_cmd.as_ref().map(|array| values(array, "cmu_port_cmd")).transpose()?;
        let stbd_cmd = cmu_stbd_cmd.as_ref().map(|array| values(array, "cmu_stbd_cmd")).transpose()?;
        for (array, name) in [(port_cmd, "cmu_port_cmd"), (stbd_cmd, "cmu_stbd_cmd")] {
            if let Some(array) = array {
                same(array, name)?;
            }
        }
        let mut outputs = Vec::with_capacity(n);
        for start in (0..n).step_by(SIGNAL_CHECK_STEPS) {
            let end = n.min(start + SIGNAL_CHECK_STEPS);
            let (owned, outputs) = (&mut self.owned, &mut outputs);
            py.detach(move || {
                owned.with_dependent_mut(|_, estimator| {
                    outputs.extend((start..end).map(|k| {
                        let input = Input {
                            phi_deg: phi[k] as f32,
                            alpha_deg: alpha[k] as f32,
                            cmu_port: port[k] as f32,
                            cmu_stbd: stbd[k] as f32,
                            cp: core::array::from_fn(|tap| cp[k * N_TAPS + tap] as f32),
                        };
                        let output = estimator.step(&input);
                        if port_cmd.is_some() || stbd_cmd.is_some() {
                            let command = |array: Option<&[f64]>| array.map_or(0.0, |array| array[k] as f32);
                            estimator.note_demand([command(port_cmd), command(stbd_cmd)]);
                        }
                        output
                    }));
                });
            });
            // Ctrl-C in a notebook stops a long run here (the estimator has stepped to `end`).
            py.check_signals()?;
        }
        outputs_dict(py, &outputs)
    }
}

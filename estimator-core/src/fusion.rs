//! Fusion of the eGK and pressure-path estimates into `C_l,roll` by a scalar steady-state
//! Kalman filter on the eGK's error (domain-models.md section 4, design B, a complementary
//! filter): `e[k] = rho e[k-1] + w`, observed as `C_l,p - C_l,eGK = e + v`, and
//! `C_l,roll = C_l,eGK + e_hat`. The eGK carries the fast content and the pressure path the
//! trend and bias, as the paper's conclusion describes.

use crate::coeffs::FusionParams;

/// Largest eGK error the fusion accepts before it resets (10 times any physical C_l).
const ERROR_LIMIT: f32 = 10.0;

/// The fusion filter's state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Fusion {
    error: f32,
}

impl Fusion {
    /// No error estimated yet.
    #[must_use]
    pub const fn new() -> Self {
        Self { error: 0.0 }
    }

    /// One step. `cl_pressure` is `None` when the pressure path measured nothing this step; the
    /// error estimate then only decays. Returns `C_l,roll` and whether the state was reset.
    pub fn step(&mut self, params: &FusionParams, cl_egk: f32, cl_pressure: Option<f32>) -> (f32, bool) {
        let predicted = params.rho * self.error;
        self.error = match cl_pressure {
            Some(cl_pressure) => predicted + params.gain * ((cl_pressure - cl_egk) - predicted),
            None => predicted,
        };
        let reset = !crate::bounded(self.error, ERROR_LIMIT);
        if reset {
            self.error = 0.0;
        }
        (cl_egk + self.error, reset)
    }
}

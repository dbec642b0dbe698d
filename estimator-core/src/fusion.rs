//! Fusion of the eGK and pressure-path estimates into `C_l,roll` by a scalar steady-state
//! Kalman filter on the eGK's error (docs/equations.md, Fusion and Fusion design: a
//! complementary filter): `e[k] = rho e[k-1] + w`, observed as `C_l,p - C_l,eGK = e + v`, and
//! `C_l,roll = C_l,eGK + e_hat`. The eGK carries the fast content and the pressure path the
//! trend and bias, as the paper's conclusion describes.

use crate::coeffs::FusionParams;
use crate::real::Real;

/// Largest eGK error the fusion accepts before it resets (10 times any physical C_l).
const ERROR_LIMIT: f32 = 10.0;

/// The fusion filter's state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Fusion<R = f32> {
    error: R,
}

impl<R: Real> Fusion<R> {
    /// No error estimated yet.
    #[must_use]
    pub const fn new() -> Self {
        Self { error: R::ZERO }
    }

    /// One step. `cl_pressure` is `None` when the pressure path measured nothing this step; the
    /// error estimate then only decays. Returns `C_l,roll` and whether the state was reset.
    pub fn step(&mut self, params: &FusionParams<R>, cl_egk: R, cl_pressure: Option<R>) -> (R, bool) {
        let predicted = params.rho * self.error;
        self.error = match cl_pressure {
            Some(cl_pressure) => predicted + params.gain * ((cl_pressure - cl_egk) - predicted),
            None => predicted,
        };
        let reset = !crate::bounded(self.error, R::from_f32(ERROR_LIMIT));
        if reset {
            self.error = R::ZERO;
        }
        (cl_egk + self.error, reset)
    }
}

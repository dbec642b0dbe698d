//! The coupling operator of the paper's eqs. 8-10: the correction of the linear superposition,
//! `C_l = C_l,roll + C_l,AFC + Xi Theta(C_l,roll, C_l,AFC, alpha, Cmu, dCmu, phi)`, whose terms
//! are gated by anti-Dirac indicators so that it vanishes without blowing or without roll
//! (paper eq. 11 and its admissibility rules).

use crate::coeffs::{MAX_VARS, coupling_var};
use crate::real::Real;
use crate::sparse::{Interpreted, ModelId, SparseEval, SparseModel};

/// Inputs of the coupling operator, in the scalar `R` (f32 on the target; f64 in the host's
/// fit, whose regressors are these variables).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CouplingInput<R = f32> {
    /// Disturbance-model roll moment.
    pub cl_roll: R,
    /// Plant-model roll moment (both jets).
    pub cl_afc: R,
    /// Angle of attack, rad.
    pub alpha_rad: R,
    /// Total momentum coefficient (port + starboard).
    pub cmu: R,
    /// Its increment over the step.
    pub dcmu: R,
    /// Roll angle, rad.
    pub phi_rad: R,
    /// Roll rate, rad/s.
    pub phi_dot_rad_s: R,
}

impl<R: Real> CouplingInput<R> {
    /// The variable vector in the order of [`coupling_var`].
    #[must_use]
    pub fn variables(&self) -> [R; MAX_VARS] {
        let mut vars = [R::ZERO; MAX_VARS];
        vars[coupling_var::CL_ROLL] = self.cl_roll;
        vars[coupling_var::CL_AFC] = self.cl_afc;
        vars[coupling_var::ALPHA] = self.alpha_rad;
        vars[coupling_var::CMU] = self.cmu;
        vars[coupling_var::DCMU] = self.dcmu;
        vars[coupling_var::PHI] = self.phi_rad;
        vars[coupling_var::PHI_DOT] = self.phi_dot_rad_s;
        vars
    }
}

/// The correction `Xi Theta(...)`; zero when it is not finite (flagged by the caller).
#[must_use]
pub fn correction(model: &SparseModel, input: &CouplingInput) -> Option<f32> {
    correction_with(Interpreted, model, input)
}

/// [`correction`] with the model evaluated by `eval` (as the set's coupling model).
#[must_use]
pub fn correction_with<E: SparseEval>(eval: E, model: &SparseModel, input: &CouplingInput) -> Option<f32> {
    let value = eval.eval(ModelId::Coupling, model, &input.variables());
    value.is_finite().then_some(value)
}

//! The plant model of one blowing jet: the SINDy difference equation of the paper's eq. 5,
//! `C_l,AFC[k+1] = Xi Theta(C_l,AFC[k], Cmu[k], dCmu[k], alpha[k], C_l,slow[k])`, with
//! `dCmu[k] = Cmu[k] - Cmu[k-1]` and the slow state
//! `C_l,slow[k+1] = p C_l,slow[k] + (1 - p) C_l,AFC[k]` ([`PlantParams`]).

use crate::coeffs::{MAX_VARS, PlantParams, plant_var};
use crate::sparse::{Interpreted, ModelId, SparseEval};

/// Largest magnitude of the plant's moment before it is treated as diverged (100 times the
/// authority of a trailing-edge jet).
const CL_LIMIT: f32 = 1.0;

/// One jet's plant state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Plant {
    cl: f32,
    slow: f32,
    last_cmu: f32,
}

impl Plant {
    /// No blowing, no moment.
    #[must_use]
    pub const fn new() -> Self {
        Self { cl: 0.0, slow: 0.0, last_cmu: 0.0 }
    }

    /// The moment of this step, `C_l,AFC[k]`.
    #[must_use]
    pub const fn cl(&self) -> f32 {
        self.cl
    }

    /// The previous step's Cmu.
    #[must_use]
    pub const fn last_cmu(&self) -> f32 {
        self.last_cmu
    }

    /// The plant's variables for a candidate Cmu at this step.
    #[must_use]
    pub fn variables(&self, cmu: f32, alpha_rad: f32) -> [f32; MAX_VARS] {
        let mut vars = [0.0; MAX_VARS];
        vars[plant_var::CL_AFC] = self.cl;
        vars[plant_var::CMU] = cmu;
        vars[plant_var::DCMU] = cmu - self.last_cmu;
        vars[plant_var::ALPHA] = alpha_rad;
        vars[plant_var::CL_SLOW] = self.slow;
        vars
    }

    /// Returns `C_l,AFC[k]` and advances to `k + 1` with this step's Cmu; the second value is
    /// true when the state diverged and was reset.
    pub fn step(&mut self, params: &PlantParams, cmu: f32, alpha_rad: f32) -> (f32, bool) {
        // `Interpreted` reads `params` whatever the id says.
        self.step_with(Interpreted, ModelId::PlantPort, params, cmu, alpha_rad)
    }

    /// [`Plant::step`] with the model evaluated by `eval` as the set's model `id`.
    pub fn step_with<E: SparseEval>(
        &mut self,
        eval: E,
        id: ModelId,
        params: &PlantParams,
        cmu: f32,
        alpha_rad: f32,
    ) -> (f32, bool) {
        let current = self.cl;
        // maxNum and minNum, not `clamp`: with any tables (a NaN or negative bound) they cannot
        // panic.
        let cmu = crate::min_num(crate::max_num(cmu, 0.0), params.cmu_max);
        let next = eval.eval(id, &params.model, &self.variables(cmu, alpha_rad));
        let slow = params.slow_pole * self.slow + (1.0 - params.slow_pole) * current;
        let reset = !(crate::bounded(next, CL_LIMIT) && crate::bounded(slow, CL_LIMIT));
        (self.cl, self.slow) = if reset { (0.0, 0.0) } else { (next, slow) };
        self.last_cmu = cmu;
        (current, reset)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::prior::PRIOR;

    #[test]
    fn first_order_prior_settles_to_its_gain_one_step_late() {
        let mut plant = Plant::new();
        let (first, _) = plant.step(&PRIOR.plant[0], 0.009, 0.0);
        assert_eq!(first, 0.0, "eq. 5: Cmu[k] acts on C_l,AFC[k+1]");
        let mut last = 0.0;
        for _ in 0..3000 {
            last = plant.step(&PRIOR.plant[0], 0.009, 0.0).0;
        }
        assert!((last - 0.01).abs() < 1e-6, "{last}");
    }

    #[test]
    fn divergent_model_is_reset_not_propagated() {
        let mut model = PRIOR.plant[0];
        model.model.terms[0].coeff = 3.0;
        let mut plant = Plant::new();
        let mut reset_seen = false;
        for _ in 0..100 {
            let (cl, reset) = plant.step(&model, 0.009, 0.0);
            assert!(cl.is_finite() && cl.abs() <= CL_LIMIT);
            reset_seen |= reset;
        }
        assert!(reset_seen);
    }
}

//! The plant model of one blowing jet: the SINDy difference equation of the paper's eq. 5,
//! `C_l,AFC[k+1] = Xi Theta(C_l,AFC[k], Cmu[k], dCmu[k], alpha[k], C_l,slow[k])`, with
//! `dCmu[k] = Cmu[k] - Cmu[k-1]` and the slow state
//! `C_l,slow[k+1] = p C_l,slow[k] + (1 - p) C_l,AFC[k]` ([`PlantParams`]).

use crate::coeffs::{MAX_VARS, PlantParams, plant_var};
use crate::real::Real;
use crate::sparse::{Interpreted, ModelId, SparseEval};

/// Largest magnitude of the plant's moment before it is treated as diverged (100 times the
/// authority of a trailing-edge jet).
const CL_LIMIT: f32 = 1.0;

/// One jet's plant state, in the scalar `R` (f32 on the target; f64 in the host's fit, which
/// runs its candidate models through [`Plant::step_by`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Plant<R = f32> {
    cl: R,
    slow: R,
    last_cmu: R,
}

impl<R: Real> Plant<R> {
    /// No blowing, no moment.
    #[must_use]
    pub const fn new() -> Self {
        Self { cl: R::ZERO, slow: R::ZERO, last_cmu: R::ZERO }
    }

    /// The moment of this step, `C_l,AFC[k]`.
    #[must_use]
    pub const fn cl(&self) -> R {
        self.cl
    }

    /// The previous step's Cmu.
    #[must_use]
    pub const fn last_cmu(&self) -> R {
        self.last_cmu
    }

    /// The plant's variables for a candidate Cmu at this step.
    #[must_use]
    pub fn variables(&self, cmu: R, alpha_rad: R) -> [R; MAX_VARS] {
        let mut vars = [R::ZERO; MAX_VARS];
        vars[plant_var::CL_AFC] = self.cl;
        vars[plant_var::CMU] = cmu;
        vars[plant_var::DCMU] = cmu - self.last_cmu;
        vars[plant_var::ALPHA] = alpha_rad;
        vars[plant_var::CL_SLOW] = self.slow;
        vars
    }

    /// The variables of step `k` with the moment set to a measured `C_l,AFC[k]` (teacher
    /// forcing, as the fit's regressors are built: Brunton et al. 2016, the paper's eq. 5),
    /// then advances the slow state and the last Cmu as [`Plant::step_by`] does.
    pub fn forced_variables(
        &mut self,
        slow_pole: R,
        cmu_max: R,
        cmu: R,
        alpha_rad: R,
        cl_measured: R,
    ) -> [R; MAX_VARS] {
        self.cl = cl_measured;
        let cmu = crate::min_num(crate::max_num(cmu, R::ZERO), cmu_max);
        let vars = self.variables(cmu, alpha_rad);
        self.slow = slow_pole * self.slow + (R::ONE - slow_pole) * cl_measured;
        self.last_cmu = cmu;
        vars
    }

    /// Returns `C_l,AFC[k]` and advances to `k + 1` with this step's Cmu, the next moment
    /// given by `model` of the plant's variables: the Cmu limited to `[0, cmu_max]`, the slow
    /// state with `slow_pole`, and a reset when either state leaves +-1 (the second value).
    pub fn step_by(
        &mut self,
        slow_pole: R,
        cmu_max: R,
        cmu: R,
        alpha_rad: R,
        model: impl FnOnce(&[R; MAX_VARS]) -> R,
    ) -> (R, bool) {
        let current = self.cl;
        // maxNum and minNum, not `clamp`: with any tables (a NaN or negative bound) they cannot
        // panic.
        let cmu = crate::min_num(crate::max_num(cmu, R::ZERO), cmu_max);
        let next = model(&self.variables(cmu, alpha_rad));
        let slow = slow_pole * self.slow + (R::ONE - slow_pole) * current;
        let limit = R::from_f32(CL_LIMIT);
        let reset = !(crate::bounded(next, limit) && crate::bounded(slow, limit));
        (self.cl, self.slow) = if reset { (R::ZERO, R::ZERO) } else { (next, slow) };
        self.last_cmu = cmu;
        (current, reset)
    }
}

impl Plant {
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
        self.step_by(params.slow_pole, params.cmu_max, cmu, alpha_rad, |vars| eval.eval(id, &params.model, vars))
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
    fn forced_variables_are_the_free_runs_when_forced_with_its_own_moment() {
        let params = PRIOR.plant[0];
        let (mut free, mut forced) = (Plant::<f64>::new(), Plant::<f64>::new());
        let model = |vars: &[f64; MAX_VARS]| 0.99 * vars[plant_var::CL_AFC] + 0.01 * vars[plant_var::CMU];
        for k in 0..200 {
            // Starts blowing at the first sample, and steps beyond the Cmu range.
            let cmu = [0.004, 0.02, -0.001][k % 3];
            let alpha_rad = 0.01 * k as f64;
            let mut seen = [f64::NAN; MAX_VARS];
            let cl = free.cl();
            free.step_by(0.9, f64::from(params.cmu_max), cmu, alpha_rad, |vars| {
                seen = *vars;
                model(vars)
            });
            let vars = forced.forced_variables(0.9, f64::from(params.cmu_max), cmu, alpha_rad, cl);
            assert_eq!(vars, seen, "step {k}");
        }
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

//! The built-in coefficient set with its sparse models compiled to code.
//!
//! Interpreting a sparse model walks its table: per term a coefficient, three factor indices
//! and a gate mask are loaded, about 20 instructions on the Cortex-M4F. `host-tools codegen`
//! also writes each model of [`DEFAULT`] as a function of straight-line code with the
//! coefficients as literals, about 4 instructions per term. The generated functions
//! follow [`SparseModel::eval`] operation by operation, so they give the same bits; the
//! firmware-against-host replay test checks that on a whole run.

use super::{CoefficientSet, DEFAULT, MAX_VARS, generated};
use crate::sparse::{ModelId, SparseEval, SparseModel};

/// The built-in set at one address, so that [`CompiledDefault`] can tell its models from any
/// other set's.
pub static BUILT_IN: CoefficientSet = DEFAULT;

/// Evaluates the sparse models of [`BUILT_IN`] with the generated code, and any other model
/// from its tables: a model is compiled only when it is the built-in set's model `id` itself
/// (compared by address), so passing another set by mistake still gives that set's values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CompiledDefault {
    _private: (),
}

impl CompiledDefault {
    /// The evaluator (the estimator's [`crate::Estimator::built_in`] holds one).
    pub const NEW: Self = Self { _private: () };
}

impl SparseEval for CompiledDefault {
    #[inline]
    fn eval(self, id: ModelId, model: &SparseModel, vars: &[f32; MAX_VARS]) -> f32 {
        let (built_in, compiled): (&SparseModel, fn(&[f32; MAX_VARS]) -> f32) = match id {
            ModelId::PlantPort => (&BUILT_IN.plant[0].model, generated::plant_port),
            ModelId::PlantStarboard => (&BUILT_IN.plant[1].model, generated::plant_starboard),
            ModelId::Coupling => (&BUILT_IN.coupling, generated::coupling),
        };
        if core::ptr::eq(model, built_in) { compiled(vars) } else { model.eval(vars) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sparse::Interpreted;

    /// Deterministic variable vectors over several orders of magnitude and both signs, with
    /// zeros, so that every gate is both open and shut.
    fn samples() -> impl Iterator<Item = [f32; MAX_VARS]> {
        let mut state = 0x2545_f491_u32;
        (0..20_000).map(move |_| {
            core::array::from_fn(|_| {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                let mantissa = (state >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0;
                let scale = [0.0, 1e-5, 1e-3, 1e-2, 0.3, 1.0][(state % 6) as usize];
                mantissa * scale
            })
        })
    }

    #[test]
    fn compiled_models_give_the_interpreted_bits() {
        let models = [
            (ModelId::PlantPort, &BUILT_IN.plant[0].model),
            (ModelId::PlantStarboard, &BUILT_IN.plant[1].model),
            (ModelId::Coupling, &BUILT_IN.coupling),
        ];
        for (id, model) in models {
            for vars in samples() {
                let compiled = CompiledDefault::NEW.eval(id, model, &vars);
                let interpreted = Interpreted.eval(id, model, &vars);
                assert_eq!(compiled.to_bits(), interpreted.to_bits(), "{id:?} at {vars:?}");
            }
        }
    }

    #[test]
    fn another_sets_model_is_interpreted() {
        let mut other = DEFAULT.plant[0].model;
        other.terms[0].coeff *= 2.0;
        let vars = [0.01, 0.005, 0.001, 0.2, 0.003, 0.0, 0.0];
        let value = CompiledDefault::NEW.eval(ModelId::PlantPort, &other, &vars);
        assert_eq!(value.to_bits(), other.eval(&vars).to_bits());
        assert_ne!(value, BUILT_IN.plant[0].model.eval(&vars));
    }
}

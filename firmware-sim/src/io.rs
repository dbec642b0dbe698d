//! The firmware's I/O behind small traits in the embedded-hal style (`no_std`), and the fixed-rate
//! loop step that reads the inputs, steps the estimator and the controller, and writes the
//! blowing demand.
//!
//! embedded-hal 1.0 has no ADC trait, so the 12-channel pressure front end has its own. The loop
//! is generic over the traits: the firmware binds them to the board (or, in QEMU, to a replay file
//! read through semihosting), the host tests bind them to fakes.

use estimator_core::coeffs::CompiledDefault;
use estimator_core::coeffs::N_TAPS;
use estimator_core::controller::{Blocks, Controller, ControllerInput, Demand};
use estimator_core::sparse::{Interpreted, SparseEval};
use estimator_core::{CoefficientSet, Estimator, Health, Input, Output};

/// The 12-channel pressure front end: one conversion of every tap per step.
pub trait PressureFrontEnd {
    /// The pressure coefficients `cp01`..`cp12` (NaN for a channel not converted this step).
    fn read(&mut self) -> [f32; N_TAPS];
}

/// The roll-angle encoder of the rig.
pub trait RollEncoder {
    /// Roll angle, deg (positive starboard wing down; NaN when not read).
    fn angle_deg(&mut self) -> f32;
}

/// The angle of attack (fixed per run in the tunnel, but read like any other input).
pub trait AlphaSource {
    /// Angle of attack, deg.
    fn alpha_deg(&mut self) -> f32;
}

/// The measured momentum coefficients of the two jets.
pub trait BlowingMeasurement {
    /// `[port, starboard]` Cmu (NaN when not measured).
    fn cmu(&mut self) -> [f32; 2];
}

/// The blowing valves: the controller's Cmu demand.
pub trait BlowingOutput {
    /// Sets the `[port, starboard]` Cmu demand.
    fn set_cmu(&mut self, cmu: [f32; 2]);
}

/// A free-running tick counter for timing the step (SysTick on the target).
pub trait TickCounter {
    /// The current count (any origin).
    fn now(&mut self) -> u32;
    /// Ticks from `start` to `end`, two readings of [`TickCounter::now`] (handles the wrap).
    fn elapsed(&self, start: u32, end: u32) -> u32;
}

/// Everything one step reads and writes.
pub trait Board: PressureFrontEnd + RollEncoder + AlphaSource + BlowingMeasurement + BlowingOutput {}

impl<T: PressureFrontEnd + RollEncoder + AlphaSource + BlowingMeasurement + BlowingOutput> Board for T {}

/// A board whose sensors read one recorded or received sample ([`Input`]) and whose valves keep
/// the last demand: the serial link's rig, a file replay, the host's reference of the loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InputBoard {
    /// The sample the sensors read.
    pub input: Input,
    /// The last `[port, starboard]` Cmu demand written.
    pub demand: [f32; 2],
}

impl InputBoard {
    /// Reading `input`, no demand yet (NaN).
    #[must_use]
    pub const fn new(input: Input) -> Self {
        Self { input, demand: [f32::NAN; 2] }
    }
}

impl PressureFrontEnd for InputBoard {
    fn read(&mut self) -> [f32; N_TAPS] {
        self.input.cp
    }
}

impl RollEncoder for InputBoard {
    fn angle_deg(&mut self) -> f32 {
        self.input.phi_deg
    }
}

impl AlphaSource for InputBoard {
    fn alpha_deg(&mut self) -> f32 {
        self.input.alpha_deg
    }
}

impl BlowingMeasurement for InputBoard {
    fn cmu(&mut self) -> [f32; 2] {
        [self.input.cmu_port, self.input.cmu_stbd]
    }
}

impl BlowingOutput for InputBoard {
    fn set_cmu(&mut self, cmu: [f32; 2]) {
        self.demand = cmu;
    }
}

/// What one loop step produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepResult {
    /// The estimator's output (its health bits are the estimator's alone).
    pub output: Output,
    /// The demand written to the valves.
    pub demand: Demand,
    /// Flags the controller set this step.
    pub controller_health: Health,
    /// Ticks of `Estimator::step` alone.
    pub ticks_estimator: u32,
    /// Ticks of the estimator and the controller.
    pub ticks_total: u32,
}

/// The fixed-rate loop's state: the estimator, the controller and which blocks are on. Its
/// constructors are `const`, so it can live in a `static` on the target.
#[derive(Debug, Clone)]
pub struct FixedRateLoop<'a, E: SparseEval = Interpreted> {
    estimator: Estimator<'a, E>,
    controller: Controller,
    blocks: Blocks,
}

impl<'a> FixedRateLoop<'a> {
    /// At rest, with the tables of `set`.
    #[must_use]
    pub const fn new(set: &'a CoefficientSet, blocks: Blocks) -> Self {
        Self { estimator: Estimator::new(set), controller: Controller::new(), blocks }
    }
}

impl FixedRateLoop<'static, CompiledDefault> {
    /// At rest, with the built-in tables and their sparse models compiled to code
    /// ([`Estimator::built_in`]): what the firmware flies.
    #[must_use]
    pub const fn built_in(blocks: Blocks) -> Self {
        Self { estimator: Estimator::built_in(), controller: Controller::new(), blocks }
    }
}

impl<'a, E: SparseEval> FixedRateLoop<'a, E> {
    /// The estimator (for its coefficients and state).
    #[must_use]
    pub const fn estimator(&self) -> &Estimator<'a, E> {
        &self.estimator
    }

    /// One step: reads the inputs through `board`, steps the estimator and the controller, notes
    /// the demand with the estimator ([`Estimator::note_demand`]: a missing Cmu measurement is
    /// then predicted from it) and writes it to the valves. The controller cancels the fused
    /// disturbance `C_l,roll`; the feedback has no balance on the board, so its measurement is
    /// NaN (held) when feedback is on.
    pub fn step<B: Board, T: TickCounter>(&mut self, board: &mut B, ticks: &mut T) -> StepResult {
        let cp = board.read();
        let phi_deg = board.angle_deg();
        let alpha_deg = board.alpha_deg();
        let [cmu_port, cmu_stbd] = board.cmu();
        let input = Input { phi_deg, alpha_deg, cmu_port, cmu_stbd, cp };
        let start = ticks.now();
        let output = self.estimator.step(&input);
        let after_estimator = ticks.now();
        let mut controller_health = Health::default();
        let controller_input = ControllerInput {
            disturbance_cl: output.cl_roll,
            measured_cl: f32::NAN,
            alpha_rad: alpha_deg * (core::f32::consts::PI / 180.0),
        };
        let (eval, set, plants) = (self.estimator.evaluator(), self.estimator.coefficients(), self.estimator.plants());
        let demand =
            self.controller.step_with(eval, set, plants, &controller_input, self.blocks, &mut controller_health);
        // The estimator predicts a missing Cmu measurement from what the valves are told.
        self.estimator.note_demand(demand.cmu);
        let end = ticks.now();
        board.set_cmu(demand.cmu);
        StepResult {
            output,
            demand,
            controller_health,
            ticks_estimator: ticks.elapsed(start, after_estimator),
            ticks_total: ticks.elapsed(start, end),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Replays fixed inputs and records the demands.
    struct FakeBoard {
        phi_deg: f32,
        demands: [[f32; 2]; 4],
        n_demands: usize,
    }

    impl PressureFrontEnd for FakeBoard {
        fn read(&mut self) -> [f32; N_TAPS] {
            [-0.5; N_TAPS]
        }
    }
    impl RollEncoder for FakeBoard {
        fn angle_deg(&mut self) -> f32 {
            self.phi_deg += 1.0;
            self.phi_deg
        }
    }
    impl AlphaSource for FakeBoard {
        fn alpha_deg(&mut self) -> f32 {
            20.0
        }
    }
    impl BlowingMeasurement for FakeBoard {
        fn cmu(&mut self) -> [f32; 2] {
            [0.0, f32::NAN]
        }
    }
    impl BlowingOutput for FakeBoard {
        fn set_cmu(&mut self, cmu: [f32; 2]) {
            self.demands[self.n_demands] = cmu;
            self.n_demands += 1;
        }
    }

    /// Counts up by 10 per reading.
    struct FakeTicks(u32);

    impl TickCounter for FakeTicks {
        fn now(&mut self) -> u32 {
            self.0 = self.0.wrapping_add(10);
            self.0
        }
        fn elapsed(&self, start: u32, end: u32) -> u32 {
            end.wrapping_sub(start)
        }
    }

    #[test]
    fn the_loop_steps_the_same_estimator_as_a_direct_call() {
        let set = &estimator_core::coeffs::DEFAULT;
        let blocks = Blocks { feedforward: true, feedback: false };
        let mut fixed_rate = FixedRateLoop::new(set, blocks);
        let mut board = FakeBoard { phi_deg: 0.0, demands: [[0.0; 2]; 4], n_demands: 0 };
        let mut ticks = FakeTicks(u32::MAX - 15);
        let mut reference = Estimator::new(set);
        for k in 0..4 {
            let result = fixed_rate.step(&mut board, &mut ticks);
            let input = Input {
                phi_deg: (k + 1) as f32,
                alpha_deg: 20.0,
                cmu_port: 0.0,
                cmu_stbd: f32::NAN,
                cp: [-0.5; N_TAPS],
            };
            let expected = reference.step(&input);
            assert_eq!(result.output, expected);
            // The starboard Cmu is missing: from the second step on it is predicted from the
            // demand the loop noted.
            assert_eq!(result.output.health.has(Health::CMU_FROM_DEMAND), k > 0);
            reference.note_demand(result.demand.cmu);
            assert_eq!(board.demands[k], result.demand.cmu);
            assert!(result.demand.cmu.iter().all(|cmu| cmu.is_finite()));
            assert_eq!((result.ticks_estimator, result.ticks_total), (10, 20));
        }
        assert_eq!(board.n_demands, 4);
    }
}

//! The synthetic wind tunnel stepped one sample at a time, for closed loops (the SIL harness).
//!
//! [`TunnelSim`] runs the same [`RunState`] and model code as [`super::simulate_run`]; only the
//! blowing command is not known in advance: the caller gives it sample by sample through
//! [`TunnelSim::advance`], and it is logged as a [`HoldSequence`] (a switch at each sample
//! where it changes) that the integrator reads exactly as it reads a precomputed sequence. The
//! valve's dead time therefore still applies (the integrator reads the log `valve_delay_s`
//! back). An open-loop run whose blowing switches only at sample times gives the same channels
//! as `simulate_run`, bit for bit, provided the dead time is at least one sample (else a
//! precomputed sequence would be read ahead of the caller's command).

use super::excitation::HoldSequence;
use super::model::Model;
use super::{Inputs, NoiseDraws, RunState, TunnelConfig, model_of};
use crate::dataset::N_TAPS;

/// The measured channels of one sample, and the true aerodynamic moment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Time, s.
    pub t_s: f64,
    /// Roll angle from the encoder (quantised), deg.
    pub phi_deg: f64,
    /// Measured Cmu, port and starboard.
    pub cmu: [f64; 2],
    /// Pressure coefficients of the 12 taps (NaN for a dead channel).
    pub cp: [f64; N_TAPS],
    /// Roll moment from the balance (noise, quantisation and balance effects included).
    pub cl: f64,
    /// The noise-free aerodynamic roll moment (disturbance and jets), the truth a metric wants.
    pub cl_aero: f64,
}

/// The synthetic tunnel as a stepped plant: [`TunnelSim::sample`] reads the channels at the
/// current time, [`TunnelSim::advance`] holds the valve commands over the next sample.
#[derive(Debug, Clone)]
pub struct TunnelSim {
    model: Model,
    run: RunState,
    sample_hz: f64,
    roll_cmd_deg: HoldSequence,
    blowing_cmd: [HoldSequence; 2],
    sample_idx: usize,
    /// The current sample, once read (its noise is drawn once).
    current: Option<Sample>,
}

impl TunnelSim {
    /// A run at rest at `alpha_deg`, sampled at `sample_hz`, with the roll command sequence and
    /// the seed of its noise.
    #[must_use]
    pub fn new(
        config: &TunnelConfig,
        alpha_deg: f64,
        sample_hz: f64,
        roll_cmd_deg: HoldSequence,
        noise_seed: u64,
    ) -> Self {
        let model = model_of(config, alpha_deg);
        let run = RunState::new(&model, alpha_deg, sample_hz, noise_seed, &config.aero, 0);
        Self {
            model,
            run,
            sample_hz,
            roll_cmd_deg,
            blowing_cmd: [HoldSequence::zero(), HoldSequence::zero()],
            sample_idx: 0,
            current: None,
        }
    }

    /// Time of the current sample, s.
    #[must_use]
    pub fn time_s(&self) -> f64 {
        self.sample_idx as f64 / self.sample_hz
    }

    /// Index of the current sample.
    #[must_use]
    pub fn sample_index(&self) -> usize {
        self.sample_idx
    }

    /// The roll command at the current time, deg.
    #[must_use]
    pub fn roll_cmd_deg(&self) -> f64 {
        self.roll_cmd_deg.value_at(self.time_s())
    }

    /// The blowing commands given so far, as sequences (port, starboard).
    #[must_use]
    pub fn blowing_log(&self) -> &[HoldSequence; 2] {
        &self.blowing_cmd
    }

    /// The measured channels at the current time (the same sample until [`TunnelSim::advance`]).
    pub fn sample(&mut self) -> Sample {
        if let Some(sample) = self.current {
            return sample;
        }
        let t_s = self.time_s();
        let draws = NoiseDraws::next(&mut self.run.rng);
        self.run.advance_processes(&self.model, &draws, self.sample_hz);
        let inputs =
            Inputs { roll_cmd_deg: &self.roll_cmd_deg, blowing_cmd: &self.blowing_cmd, sample_hz: self.sample_hz };
        let sample = self.run.record(&self.model, &inputs, t_s, &draws);
        self.current = Some(sample);
        sample
    }

    /// Holds the valve commands `cmu_cmd` (port, starboard; non-finite or negative reads as 0)
    /// from the current sample to the next, integrates over it, and moves to the next sample.
    pub fn advance(&mut self, cmu_cmd: [f64; 2]) {
        if self.current.is_none() {
            // The noise of a sample is drawn when it is read; keep the order when it was not.
            let _ = self.sample();
        }
        let t_s = self.time_s();
        for (log, command) in self.blowing_cmd.iter_mut().zip(cmu_cmd) {
            log.hold_from(t_s, if command.is_finite() { command.max(0.0) } else { 0.0 });
        }
        let inputs =
            Inputs { roll_cmd_deg: &self.roll_cmd_deg, blowing_cmd: &self.blowing_cmd, sample_hz: self.sample_hz };
        self.run.integrate_sample(&self.model, &inputs, t_s);
        self.sample_idx += 1;
        self.current = None;
    }
}

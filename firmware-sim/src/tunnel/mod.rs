//! The synthetic wind tunnel: a physical model of the paper's rolling UCAS wing in the IIT
//! Fejer tunnel (section II: c = 330 mm, b = 287 mm, S = 0.0474 m^2, I_xx = 3.12e-4 kg m^2,
//! U = 6.5 m/s) that stands in for the experiment, since no tunnel data exist.
//!
//! It is deliberately richer than the estimator's model families, so that no fit is trivially
//! exact:
//! - body-axis roll with sideslip `beta = asin(sin alpha sin phi)`, driven by a roll servo;
//! - one Goman-Khrabrov vortex state per half-wing with its own effective incidence;
//! - sideslip stiffness, roll damping and acceleration terms, and buffet;
//! - blowing actuators with valve dead time and lag, a circulation rise with overshoot,
//!   square-root effectiveness in Cmu, an alpha-dependent gain, and a physical interaction with
//!   the roll disturbance (blowing raises the blown side's incidence, and the jet loses
//!   effectiveness when that side's vortex breaks down), which grows with alpha;
//! - 12 pressure taps with tubing dynamics and noise, a noisy balance whose inertial tare is
//!   subtracted (as a careful experimenter does with a wind-off run of the same motion), and a
//!   quantised roll encoder.
//!
//! Every effect of the diagnosis vocabulary can be switched on ([`effects`]). Runs are seeded
//! and deterministic: the noise of a run is drawn in a fixed order whatever effects are on, so
//! switching an effect changes only the channels it physically reaches.

pub mod effects;
pub mod excitation;
mod model;
pub mod params;
mod stepping;
pub mod taps;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::dataset::{Channels, N_TAPS, RunKind, Tunnel, Wing};
use effects::{Effects, FaultMode, PressureFault};
use excitation::HoldSequence;
use model::{Drive, Model, ModelConfig, State, idx};
use params::{ActuatorParams, AeroParams, RigParams, SensorParams};
pub use stepping::{Sample, TunnelSim};

/// Standard gravity, m/s^2.
const GRAVITY_MPS2: f64 = 9.80665;

/// The physical tunnel: conditions, wing, parameters and effects.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TunnelConfig {
    /// Free-stream conditions.
    pub tunnel: TunnelConditions,
    /// Wing geometry and inertia.
    pub wing: Wing,
    /// Disturbance aerodynamics.
    pub aero: AeroParams,
    /// Blowing actuators.
    pub actuator: ActuatorParams,
    /// Sensors.
    pub sensors: SensorParams,
    /// Roll rig.
    pub rig: RigParams,
    /// Switched-on effects.
    pub effects: Effects,
}

/// Free-stream conditions with the paper's defaults (6.5 m/s, 1.2 kg/m^3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TunnelConditions(pub Tunnel);

impl Default for TunnelConditions {
    fn default() -> Self {
        Self(Tunnel { u_inf_mps: 6.5, rho_kgm3: 1.2 })
    }
}

/// One run to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSpec {
    /// Which inputs are excited (recorded in the manifest).
    pub kind: RunKind,
    /// Angle of attack, deg.
    pub alpha_deg: f64,
    /// Duration, s.
    pub duration_s: f64,
    /// Sample rate, Hz.
    pub sample_hz: f64,
    /// Commanded roll angle, deg.
    pub roll_cmd_deg: HoldSequence,
    /// Commanded Cmu, port and starboard.
    pub blowing_cmd: [HoldSequence; 2],
    /// Seed of this run's noise.
    pub noise_seed: u64,
}

/// Simulates one run and returns its recorded channels (with the logged commands).
#[must_use]
pub fn simulate_run(config: &TunnelConfig, spec: &RunSpec) -> Channels {
    let model = model_of(config, spec.alpha_deg);
    let n_samples = (spec.duration_s * spec.sample_hz).round().max(0.0) as usize;
    let inputs = Inputs { roll_cmd_deg: &spec.roll_cmd_deg, blowing_cmd: &spec.blowing_cmd, sample_hz: spec.sample_hz };
    let mut run = RunState::new(&model, spec.alpha_deg, spec.sample_hz, spec.noise_seed, &config.aero, n_samples);
    let mut channels = empty_channels(n_samples);
    for sample_idx in 0..n_samples {
        let t_s = sample_idx as f64 / spec.sample_hz;
        let draws = NoiseDraws::next(&mut run.rng);
        run.advance_processes(&model, &draws, spec.sample_hz);
        let sample = run.record(&model, &inputs, t_s, &draws);
        push_sample(&mut channels, &sample);
        push_some(&mut channels.phi_cmd_deg, spec.roll_cmd_deg.value_at(t_s));
        push_some(&mut channels.cmu_port_cmd, spec.blowing_cmd[0].value_at(t_s));
        push_some(&mut channels.cmu_stbd_cmd, spec.blowing_cmd[1].value_at(t_s));
        run.integrate_sample(&model, &inputs, t_s);
    }
    channels
}

/// The model of a tunnel configuration at one angle of attack.
fn model_of(config: &TunnelConfig, alpha_deg: f64) -> Model {
    Model::new(
        &ModelConfig {
            tunnel: &config.tunnel.0,
            wing: &config.wing,
            aero: &config.aero,
            actuator: &config.actuator,
            sensors: &config.sensors,
            rig: &config.rig,
            effects: &config.effects,
        },
        alpha_deg,
    )
}

/// The commanded inputs of a run as functions of time (exact, so that delays and substeps read
/// them at any instant).
#[derive(Debug, Clone, Copy)]
struct Inputs<'a> {
    roll_cmd_deg: &'a HoldSequence,
    blowing_cmd: &'a [HoldSequence; 2],
    sample_hz: f64,
}

/// Appends one sample's measured channels.
fn push_sample(channels: &mut Channels, sample: &Sample) {
    channels.t_s.push(sample.t_s);
    channels.phi_deg.push(sample.phi_deg);
    channels.cmu_port.push(sample.cmu[0]);
    channels.cmu_stbd.push(sample.cmu[1]);
    for (column, &value) in channels.cp.iter_mut().zip(&sample.cp) {
        column.push(value);
    }
    channels.cl.push(sample.cl);
}

/// Random numbers of one sample, always drawn in the same order and number.
#[derive(Debug, Clone, Copy)]
struct NoiseDraws {
    buffet: [f64; 2],
    q: f64,
    cp: [f64; N_TAPS],
    balance: f64,
    cmu: [f64; 2],
    walk: f64,
    spike_uniform: f64,
    spike_sign: f64,
}

impl NoiseDraws {
    fn next(rng: &mut ChaCha8Rng) -> Self {
        let mut normal = || -> f64 { StandardNormal.sample(rng) };
        let buffet = [normal(), normal()];
        let q = normal();
        let cp = std::array::from_fn(|_| normal());
        let balance = normal();
        let cmu = [normal(), normal()];
        let walk = normal();
        let spike_sign = normal();
        let spike_uniform = rand::Rng::random::<f64>(rng);
        Self { buffet, q, cp, balance, cmu, walk, spike_uniform, spike_sign }
    }
}

/// Mutable state of a run being simulated.
#[derive(Debug, Clone)]
struct RunState {
    state: State,
    rng: ChaCha8Rng,
    /// Buffet processes (unit variance AR(1)) and their scale at this alpha.
    buffet: [f64; 2],
    buffet_std: f64,
    buffet_pole: f64,
    /// Relative dynamic-pressure fluctuation (AR(1)).
    q_deviation: f64,
    /// Random-walk part of the balance drift, C_l.
    drift_walk: f64,
    /// Value a stuck channel holds, once the fault has started.
    stuck_value: Option<f64>,
    /// Valve outputs at every substep so far (for the fractional `actuator_delay`).
    valve_history: Vec<[f64; 2]>,
}

impl RunState {
    fn new(
        model: &Model,
        alpha_deg: f64,
        sample_hz: f64,
        noise_seed: u64,
        aero: &AeroParams,
        n_samples: usize,
    ) -> Self {
        let alpha_scale = (alpha_deg.to_radians().sin() / 20f64.to_radians().sin()).powi(2);
        let keep_history = model.effects().actuator_delay.is_some();
        Self {
            state: model.rest_state(),
            rng: ChaCha8Rng::seed_from_u64(noise_seed),
            buffet: [0.0; 2],
            buffet_std: aero.buffet_state_std * alpha_scale,
            buffet_pole: (-std::f64::consts::TAU * aero.buffet_corner_hz / sample_hz).exp(),
            q_deviation: 0.0,
            drift_walk: 0.0,
            stuck_value: None,
            valve_history: Vec::with_capacity(if keep_history { n_samples * model.rig().substeps + 1 } else { 0 }),
        }
    }

    /// Advances the noise-driven processes by one sample.
    fn advance_processes(&mut self, model: &Model, draws: &NoiseDraws, sample_hz: f64) {
        let innovation = (1.0 - self.buffet_pole * self.buffet_pole).sqrt();
        for side in 0..2 {
            self.buffet[side] = self.buffet_pole * self.buffet[side] + innovation * draws.buffet[side];
        }
        if let Some(fluctuation) = model.effects().q_fluctuation {
            let pole = (-1.0 / (fluctuation.tau_s * sample_hz)).exp();
            let innovation = fluctuation.rel_std * (1.0 - pole * pole).sqrt();
            self.q_deviation = pole * self.q_deviation + innovation * draws.q;
        }
        self.drift_walk += draws.walk / sample_hz.sqrt();
    }

    /// The drive at time `t_s` for a given (stage) state.
    fn drive(&self, model: &Model, inputs: &Inputs<'_>, t_s: f64, stage: &State, q_deviation: f64) -> Drive {
        let actuator = model.actuator();
        let valve_cmd = std::array::from_fn(|side| inputs.blowing_cmd[side].value_at(t_s - actuator.valve_delay_s));
        let delayed_valve = match model.effects().actuator_delay {
            Some(delay) => self.delayed_valve(model, inputs.sample_hz, t_s - delay.delay_s),
            None => [stage[idx::VALVE], stage[idx::VALVE + 1]],
        };
        Drive {
            roll_cmd_rad: inputs.roll_cmd_deg.value_at(t_s).to_radians(),
            valve_cmd,
            delayed_valve,
            buffet: [self.buffet[0] * self.buffet_std, self.buffet[1] * self.buffet_std],
            q_factor: 1.0 + q_deviation,
        }
    }

    /// Valve output at an earlier time, linearly interpolated between substeps (a fractional
    /// delay); zero before the run started, the newest stored value beyond it.
    fn delayed_valve(&self, model: &Model, sample_hz: f64, t_s: f64) -> [f64; 2] {
        if t_s <= 0.0 || self.valve_history.is_empty() {
            return self.valve_history.first().copied().unwrap_or([0.0; 2]);
        }
        let position = t_s * sample_hz * model.rig().substeps as f64;
        let below = position.floor() as usize;
        let last = self.valve_history.len() - 1;
        if below >= last {
            return self.valve_history[last];
        }
        let weight = position - below as f64;
        let (early, late) = (self.valve_history[below], self.valve_history[below + 1]);
        std::array::from_fn(|side| early[side] + weight * (late[side] - early[side]))
    }

    /// Integrates the state over one sample with RK4 substeps.
    fn integrate_sample(&mut self, model: &Model, inputs: &Inputs<'_>, t_s: f64) {
        let substeps = model.rig().substeps.max(1);
        let step_s = 1.0 / (inputs.sample_hz * substeps as f64);
        let q_deviation = self.q_deviation;
        for substep in 0..substeps {
            let t0 = t_s + substep as f64 * step_s;
            if model.effects().actuator_delay.is_some() {
                self.valve_history.push([self.state[idx::VALVE], self.state[idx::VALVE + 1]]);
            }
            let rate = |time: f64, stage: &State| {
                model.derivative(stage, &self.drive(model, inputs, time, stage, q_deviation))
            };
            self.state = rk4_step(&self.state, t0, step_s, rate);
        }
    }

    /// The measured channels of the sample at time `t_s` (with the noise-free aerodynamic
    /// moment beside them).
    fn record(&mut self, model: &Model, inputs: &Inputs<'_>, t_s: f64, draws: &NoiseDraws) -> Sample {
        let drive = self.drive(model, inputs, t_s, &self.state, self.q_deviation);
        let flow = model.flow(&self.state, &drive);
        let sensors = *model.sensors();
        let rel_noise = model.actuator().measurement_rel_noise;
        let phi_deg = quantise(self.state[idx::PHI].to_degrees(), sensors.encoder_resolution_deg);
        let cmu =
            std::array::from_fn(|side| (self.state[idx::VALVE + side] * (1.0 + rel_noise * draws.cmu[side])).max(0.0));
        let mut cp = [0.0; N_TAPS];
        for (tap, value_out) in cp.iter_mut().enumerate() {
            let clean = model.tap_reading(&self.state, tap) + sensors.cp_noise_std * draws.cp[tap];
            let value = self.apply_fault(model.effects().pressure_fault, tap, t_s, clean, draws);
            *value_out = quantise(value, sensors.cp_resolution);
        }
        let cl = flow.cl_aero + self.balance_errors(model, t_s, &flow) + sensors.balance_noise_std_cl * draws.balance;
        Sample { t_s, phi_deg, cmu, cp, cl: quantise(cl, sensors.cl_resolution), cl_aero: flow.cl_aero }
    }

    /// What the balance reads beyond the aerodynamic moment, C_l: the effects of the balance
    /// block (untared inertia and weight, structural mode, zero drift).
    fn balance_errors(&self, model: &Model, t_s: f64, flow: &model::Flow) -> f64 {
        let effects = model.effects();
        let scale = model.moment_scale_nm();
        let phi = self.state[idx::PHI];
        let mut error_nm = model.structure_error_nm(&self.state, flow);
        if let Some(tare) = effects.inertial_tare {
            error_nm -= tare.ixx_kgm2 * flow.phi_ddot;
        }
        if let Some(tare) = effects.gravity_tare {
            error_nm += tare.mass_kg * GRAVITY_MPS2 * tare.cg_offset_m * (phi + tare.phase_deg.to_radians()).sin();
        }
        let mut error = error_nm / scale;
        if let Some(drift) = effects.bias_drift {
            error += drift.rate_per_s * t_s + drift.walk_per_sqrt_s * self.drift_walk;
        }
        error
    }

    /// Applies the `pressure_fault` effect to tap `tap`.
    fn apply_fault(
        &mut self,
        fault: Option<PressureFault>,
        tap: usize,
        t_s: f64,
        clean: f64,
        draws: &NoiseDraws,
    ) -> f64 {
        let Some(fault) = fault.filter(|fault| fault.channel == tap + 1 && t_s >= fault.start_s) else {
            return clean;
        };
        match fault.mode {
            FaultMode::Stuck => *self.stuck_value.get_or_insert(clean),
            FaultMode::Dead => f64::NAN,
            FaultMode::Bias => clean + fault.value,
            FaultMode::Spike if draws.spike_uniform < fault.spike_rate_hz * 1e-3 => {
                clean + fault.value * draws.spike_sign.signum()
            }
            FaultMode::Spike => clean,
        }
    }
}

/// One classical fourth-order Runge-Kutta step.
fn rk4_step(state: &State, t0: f64, step_s: f64, rate: impl Fn(f64, &State) -> State) -> State {
    let stage = |base: &State, slope: &State, fraction: f64| -> State {
        std::array::from_fn(|i| base[i] + fraction * step_s * slope[i])
    };
    let k1 = rate(t0, state);
    let k2 = rate(t0 + 0.5 * step_s, &stage(state, &k1, 0.5));
    let k3 = rate(t0 + 0.5 * step_s, &stage(state, &k2, 0.5));
    let k4 = rate(t0 + step_s, &stage(state, &k3, 1.0));
    std::array::from_fn(|i| state[i] + step_s / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
}

/// Rounds to the sensor's resolution. Dividing by the integer count per unit (rather than
/// multiplying by the resolution) gives the double nearest to the decimal, which is written
/// back with few digits.
fn quantise(value: f64, resolution: f64) -> f64 {
    if !(resolution > 0.0 && resolution <= 1.0 && value.is_finite()) {
        return value;
    }
    let per_unit = (1.0 / resolution).round();
    (value * per_unit).round() / per_unit
}

fn push_some(column: &mut Option<Vec<f64>>, value: f64) {
    if let Some(column) = column {
        column.push(value);
    }
}

fn empty_channels(n_samples: usize) -> Channels {
    let column = || Vec::with_capacity(n_samples);
    Channels {
        t_s: column(),
        phi_deg: column(),
        cmu_port: column(),
        cmu_stbd: column(),
        cp: std::array::from_fn(|_| column()),
        cl: column(),
        alpha_deg: None,
        phi_cmd_deg: Some(column()),
        cmu_port_cmd: Some(column()),
        cmu_stbd_cmd: Some(column()),
    }
}

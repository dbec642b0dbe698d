//! The continuous-time model of the rolling wing in the tunnel: roll servo, two
//! Goman-Khrabrov vortex states, blowing actuators, pressure tubing, structural mode.
//!
//! The state is integrated with classical RK4 at `RigParams::substeps` steps per sample; the
//! inputs (roll command, valve commands) are exact functions of time, and noise-driven inputs
//! (buffet, dynamic-pressure fluctuation) are held over a sample.

use super::effects::Effects;
use super::params::{ActuatorParams, AeroParams, RigParams, SensorParams};
use super::taps::{Side, TAPS};
use crate::dataset::{N_TAPS, Tunnel, Wing};

/// Indices into the state vector.
pub(crate) mod idx {
    /// Roll angle, rad.
    pub const PHI: usize = 0;
    /// Roll rate, rad/s.
    pub const PHI_DOT: usize = 1;
    /// Fast vortex states, port and starboard (GK `x`, 1 = vortex intact over the wing).
    pub const VORTEX: usize = 2;
    /// Slow vortex states (the `vortex_lag` effect).
    pub const VORTEX_SLOW: usize = 4;
    /// Valve outputs (the recorded Cmu), port and starboard.
    pub const VALVE: usize = 6;
    /// Extra actuator lag states (the `actuator_lag` effect).
    pub const ACT_LAG: usize = 8;
    /// Rising jet circulation, port and starboard (C_l).
    pub const JET_RISE: usize = 10;
    /// Settling counter-circulation, port and starboard (C_l).
    pub const JET_SETTLE: usize = 12;
    /// Structural mode of the balance: displacement and rate, in N m of load.
    pub const MODE: usize = 14;
    /// Tubing outputs of the 12 taps.
    pub const TUBE: usize = 16;
    /// Tubing rates of the 12 taps.
    pub const TUBE_DOT: usize = TUBE + super::N_TAPS;
    /// Extra pressure lag states (the `pressure_lag` effect).
    pub const PRESSURE_LAG: usize = TUBE_DOT + super::N_TAPS;
    /// Number of states.
    pub const N: usize = PRESSURE_LAG + super::N_TAPS;
}

/// The state vector.
pub(crate) type State = [f64; idx::N];

/// Inputs at one instant, assembled by the integrator for each RK4 stage.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Drive {
    /// Commanded roll angle, rad.
    pub roll_cmd_rad: f64,
    /// Valve commands after the valve's dead time, port and starboard.
    pub valve_cmd: [f64; 2],
    /// Valve outputs delayed by the `actuator_delay` effect (or undelayed when it is off).
    pub delayed_valve: [f64; 2],
    /// Buffet fluctuation of the vortex states, port and starboard.
    pub buffet: [f64; 2],
    /// Dynamic pressure over its mean.
    pub q_factor: f64,
}

/// Everything algebraic the model derives from a state and its drive.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Flow {
    /// Roll acceleration, rad/s^2.
    pub phi_ddot: f64,
    /// Effective Cmu at each slot.
    pub cmu_eff: [f64; 2],
    /// Aerodynamic roll moment coefficient (disturbance, jets and aerodynamic effects).
    pub cl_aero: f64,
    /// Jet moment target per side (before the circulation dynamics).
    pub jet_target: [f64; 2],
    /// True pressure coefficient at each tap (before tubing).
    pub cp_true: [f64; N_TAPS],
}

/// The model with its constants for one run.
#[derive(Debug, Clone)]
pub(crate) struct Model {
    aero: AeroParams,
    actuator: ActuatorParams,
    sensors: SensorParams,
    rig: RigParams,
    effects: Effects,
    alpha_rad: f64,
    /// `b / (2 U)`, s.
    half_span_time_s: f64,
    /// `q S b`, N m per unit C_l.
    moment_scale_nm: f64,
    /// Ixx of the wing, kg m^2.
    ixx_kgm2: f64,
    /// Vortex-lift moment gain at this alpha.
    vortex_gain: f64,
    /// Sideslip derivative at this alpha, per rad.
    clbeta: f64,
    /// Full-blowing jet moment at this alpha.
    jet_full_moment: f64,
    /// Free-stream speed, m/s.
    u_inf_mps: f64,
    /// Semi-span, m.
    semi_span_m: f64,
}

/// Configuration of a [`Model`]: the physical parameter blocks of a scenario.
#[derive(Debug, Clone)]
pub(crate) struct ModelConfig<'a> {
    pub tunnel: &'a Tunnel,
    pub wing: &'a Wing,
    pub aero: &'a AeroParams,
    pub actuator: &'a ActuatorParams,
    pub sensors: &'a SensorParams,
    pub rig: &'a RigParams,
    pub effects: &'a Effects,
}

impl Model {
    pub(crate) fn new(config: &ModelConfig<'_>, alpha_deg: f64) -> Self {
        let alpha_rad = alpha_deg.to_radians();
        let vortex_scale = (alpha_rad.sin() / 20f64.to_radians().sin()).powi(2);
        Self {
            aero: *config.aero,
            actuator: *config.actuator,
            sensors: *config.sensors,
            rig: *config.rig,
            effects: config.effects.clone(),
            alpha_rad,
            half_span_time_s: config.wing.span_m / (2.0 * config.tunnel.u_inf_mps),
            moment_scale_nm: config.tunnel.dynamic_pressure_pa() * config.wing.area_m2 * config.wing.span_m,
            ixx_kgm2: config.wing.ixx_kgm2,
            vortex_gain: config.aero.vortex_gain * vortex_scale,
            clbeta: config.aero.clbeta_per_rad_per_deg * alpha_deg,
            jet_full_moment: quadratic_through(config.actuator.full_moment_at_alpha, alpha_deg),
            u_inf_mps: config.tunnel.u_inf_mps,
            semi_span_m: 0.5 * config.wing.span_m,
        }
    }

    pub(crate) fn effects(&self) -> &Effects {
        &self.effects
    }

    pub(crate) fn moment_scale_nm(&self) -> f64 {
        self.moment_scale_nm
    }

    pub(crate) fn sensors(&self) -> &SensorParams {
        &self.sensors
    }

    pub(crate) fn rig(&self) -> &RigParams {
        &self.rig
    }

    pub(crate) fn actuator(&self) -> &ActuatorParams {
        &self.actuator
    }

    /// The steady state with the wing at rest at `phi = 0`, no blowing, tubes settled.
    pub(crate) fn rest_state(&self) -> State {
        let mut state = [0.0; idx::N];
        let drive = Drive { q_factor: 1.0, ..Drive::default() };
        let (incidence, _) = self.side_incidence(&state, [0.0; 2]);
        for side in 0..2 {
            let x_rest = self.breakdown_curve(incidence[side]);
            state[idx::VORTEX + side] = x_rest;
            state[idx::VORTEX_SLOW + side] = x_rest;
        }
        let flow = self.flow(&state, &drive);
        state[idx::TUBE..idx::TUBE + N_TAPS].copy_from_slice(&flow.cp_true);
        state[idx::PRESSURE_LAG..idx::PRESSURE_LAG + N_TAPS].copy_from_slice(&flow.cp_true);
        state
    }

    /// Time derivative of the state.
    pub(crate) fn derivative(&self, state: &State, drive: &Drive) -> State {
        let flow = self.flow(state, drive);
        let mut rate = [0.0; idx::N];
        rate[idx::PHI] = state[idx::PHI_DOT];
        rate[idx::PHI_DOT] = flow.phi_ddot;
        self.vortex_rates(state, &flow, &mut rate);
        self.actuator_rates(state, drive, &flow, &mut rate);
        self.structure_rates(state, &flow, &mut rate);
        self.tubing_rates(state, &flow, &mut rate);
        rate
    }

    /// The algebraic quantities of a state.
    pub(crate) fn flow(&self, state: &State, drive: &Drive) -> Flow {
        let phi_ddot = self.servo_acceleration(state, drive.roll_cmd_rad);
        let cmu_eff = self.effective_cmu(state, drive);
        let vortex_eff = self.vortex_effective(state, drive);
        let jet_target = self.jet_target(cmu_eff, vortex_eff);
        let cl_aero = drive.q_factor * self.aero_moment(state, phi_ddot, vortex_eff, cmu_eff);
        let cp_true = self.taps(state, vortex_eff, drive.q_factor);
        Flow { phi_ddot, cmu_eff, cl_aero, jet_target, cp_true }
    }

    /// Roll servo: a critically damped second-order tracking of the command.
    fn servo_acceleration(&self, state: &State, roll_cmd_rad: f64) -> f64 {
        let omega = std::f64::consts::TAU * self.rig.servo_natural_hz;
        omega * omega * (roll_cmd_rad - state[idx::PHI]) - 2.0 * self.rig.servo_damping * omega * state[idx::PHI_DOT]
    }

    /// Effective incidence of each half-wing and its rate with roll, rad and rad/s.
    ///
    /// Body-axis roll at incidence alpha gives sideslip `beta = asin(sin alpha sin phi)` and
    /// body incidence `alpha_b = atan(tan alpha cos phi)` (docs/equations.md, Kinematics); the
    /// windward half-wing sees `alpha_b + kb beta`, and blowing raises the blown side's
    /// incidence (docs/equations.md, The synthetic tunnel's model: the physical coupling).
    fn side_incidence(&self, state: &State, cmu_eff: [f64; 2]) -> ([f64; 2], [f64; 2]) {
        let (phi, phi_dot) = (state[idx::PHI], state[idx::PHI_DOT]);
        let (sin_a, tan_a) = (self.alpha_rad.sin(), self.alpha_rad.tan());
        let beta = (sin_a * phi.sin()).clamp(-1.0, 1.0).asin();
        let alpha_b = (tan_a * phi.cos()).atan();
        let dbeta_dphi = sin_a * phi.cos() / beta.cos().max(1e-9);
        let dalpha_b_dphi = -tan_a * phi.sin() / (1.0 + (tan_a * phi.cos()).powi(2));
        let kb = self.aero.sideslip_incidence_gain;
        let per_cmu = self.actuator.incidence_per_cmu_deg.to_radians();
        let incidence = [alpha_b - kb * beta + per_cmu * cmu_eff[0], alpha_b + kb * beta + per_cmu * cmu_eff[1]];
        let rate = [(dalpha_b_dphi - kb * dbeta_dphi) * phi_dot, (dalpha_b_dphi + kb * dbeta_dphi) * phi_dot];
        (incidence, rate)
    }

    /// Quasi-steady vortex state `x0 = (1 - tanh(k (a - a*))) / 2` (Fischenberg form,
    /// docs/equations.md, Flow state and published time constants).
    fn breakdown_curve(&self, incidence_rad: f64) -> f64 {
        let excess_deg = incidence_rad.to_degrees() - self.aero.breakdown_alpha_deg;
        0.5 * (1.0 - (self.aero.breakdown_steepness_per_deg * excess_deg).tanh())
    }

    fn vortex_effective(&self, state: &State, drive: &Drive) -> [f64; 2] {
        let weight = self.effects.vortex_lag.map_or(0.0, |lag| lag.weight);
        let mut vortex = [0.0; 2];
        for side in 0..2 {
            let fast = state[idx::VORTEX + side];
            let slow = state[idx::VORTEX_SLOW + side];
            vortex[side] = (1.0 - weight) * fast + weight * slow + drive.buffet[side];
        }
        vortex
    }

    /// Goman-Khrabrov lags `tau1 x' + x = x0(a - tau2 a')` (GK 1994), one per half-wing, and
    /// the slow state of the `vortex_lag` effect `tau x2' + x2 = x0(a)`.
    fn vortex_rates(&self, state: &State, flow: &Flow, rate: &mut State) {
        let (incidence, incidence_rate) = self.side_incidence(state, flow.cmu_eff);
        for side in 0..2 {
            let lagged = incidence[side] - self.aero.tau2_s * incidence_rate[side];
            let x = state[idx::VORTEX + side];
            rate[idx::VORTEX + side] = (self.breakdown_curve(lagged) - x) / self.aero.tau1_s;
            if let Some(lag) = self.effects.vortex_lag {
                let slow = state[idx::VORTEX_SLOW + side];
                rate[idx::VORTEX_SLOW + side] = (self.breakdown_curve(incidence[side]) - slow) / lag.tau_s;
            }
        }
    }

    /// Effective Cmu at each slot: the valve output, delayed and lagged by the actuator effects.
    fn effective_cmu(&self, state: &State, drive: &Drive) -> [f64; 2] {
        if self.effects.actuator_lag.is_some() {
            [state[idx::ACT_LAG], state[idx::ACT_LAG + 1]]
        } else {
            drive.delayed_valve
        }
    }

    /// Quasi-steady jet moment of each side: sub-linear (square-root, jet-flap theory) in Cmu,
    /// an alpha-dependent gain, and a loss of effectiveness when that side's vortex has broken
    /// down (docs/equations.md, Actuator and plant magnitudes; The synthetic tunnel's model).
    fn jet_target(&self, cmu_eff: [f64; 2], vortex_eff: [f64; 2]) -> [f64; 2] {
        let mut target = [0.0; 2];
        for side in 0..2 {
            let effectiveness = self.jet_effectiveness(cmu_eff[side]);
            let attached = 1.0 - self.actuator.breakdown_effectiveness_loss * (1.0 - vortex_eff[side]).clamp(0.0, 1.0);
            target[side] = self.jet_full_moment * effectiveness * attached;
        }
        target
    }

    /// Square-root effectiveness of a jet, 0 at no blowing and 1 at `cmu_max`, regularised near
    /// zero so that its slope stays finite.
    fn jet_effectiveness(&self, cmu: f64) -> f64 {
        let offset = self.actuator.sqrt_offset;
        let fraction = (cmu / self.actuator.cmu_max).max(0.0);
        ((fraction + offset).sqrt() - offset.sqrt()) / ((1.0 + offset).sqrt() - offset.sqrt())
    }

    /// Jet-augmented lift slope: the change of each blown half-wing's incidence caused by the
    /// roll motion (sideslip, body incidence and the roll-rate upwash at the jet's station)
    /// times its jet effectiveness. Zero without roll or without blowing.
    fn jet_lift_slope_moment(&self, state: &State, cmu_eff: [f64; 2]) -> f64 {
        let (incidence, _) = self.side_incidence(state, [0.0; 2]);
        let upwash = state[idx::PHI_DOT] * self.actuator.jet_span_fraction * self.semi_span_m / self.u_inf_mps;
        let change = [incidence[0] - self.alpha_rad - upwash, incidence[1] - self.alpha_rad + upwash];
        let port = self.jet_effectiveness(cmu_eff[0]) * change[0];
        let starboard = self.jet_effectiveness(cmu_eff[1]) * change[1];
        self.actuator.port_moment_sign * self.actuator.lift_slope_gain_per_rad * (port - starboard)
    }

    fn actuator_rates(&self, state: &State, drive: &Drive, flow: &Flow, rate: &mut State) {
        let actuator = &self.actuator;
        for side in 0..2 {
            rate[idx::VALVE + side] = (drive.valve_cmd[side] - state[idx::VALVE + side]) / actuator.valve_tau_s;
            if let Some(lag) = self.effects.actuator_lag {
                rate[idx::ACT_LAG + side] = (drive.delayed_valve[side] - state[idx::ACT_LAG + side]) / lag.tau_s;
            }
            let target = flow.jet_target[side];
            rate[idx::JET_RISE + side] = (target - state[idx::JET_RISE + side]) / actuator.rise_tau_s;
            rate[idx::JET_SETTLE + side] = (target - state[idx::JET_SETTLE + side]) / actuator.settle_tau_s;
        }
    }

    /// Jet roll moment of each side: `k J_rise - (k - 1) J_settle`, signed so that port blowing
    /// gives `port_moment_sign` and starboard blowing the opposite.
    pub(crate) fn jet_moment(&self, state: &State) -> f64 {
        let gain = self.actuator.overshoot_gain;
        let side_moment =
            |side: usize| gain * state[idx::JET_RISE + side] - (gain - 1.0) * state[idx::JET_SETTLE + side];
        self.actuator.port_moment_sign * (side_moment(0) - side_moment(1))
    }

    /// Aerodynamic roll moment: sideslip stiffness, roll damping and acceleration, vortex
    /// asymmetry, jets, and the aerodynamic effects (docs/equations.md, The synthetic tunnel's
    /// model).
    fn aero_moment(&self, state: &State, phi_ddot: f64, vortex_eff: [f64; 2], cmu_eff: [f64; 2]) -> f64 {
        let phi = state[idx::PHI];
        let p_hat = state[idx::PHI_DOT] * self.half_span_time_s;
        let p_hat_dot = phi_ddot * self.half_span_time_s * self.half_span_time_s;
        let beta = (self.alpha_rad.sin() * phi.sin()).clamp(-1.0, 1.0).asin();
        let stiffness_and_damping = self.clbeta * beta + self.aero.clp * p_hat;
        let mut moment = stiffness_and_damping
            + self.aero.clpdot * p_hat_dot
            + self.vortex_gain * (vortex_eff[0] - vortex_eff[1])
            + self.jet_moment(state)
            + self.jet_lift_slope_moment(state, cmu_eff);
        if let Some(damping) = self.effects.roll_damping {
            moment += damping.clp * p_hat;
        }
        if let Some(coupling) = self.effects.coupling {
            let blowing = (cmu_eff[0] - cmu_eff[1]) / self.actuator.cmu_max;
            moment += coupling.gain * blowing * stiffness_and_damping;
        }
        if let Some(cubic) = self.effects.cubic_stiffness {
            moment += cubic.gain * (phi / 30f64.to_radians()).powi(3);
        }
        moment
    }

    /// Structural mode of the balance: `y'' + 2 zeta w y' + w^2 y = w^2 u`, driven by the load
    /// `u = I phi'' + q S b C_l`.
    fn structure_rates(&self, state: &State, flow: &Flow, rate: &mut State) {
        let Some(mode) = self.effects.balance_resonance else { return };
        let omega = std::f64::consts::TAU * mode.freq_hz;
        let load_nm = self.ixx_kgm2 * flow.phi_ddot + self.moment_scale_nm * flow.cl_aero;
        rate[idx::MODE] = state[idx::MODE + 1];
        rate[idx::MODE + 1] =
            omega * omega * (load_nm - state[idx::MODE]) - 2.0 * mode.zeta * omega * state[idx::MODE + 1];
    }

    /// Load the balance reads beyond the static load because of its structural mode, N m.
    pub(crate) fn structure_error_nm(&self, state: &State, flow: &Flow) -> f64 {
        let Some(mode) = self.effects.balance_resonance else { return 0.0 };
        let load_nm = self.ixx_kgm2 * flow.phi_ddot + self.moment_scale_nm * flow.cl_aero;
        mode.gain * (state[idx::MODE] - load_nm)
    }

    /// Pressure tubing: second order per tap, `p'' + 2 zeta w p' + w^2 p = w^2 Cp`, then the
    /// first-order lag of the `pressure_lag` effect on the channels it names.
    fn tubing_rates(&self, state: &State, flow: &Flow, rate: &mut State) {
        let omega = std::f64::consts::TAU * self.sensors.tubing_natural_hz;
        let zeta = self.sensors.tubing_damping;
        for tap in 0..N_TAPS {
            let tube = state[idx::TUBE + tap];
            let tube_dot = state[idx::TUBE_DOT + tap];
            rate[idx::TUBE + tap] = tube_dot;
            rate[idx::TUBE_DOT + tap] = omega * omega * (flow.cp_true[tap] - tube) - 2.0 * zeta * omega * tube_dot;
            if let Some(lag) = &self.effects.pressure_lag {
                rate[idx::PRESSURE_LAG + tap] = (tube - state[idx::PRESSURE_LAG + tap]) / lag.tau_s;
            }
        }
    }

    /// Pressure reading of tap `tap` before noise: the tubing output, or the lagged one when the
    /// `pressure_lag` effect covers this channel.
    pub(crate) fn tap_reading(&self, state: &State, tap: usize) -> f64 {
        match &self.effects.pressure_lag {
            Some(lag) if lag.channels.is_empty() || lag.channels.contains(&(tap + 1)) => state[idx::PRESSURE_LAG + tap],
            _ => state[idx::TUBE + tap],
        }
    }

    /// True pressure coefficient of every tap: attached-flow suction and vortex suction at the
    /// tap's local incidence (which includes the roll-rate upwash `p y / U`), and the suction the
    /// jet induces ahead of its trailing edge.
    fn taps(&self, state: &State, vortex_eff: [f64; 2], q_factor: f64) -> [f64; N_TAPS] {
        let (incidence, _) = self.side_incidence(state, [0.0; 2]);
        let roll_rate = state[idx::PHI_DOT];
        let gain = self.actuator.overshoot_gain;
        let mut cp = [0.0; N_TAPS];
        for (tap, layout) in TAPS.iter().enumerate() {
            let side = layout.side as usize;
            let span_sign = match layout.side {
                Side::Port => -1.0,
                Side::Starboard => 1.0,
            };
            let upwash = span_sign * roll_rate * layout.span_fraction * self.semi_span_m / self.u_inf_mps;
            let local = (incidence[side] + upwash).sin();
            let jet = gain * state[idx::JET_RISE + side] - (gain - 1.0) * state[idx::JET_SETTLE + side];
            let attached = -1.2 * (1.0 - layout.chord_fraction) * local;
            let vortex = -2.5 * layout.span_fraction * local.max(0.0).powf(1.5) * vortex_eff[side];
            let jet_suction = -30.0 * layout.chord_fraction.powi(2) * jet;
            let base = -0.05 - 0.1 * (1.0 - layout.chord_fraction);
            cp[tap] = q_factor * (base + attached + vortex + jet_suction);
        }
        cp
    }
}

/// The quadratic through `(0, v0), (10, v1), (20, v2)` evaluated at `alpha_deg` (clamped to
/// -5..25 deg so that it never extrapolates far).
fn quadratic_through(values: [f64; 3], alpha_deg: f64) -> f64 {
    let a = alpha_deg.clamp(-5.0, 25.0) / 10.0;
    let [v0, v1, v2] = values;
    v0 * (a - 1.0) * (a - 2.0) / 2.0 - v1 * a * (a - 2.0) + v2 * a * (a - 1.0) / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadratic_passes_through_its_points() {
        let values = [0.010, 0.0115, 0.008];
        for (idx, alpha) in [0.0, 10.0, 20.0].into_iter().enumerate() {
            assert!((quadratic_through(values, alpha) - values[idx]).abs() < 1e-15);
        }
    }
}

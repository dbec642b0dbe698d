//! Effects the estimator's models lack, each switchable with its physical parameters: the
//! vocabulary of `docs/spec/diagnosis.md` plus effects outside it (for blind validation).
//!
//! An effect given without parameters takes a moderate default setting. The default tunnel has
//! every effect off. The injection code lives here, apart from the diagnosis's candidate models,
//! and uses other forms on purpose (fractional delays, continuous-time filters integrated with
//! RK4, a slow second vortex state with its own incidence) so that a diagnosis is not solved by
//! running the same code backwards.

use serde::Deserialize;

use crate::effect::Effect;

/// The switched-on effects of a scenario; `None` is off.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Effects {
    /// Transport delay between the recorded Cmu and its aerodynamic effect.
    pub actuator_delay: Option<ActuatorDelay>,
    /// First-order lag between the recorded Cmu and the effective Cmu.
    pub actuator_lag: Option<ActuatorLag>,
    /// Inertial reaction left in the balance moment.
    pub inertial_tare: Option<InertialTare>,
    /// Weight moment of a centre of gravity off the roll axis left in the balance moment.
    pub gravity_tare: Option<GravityTare>,
    /// Extra aerodynamic roll damping.
    pub roll_damping: Option<RollDamping>,
    /// A second, slower vortex state.
    pub vortex_lag: Option<VortexLag>,
    /// Extra disturbance-actuation interaction.
    pub coupling: Option<Coupling>,
    /// First-order lag of the pressure channels.
    pub pressure_lag: Option<PressureLag>,
    /// One faulty pressure channel.
    pub pressure_fault: Option<PressureFault>,
    /// Lightly damped structural mode of balance and sting.
    pub balance_resonance: Option<BalanceResonance>,
    /// Slow zero drift of the balance.
    pub bias_drift: Option<BiasDrift>,
    /// Outside the vocabulary: low-frequency fluctuation of the dynamic pressure.
    pub q_fluctuation: Option<QFluctuation>,
    /// Outside the vocabulary: a cubic static roll stiffness.
    pub cubic_stiffness: Option<CubicStiffness>,
}

impl Effects {
    /// The effects that are on, in vocabulary order.
    #[must_use]
    pub fn on(&self) -> Vec<Effect> {
        let flags = [
            (Effect::ActuatorDelay, self.actuator_delay.is_some()),
            (Effect::ActuatorLag, self.actuator_lag.is_some()),
            (Effect::InertialTare, self.inertial_tare.is_some()),
            (Effect::GravityTare, self.gravity_tare.is_some()),
            (Effect::RollDamping, self.roll_damping.is_some()),
            (Effect::VortexLag, self.vortex_lag.is_some()),
            (Effect::Coupling, self.coupling.is_some()),
            (Effect::PressureLag, self.pressure_lag.is_some()),
            (Effect::PressureFault, self.pressure_fault.is_some()),
            (Effect::BalanceResonance, self.balance_resonance.is_some()),
            (Effect::BiasDrift, self.bias_drift.is_some()),
            (Effect::QFluctuation, self.q_fluctuation.is_some()),
            (Effect::CubicStiffness, self.cubic_stiffness.is_some()),
        ];
        flags.into_iter().filter(|(_, on)| *on).map(|(effect, _)| effect).collect()
    }
}

/// Pneumatic transport delay (a fractional delay, interpolated at the integration substeps).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ActuatorDelay {
    /// Delay, s.
    pub delay_s: f64,
}

impl Default for ActuatorDelay {
    fn default() -> Self {
        Self { delay_s: 0.02 }
    }
}

/// Valve and plenum lag beyond the recorded Cmu.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ActuatorLag {
    /// Time constant, s.
    pub tau_s: f64,
}

impl Default for ActuatorLag {
    fn default() -> Self {
        Self { tau_s: 0.03 }
    }
}

/// The untared part of the wing's inertial reaction, `-I phi_ddot / (q S b)` in C_l.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InertialTare {
    /// Inertia whose reaction is left in the balance, kg m^2.
    pub ixx_kgm2: f64,
}

impl Default for InertialTare {
    fn default() -> Self {
        Self { ixx_kgm2: 1.0e-5 }
    }
}

/// Weight moment `m g d sin(phi + phase)` of a centre of gravity at distance `d` from the roll
/// axis.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GravityTare {
    /// Mass whose weight moment is left in the balance, kg.
    pub mass_kg: f64,
    /// Distance of its centre of gravity from the roll axis, m.
    pub cg_offset_m: f64,
    /// Angle of the offset from the wing's vertical, deg.
    pub phase_deg: f64,
}

impl Default for GravityTare {
    fn default() -> Self {
        Self { mass_kg: 0.130, cg_offset_m: 5.0e-4, phase_deg: 0.0 }
    }
}

/// Extra roll damping `C_l,p,extra p_hat`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RollDamping {
    /// Extra damping derivative per unit `p_hat = p b / (2 U)`.
    pub clp: f64,
}

impl Default for RollDamping {
    fn default() -> Self {
        Self { clp: -0.03 }
    }
}

/// A slower vortex-breakdown state per half-wing, `tau x2' + x2 = x0(alpha_side)`, that replaces
/// a share of the fast state in the moment and the pressures.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VortexLag {
    /// Time constant of the slow state, s.
    pub tau_s: f64,
    /// Share of the slow state in the effective vortex state (0..1).
    pub weight: f64,
}

impl Default for VortexLag {
    fn default() -> Self {
        Self { tau_s: 0.6, weight: 0.5 }
    }
}

/// Extra interaction: blowing changes the wing's sideslip stiffness and roll damping by
/// `gain (Cmu_port - Cmu_stbd) / Cmu_max` of their values; zero without roll or blowing.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Coupling {
    /// Fractional change of the disturbance moment at full blowing.
    pub gain: f64,
}

impl Default for Coupling {
    fn default() -> Self {
        Self { gain: 0.3 }
    }
}

/// First-order lag of the pressure channels (after the tubing's own dynamics).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PressureLag {
    /// Time constant, s.
    pub tau_s: f64,
    /// Channels affected (1-based); empty means all twelve.
    pub channels: Vec<usize>,
}

impl Default for PressureLag {
    fn default() -> Self {
        Self { tau_s: 0.02, channels: Vec::new() }
    }
}

/// How a pressure channel fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultMode {
    /// Holds the value it had when the fault started.
    Stuck,
    /// Reads nothing (missing samples).
    Dead,
    /// Adds a constant offset.
    Bias,
    /// Adds spikes of the given amplitude at random samples.
    Spike,
}

/// One faulty pressure channel from `start_s` on.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PressureFault {
    /// Faulty channel, 1-based (`cp07` is 7).
    pub channel: usize,
    /// Kind of fault.
    pub mode: FaultMode,
    /// Offset (bias) or spike amplitude, in Cp.
    pub value: f64,
    /// Spike rate, per second (spike mode only).
    pub spike_rate_hz: f64,
    /// Time from which the channel is faulty, s from the start of the run.
    pub start_s: f64,
}

impl Default for PressureFault {
    fn default() -> Self {
        Self { channel: 7, mode: FaultMode::Bias, value: 0.1, spike_rate_hz: 5.0, start_s: 0.0 }
    }
}

/// Structural mode of balance and sting, excited by the total load (inertial and
/// aerodynamic): the balance reads the load plus `gain` times the mode's dynamic amplification.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BalanceResonance {
    /// Natural frequency, Hz.
    pub freq_hz: f64,
    /// Damping ratio.
    pub zeta: f64,
    /// Share of the dynamic response that reaches the balance reading.
    pub gain: f64,
}

impl Default for BalanceResonance {
    fn default() -> Self {
        Self { freq_hz: 25.0, zeta: 0.03, gain: 0.01 }
    }
}

/// Zero drift of the balance: a ramp plus a random walk, in C_l.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BiasDrift {
    /// Drift rate, C_l per s.
    pub rate_per_s: f64,
    /// Random-walk intensity, C_l per sqrt(s).
    pub walk_per_sqrt_s: f64,
}

impl Default for BiasDrift {
    fn default() -> Self {
        Self { rate_per_s: 2.0e-5, walk_per_sqrt_s: 0.0 }
    }
}

/// Fluctuation of the dynamic pressure around its mean (an AR(1) process): the aerodynamic
/// moment and every pressure coefficient scale with `q(t) / q_mean`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct QFluctuation {
    /// Relative standard deviation of q.
    pub rel_std: f64,
    /// Correlation time, s.
    pub tau_s: f64,
}

impl Default for QFluctuation {
    fn default() -> Self {
        Self { rel_std: 0.03, tau_s: 0.5 }
    }
}

/// A cubic static roll stiffness `gain (phi / 30 deg)^3` in C_l.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CubicStiffness {
    /// Moment at phi = 30 deg.
    pub gain: f64,
}

impl Default for CubicStiffness {
    fn default() -> Self {
        Self { gain: 0.002 }
    }
}

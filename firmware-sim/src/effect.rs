//! The effect vocabulary (docs/spec/diagnosis.md, "Effect vocabulary"): one type for the
//! effects the tunnel injects, the diagnosis names and the blind campaign scores, so that a
//! name is spelled in one place.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// An unmodelled effect: the eleven of the diagnosis vocabulary and two outside it (which the
/// blind campaign injects to check that the diagnosis answers `unattributed`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Effect {
    /// Pure transport delay between the recorded Cmu and its aerodynamic effect.
    ActuatorDelay,
    /// First-order lag between the recorded Cmu and the effective Cmu.
    ActuatorLag,
    /// The wing's inertial reaction left in the balance moment.
    InertialTare,
    /// The weight moment of a centre of gravity off the roll axis left in the balance moment.
    GravityTare,
    /// An aerodynamic moment proportional to the roll rate that the disturbance model lacks.
    RollDamping,
    /// A second, slower flow state beyond the eGK's single lag.
    VortexLag,
    /// Disturbance-actuation interaction beyond the superposition.
    Coupling,
    /// First-order lag of pressure channels (tubing, sensor).
    PressureLag,
    /// One pressure channel stuck, dead, biased or spiking.
    PressureFault,
    /// A lightly damped structural mode of balance and sting.
    BalanceResonance,
    /// Slow zero drift of the balance.
    BiasDrift,
    /// Outside the vocabulary: a fluctuation of the dynamic pressure.
    QFluctuation,
    /// Outside the vocabulary: a static nonlinear roll stiffness.
    CubicStiffness,
}

/// The block of the sim an effect belongs to (docs/spec/diagnosis.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Block {
    /// The disturbance model (eGK, pressure path).
    Disturbance,
    /// The plant model of the blowing.
    Plant,
    /// The coupling operator.
    Coupling,
    /// The pressure sensors.
    Sensor,
    /// The balance.
    Balance,
}

impl Block {
    /// The name used in reports and JSON.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Disturbance => "disturbance",
            Self::Plant => "plant",
            Self::Coupling => "coupling",
            Self::Sensor => "sensor",
            Self::Balance => "balance",
        }
    }
}

impl Effect {
    /// The diagnosis vocabulary, in the contract's order.
    pub const VOCABULARY: [Self; 11] = [
        Self::ActuatorDelay,
        Self::ActuatorLag,
        Self::InertialTare,
        Self::GravityTare,
        Self::RollDamping,
        Self::VortexLag,
        Self::Coupling,
        Self::PressureLag,
        Self::PressureFault,
        Self::BalanceResonance,
        Self::BiasDrift,
    ];

    /// The effects outside the vocabulary.
    pub const OUTSIDE_VOCABULARY: [Self; 2] = [Self::QFluctuation, Self::CubicStiffness];

    /// Every effect: the vocabulary, then those outside it.
    pub const ALL: [Self; 13] = [
        Self::ActuatorDelay,
        Self::ActuatorLag,
        Self::InertialTare,
        Self::GravityTare,
        Self::RollDamping,
        Self::VortexLag,
        Self::Coupling,
        Self::PressureLag,
        Self::PressureFault,
        Self::BalanceResonance,
        Self::BiasDrift,
        Self::QFluctuation,
        Self::CubicStiffness,
    ];

    /// The name, exactly as in the contract.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::ActuatorDelay => "actuator_delay",
            Self::ActuatorLag => "actuator_lag",
            Self::InertialTare => "inertial_tare",
            Self::GravityTare => "gravity_tare",
            Self::RollDamping => "roll_damping",
            Self::VortexLag => "vortex_lag",
            Self::Coupling => "coupling",
            Self::PressureLag => "pressure_lag",
            Self::PressureFault => "pressure_fault",
            Self::BalanceResonance => "balance_resonance",
            Self::BiasDrift => "bias_drift",
            Self::QFluctuation => "q_fluctuation",
            Self::CubicStiffness => "cubic_stiffness",
        }
    }

    /// True for the effects of the diagnosis vocabulary.
    #[must_use]
    pub const fn in_vocabulary(self) -> bool {
        !matches!(self, Self::QFluctuation | Self::CubicStiffness)
    }

    /// The block of the sim the effect belongs to (for the two outside the vocabulary: the one
    /// they act through).
    #[must_use]
    pub const fn block(self) -> Block {
        match self {
            Self::ActuatorDelay | Self::ActuatorLag => Block::Plant,
            Self::InertialTare | Self::GravityTare | Self::BalanceResonance | Self::BiasDrift => Block::Balance,
            Self::RollDamping | Self::VortexLag | Self::QFluctuation | Self::CubicStiffness => Block::Disturbance,
            Self::Coupling => Block::Coupling,
            Self::PressureLag | Self::PressureFault => Block::Sensor,
        }
    }

    /// True for the effects that act on the pressure channels (their size is measured against
    /// the pressure noise, their gaps are in Cp).
    #[must_use]
    pub const fn is_sensor(self) -> bool {
        matches!(self.block(), Block::Sensor)
    }
}

impl fmt::Display for Effect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A name that is not an effect.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown effect `{0}` (expected one of: {list})", list = Effect::ALL.map(Effect::name).join(", "))]
pub struct UnknownEffect(pub String);

impl FromStr for Effect {
    type Err = UnknownEffect;

    fn from_str(name: &str) -> Result<Self, Self::Err> {
        Self::ALL.into_iter().find(|effect| effect.name() == name).ok_or_else(|| UnknownEffect(name.to_owned()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_parses_back_and_serialises_as_itself() {
        for effect in Effect::ALL {
            assert_eq!(effect.name().parse::<Effect>(), Ok(effect));
            assert_eq!(serde_json::to_string(&effect).unwrap(), format!("\"{}\"", effect.name()));
        }
        let error = "vortex".parse::<Effect>().unwrap_err().to_string();
        assert!(error.contains("vortex") && error.contains("vortex_lag"), "{error}");
    }

    #[test]
    fn the_vocabulary_and_the_rest_make_all() {
        let joined: Vec<Effect> = Effect::VOCABULARY.into_iter().chain(Effect::OUTSIDE_VOCABULARY).collect();
        assert_eq!(joined, Effect::ALL.to_vec());
        assert!(Effect::VOCABULARY.iter().all(|e| e.in_vocabulary()));
        assert!(Effect::OUTSIDE_VOCABULARY.iter().all(|e| !e.in_vocabulary()));
    }
}

//! What a sensor check reports: a finding on one, some or all pressure channels, its
//! parameters and its strength. The innovation checks ([`super::sensor`]) and the balance
//! alignment (the `pressure_lag` module) both produce it, so it lives apart from either.

use firmware_sim::effect::Effect;

use super::regression;

/// A sensor finding with its strength.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorFinding {
    /// [`Effect::PressureLag`] or [`Effect::PressureFault`].
    pub effect: Effect,
    /// Physical parameters.
    pub params: Vec<(String, ParamValue)>,
    /// The channel, for a single-channel finding (`cp07`).
    pub channel: Option<String>,
    /// Every channel the finding concerns (one for a fault; one, some or all for a lag).
    pub channels: Vec<String>,
    /// Mean square the finding explains per affected training sample, Cp^2.
    pub explained: f64,
    /// Noise variance of the affected channels' innovations, Cp^2.
    pub noise_var: f64,
    /// Evidence: `N_eff ln(SSR_0 / SSR) - k ln N_eff`.
    pub delta_bic: f64,
    /// Held-out gap before and after, Cp.
    pub heldout: regression::HeldoutGap,
    /// Gap on the selection part before and after, Cp (the decisions rest on it).
    pub selection: regression::HeldoutGap,
    /// One line of evidence for the report.
    pub evidence: String,
}

/// A parameter value: a number or a word (the fault mode).
#[derive(Debug, Clone, PartialEq)]
pub enum ParamValue {
    /// A number.
    Number(f64),
    /// A word.
    Text(String),
}

/// Name of channel `tap` (0-based) as in the dataset (`cp01`).
#[must_use]
pub fn channel_name(tap: usize) -> String {
    format!("cp{:02}", tap + 1)
}

impl SensorFinding {
    /// Its key in the sim's signature: the name and its channels (`pressure_lag:cp03+cp07`).
    #[must_use]
    pub fn floor_key(&self) -> String {
        format!("{}:{}", self.effect, self.channels.join("+"))
    }
}

/// Whether a finding is a lag of a whole set: the common lag, or every channel's own lag
/// ([`super::lag_set`], its shared part from the healthy channels or the balance), not a group
/// found on the innovations alone (marked by the sim's own alignment among its parameters).
#[must_use]
pub fn is_set_lag(finding: &SensorFinding) -> bool {
    finding.effect == Effect::PressureLag && finding.params.iter().any(|(key, _)| key == "reference_tau_s")
}

/// Strength of a finding in noise units: explained mean square over the noise variance.
#[must_use]
pub fn strength(finding: &SensorFinding) -> f64 {
    if finding.noise_var > 0.0 { finding.explained / finding.noise_var } else { 0.0 }
}

//! Physical parameters of the synthetic wind tunnel, with defaults from the paper (section II)
//! and from docs/equations.md, "Parameter ranges and sources" (Reference quantities of the
//! experiment; Magnitudes of the wing and its sensors; The synthetic tunnel's model).
//!
//! Every parameter is in SI units (angles in degrees where the name says `_deg`); time
//! constants are in seconds, not convective times, so that a change of `u_inf_mps` does not
//! silently rescale the mechanical and pneumatic parts.

use serde::Deserialize;

/// Disturbance aerodynamics of the rolling wing: two Goman-Khrabrov vortex states (one per
/// half-wing), static sideslip stiffness, roll damping and acceleration terms
/// (docs/equations.md, The synthetic tunnel's model).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AeroParams {
    /// Relaxation time of the vortex states, s (GK tau1; 3 c/U at the paper's speed).
    pub tau1_s: f64,
    /// Input delay of the vortex states, s (GK tau2; 0.5 c/U).
    pub tau2_s: f64,
    /// Effective incidence at which the vortex breaks down over the wing, deg.
    pub breakdown_alpha_deg: f64,
    /// Steepness of the breakdown curve `x0 = (1 - tanh(k (a - a*))) / 2`, per deg.
    pub breakdown_steepness_per_deg: f64,
    /// Sideslip-to-incidence coupling of each half-wing (windward side sees `+kb beta`).
    pub sideslip_incidence_gain: f64,
    /// Sideslip derivative per degree of alpha, per rad per deg (`C_l,beta = k alpha_deg`).
    pub clbeta_per_rad_per_deg: f64,
    /// Roll damping derivative `C_l,p` per unit `p_hat = p b / (2 U)`.
    pub clp: f64,
    /// Roll acceleration derivative per unit `p_hat_dot = p_dot (b / (2 U))^2`.
    pub clpdot: f64,
    /// Roll moment per unit vortex-state asymmetry `x_L - x_R` at alpha = 20 deg (scales with
    /// `sin^2 alpha`, the vortex-lift scaling).
    pub vortex_gain: f64,
    /// Standard deviation of the buffet fluctuation of each vortex state at alpha = 20 deg
    /// (scales with `sin^2 alpha`).
    pub buffet_state_std: f64,
    /// Corner frequency of the buffet fluctuation, Hz.
    pub buffet_corner_hz: f64,
}

impl Default for AeroParams {
    fn default() -> Self {
        Self {
            tau1_s: 0.152,
            tau2_s: 0.025,
            breakdown_alpha_deg: 22.0,
            breakdown_steepness_per_deg: 0.25,
            sideslip_incidence_gain: 1.0,
            clbeta_per_rad_per_deg: -0.0075,
            clp: -0.17,
            clpdot: -0.01,
            vortex_gain: 0.03,
            buffet_state_std: 0.005,
            buffet_corner_hz: 15.0,
        }
    }
}

/// Blowing actuators (one per trailing edge): valve, aerodynamic response and the physical
/// interaction with the roll disturbance (docs/equations.md, Actuator and plant magnitudes; The
/// synthetic tunnel's model).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ActuatorParams {
    /// Largest momentum coefficient the supply delivers.
    pub cmu_max: f64,
    /// Dead time of the valve between command and slot flow, s.
    pub valve_delay_s: f64,
    /// First-order time constant of the valve and plenum, s.
    pub valve_tau_s: f64,
    /// Rise time constant of the jet-induced circulation, s (about 0.5 c/U).
    pub rise_tau_s: f64,
    /// Time constant of the wake's counter-circulation that settles the turn-on overshoot, s
    /// (1.5 c/U).
    pub settle_tau_s: f64,
    /// Overshoot gain: the jet moment is `k J_rise - (k - 1) J_settle`, so `k = 1` has no
    /// overshoot and `k = 1.45` overshoots by about 12 %.
    pub overshoot_gain: f64,
    /// Roll moment at full blowing at alpha = 0, 10, 20 deg (quadratic in alpha between them).
    pub full_moment_at_alpha: [f64; 3],
    /// Regularisation of the square-root effectiveness, as a fraction of `cmu_max`.
    pub sqrt_offset: f64,
    /// Increase of the blown half-wing's effective incidence per unit Cmu, deg.
    pub incidence_per_cmu_deg: f64,
    /// Jet-augmented lift slope: roll moment per unit jet effectiveness per rad of change of
    /// the blown half-wing's incidence caused by roll (jet-flap theory: blowing raises the lift
    /// slope, Spence 1956), a disturbance-actuation interaction that grows with alpha.
    pub lift_slope_gain_per_rad: f64,
    /// Spanwise station of the jets as a fraction of the semi-span.
    pub jet_span_fraction: f64,
    /// Loss of jet effectiveness when the blown side's vortex has broken down (0..1).
    pub breakdown_effectiveness_loss: f64,
    /// Relative noise of the measured Cmu (a mass-flow meter); zero flow reads exactly zero.
    pub measurement_rel_noise: f64,
    /// Sign of the roll moment of port blowing (+1: port blowing rolls starboard wing down).
    pub port_moment_sign: f64,
}

impl Default for ActuatorParams {
    fn default() -> Self {
        Self {
            cmu_max: 0.009,
            valve_delay_s: 0.005,
            valve_tau_s: 0.003,
            rise_tau_s: 0.025,
            settle_tau_s: 0.076,
            overshoot_gain: 1.45,
            full_moment_at_alpha: [0.010, 0.0115, 0.011],
            sqrt_offset: 0.02,
            incidence_per_cmu_deg: 80.0,
            lift_slope_gain_per_rad: 0.013,
            jet_span_fraction: 0.6,
            breakdown_effectiveness_loss: 0.4,
            measurement_rel_noise: 0.005,
            port_moment_sign: 1.0,
        }
    }
}

/// Sensors: the 12 upper-surface pressure taps, the balance and the roll encoder
/// (docs/equations.md, Magnitudes of the wing and its sensors; The synthetic tunnel's model).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SensorParams {
    /// White noise of each pressure coefficient.
    pub cp_noise_std: f64,
    /// Natural frequency of the tubing of every tap, Hz.
    pub tubing_natural_hz: f64,
    /// Damping ratio of the tubing.
    pub tubing_damping: f64,
    /// Resolution of the recorded pressure coefficients.
    pub cp_resolution: f64,
    /// White noise of the balance, in roll-moment coefficient.
    pub balance_noise_std_cl: f64,
    /// Resolution of the recorded roll-moment coefficient.
    pub cl_resolution: f64,
    /// Resolution of the roll encoder, deg.
    pub encoder_resolution_deg: f64,
}

impl Default for SensorParams {
    fn default() -> Self {
        Self {
            cp_noise_std: 0.01,
            tubing_natural_hz: 120.0,
            tubing_damping: 0.6,
            cp_resolution: 1e-5,
            balance_noise_std_cl: 2.8e-4,
            cl_resolution: 1e-7,
            encoder_resolution_deg: 0.01,
        }
    }
}

/// The roll rig: a servo that tracks the commanded roll angle as a critically damped
/// second-order system, so the wing's true roll rate and acceleration are smooth and known.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RigParams {
    /// Natural frequency of the roll servo, Hz (content up to about 3 Hz).
    pub servo_natural_hz: f64,
    /// Damping ratio of the roll servo.
    pub servo_damping: f64,
    /// Internal integration steps per recorded sample.
    pub substeps: usize,
}

impl Default for RigParams {
    fn default() -> Self {
        Self { servo_natural_hz: 4.0, servo_damping: 1.0, substeps: 4 }
    }
}

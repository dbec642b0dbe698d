//! The coefficient set: every table the estimator needs, fitted on the host (`host-tools fit`)
//! and either compiled in as const tables (`coeffs::generated`) or loaded from a postcard blob
//! ([`crate::blob`]).
//!
//! Sizes are fixed at compile time; a fit that needs fewer entries leaves the rest zero (unused
//! pressure-model modes are zero rows and columns, unused sparse terms are zero terms past
//! `n_terms`).

mod compiled;
// Printed by `host-tools codegen` (prettyplease), checked against the committed model by a
// test; rustfmt leaves the printer's layout alone.
#[rustfmt::skip]
mod generated;

use serde::{Deserialize, Serialize};

use crate::real::Real;
use crate::sparse::SparseModel;

pub use compiled::{BUILT_IN, CompiledDefault};
pub use generated::DEFAULT;

/// Version of the coefficient-set layout. Bump it whenever a field or a size changes.
pub const SCHEMA_VERSION: u16 = 8;

/// Number of upper-surface pressure taps.
pub const N_TAPS: usize = 12;

/// Largest rank of the reduced, time-shifted pressure model.
pub const PRESSURE_RANK: usize = 10;

/// Inputs of the pressure model: `[phi_rad, phi_dot_rad_s, cmu_port, cmu_stbd, 1]`.
pub const N_PRESSURE_INPUTS: usize = 5;

/// Largest number of angle-of-attack breakpoints of the eGK schedule.
pub const N_ALPHA: usize = 8;

/// Largest number of terms of a sparse model.
pub const MAX_TERMS: usize = 16;

/// Largest total degree of a sparse term (paper eq. 12 uses cubes; the plant's alpha
/// interactions of the degree-2 actuation terms are of degree 3).
pub const MAX_DEGREE: usize = 3;

/// Largest number of variables of a sparse model.
pub const MAX_VARS: usize = 7;

/// Variables of the plant model (paper eq. 5, plus a slow state): `[C_l,AFC, Cmu, dCmu,
/// alpha_rad, C_l,slow]`.
pub const N_PLANT_VARS: usize = 5;

/// Variables of the coupling operator (paper eqs. 9-11, plus the roll rate):
/// `[C_l,roll, C_l,AFC, alpha_rad, Cmu, dCmu, phi_rad, phi_dot_rad_s]`.
pub const N_COUPLING_VARS: usize = 7;

/// Slots of the demand history the actuator response reads ([`ActuatorResponse`]): the longest
/// dead time is `DEMAND_SLOTS - 1` steps (63 ms at 1 kHz). A valve and plenum of a
/// trailing-edge jet respond within a few ms (the tunnel's valve: 5 ms dead time and a 3 ms
/// lag, `firmware-sim/src/tunnel/params.rs`); the history is 12 times that, 512 bytes for both
/// jets. A power of two, so the ring index is a mask.
pub const DEMAND_SLOTS: usize = 64;

/// Margin of the estimate envelope ([`Envelope`]), as a share of the measured range's span on
/// each side: the estimator keeps `C_l,roll`, `C_l,linear` and `C_l` within
/// `[low - ENVELOPE_MARGIN span, high + ENVELOPE_MARGIN span]`.
///
/// Why a quarter: the range is the balance's over the training part, so a legitimate estimate
/// may leave it (the held-out part and later flights move the wing differently, and the
/// estimate carries its own error). On the default campaign the estimates of every run, held-out
/// part included, reach at most 0.5 % of the span beyond the training range (`C_l` 0.0554
/// against 0.0549, span 0.106; `host-tools replay`), fifty times less than this margin, and the
/// held-out RMS error of `C_l` is 0.3 % of the span. An estimate beyond the margin, 1.5 times
/// the measured span from one end to the other, is a moment the wing was never seen to make:
/// the soak's garbage input drove `C_l` to 0.39 before the envelope, 3.7 spans
/// (`cargo xtask soak --steps 10000000 --seed 3`).
pub const ENVELOPE_MARGIN: f32 = 0.25;

/// Index of each plant variable.
pub mod plant_var {
    /// The side's actuation roll moment at step k.
    pub const CL_AFC: usize = 0;
    /// The side's momentum coefficient at step k.
    pub const CMU: usize = 1;
    /// Its increment `Cmu[k] - Cmu[k-1]`.
    pub const DCMU: usize = 2;
    /// Angle of attack, rad.
    pub const ALPHA: usize = 3;
    /// The slow state: `C_l,AFC` through a first-order low-pass ([`super::PlantParams`]).
    pub const CL_SLOW: usize = 4;
}

/// Index of each coupling variable.
pub mod coupling_var {
    /// Disturbance-model roll moment.
    pub const CL_ROLL: usize = 0;
    /// Plant-model roll moment (both sides).
    pub const CL_AFC: usize = 1;
    /// Angle of attack, rad.
    pub const ALPHA: usize = 2;
    /// Total momentum coefficient (port + starboard).
    pub const CMU: usize = 3;
    /// Its increment.
    pub const DCMU: usize = 4;
    /// Roll angle, rad (its indicator gates terms on roll motion).
    pub const PHI: usize = 5;
    /// Roll rate, rad/s (the rate filter's, as the eGK reads it): blowing on a rolling wing
    /// changes the jet's moment with the blown half-wing's incidence, which the roll rate
    /// moves (`p b / 2U` of it), and the disturbance model's moment alone does not carry it.
    pub const PHI_DOT: usize = 6;
}

/// The whole coefficient set.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CoefficientSet {
    /// Layout version; must equal [`SCHEMA_VERSION`].
    pub schema_version: u16,
    /// Fixed step, s.
    pub dt_s: f32,
    /// Roll-rate and roll-acceleration differentiators.
    pub rate_filter: RateFilter,
    /// Angle-of-attack breakpoints of the eGK schedule, deg, ascending; `n_alpha` are used.
    pub alpha_schedule_deg: [f32; N_ALPHA],
    /// Number of used breakpoints (at least 1).
    pub n_alpha: u8,
    /// eGK parameters at each breakpoint (linearly interpolated in alpha, held outside).
    pub egk: [EgkParams; N_ALPHA],
    /// Time-shifted pressure model, its steady-state Kalman filter and the map to C_l.
    pub pressure: PressureModel,
    /// Fusion of the eGK and pressure estimates.
    pub fusion: FusionParams,
    /// Plant models of the port and starboard jets (paper eq. 5, with a slow state).
    pub plant: [PlantParams; 2],
    /// Coupling operator (paper eqs. 9-11).
    pub coupling: SparseModel,
    /// Feedforward and feedback controller blocks.
    pub controller: ControllerParams,
    /// Response of the port and starboard jets' Cmu to the controller's demand: what the plant
    /// runs on while the blowing measurement is missing.
    pub actuator: [ActuatorResponse; 2],
    /// The roll moments the fit data measured: the estimates are kept within it, with a margin.
    pub envelope: Envelope,
}

/// First-order filtered differentiators for the roll rate and acceleration from the encoder:
/// `y[k] = p y[k-1] + (1 - p) (u[k] - u[k-1]) / dt` with the pole `p = exp(-2 pi f_c dt)`
/// computed on the host.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RateFilter<R = f32> {
    /// Pole of the roll-rate differentiator.
    pub rate_pole: R,
    /// Pole of the roll-acceleration differentiator.
    pub accel_pole: R,
}

/// Parameters of the extended Goman-Khrabrov model at one angle of attack.
///
/// Two flow states (port and starboard vortex), each `tau1 x' + x = x0(a - tau2 a')` at its
/// half-wing's effective incidence `a = atan(tan alpha cos phi) -+ kb asin(sin alpha sin phi)`,
/// with `x0(a) = (1 - tanh(k (a - a*))) / 2`; the output map is
/// `C_l = C_l,beta beta + C_l,p p_hat + C_l,pdot p_hat_dot + K_v (x_L - x_R) + C_l,0`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EgkParams<R = f32> {
    /// Relaxation time, s (> 0).
    pub tau1_s: R,
    /// Input delay, s (>= 0).
    pub tau2_s: R,
    /// Breakdown incidence a*, deg.
    pub breakdown_deg: R,
    /// Steepness k of the breakdown curve, per deg.
    pub steepness_per_deg: R,
    /// Sideslip-to-incidence gain kb of each half-wing.
    pub sideslip_gain: R,
    /// Sideslip derivative C_l,beta, per rad.
    pub clbeta_per_rad: R,
    /// Roll damping C_l,p per unit `p_hat = p b / (2 U)`.
    pub clp: R,
    /// Roll-acceleration derivative per unit `p_hat_dot = p_dot (b / (2 U))^2`.
    pub clpdot: R,
    /// Quadratic roll damping C_l,p|p| per unit `p_hat |p_hat|`: the rate damping of a slender
    /// wing grows faster than the rate (the `|phi_dot| phi_dot` term of Elzebda, Nayfeh & Mook,
    /// J. Aircraft 26(8), 1989; docs/equations.md, Slender-wing roll moment forms).
    pub clpp: R,
    /// Vortex-asymmetry gain K_v.
    pub vortex_gain: R,
    /// Constant offset C_l,0.
    pub bias: R,
    /// `b / (2 U)`, s: converts the roll rate to `p_hat`.
    pub half_span_time_s: R,
}

/// The time-shifted (delay-embedded), reduced linear model of the 12 pressure coefficients
/// with control inputs (DMDc; Brunton et al. 2016, Proctor et al. 2016), its steady-state
/// Kalman gain and the linear map to C_l (docs/equations.md, Time-shifted pressure model and its
/// Kalman filter).
///
/// Reduced state `a`: `a[k+1] = A a[k] + B u[k]`, measured pressures
/// `Cp[k] = C a[k] + cp_mean + v`; update `a = a_pred + K (Cp - C a_pred - cp_mean)` channel by
/// channel; `C_l,p = w . (C a + cp_mean) + w0`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PressureModel<R = f32> {
    /// Number of used modes (at most [`PRESSURE_RANK`]).
    pub rank: u8,
    /// State matrix `A`, rows by columns.
    pub a: [[R; PRESSURE_RANK]; PRESSURE_RANK],
    /// Input matrix `B`.
    pub b: [[R; N_PRESSURE_INPUTS]; PRESSURE_RANK],
    /// Output matrix `C` (tap by mode): the newest pressure block of the time-shifted state.
    pub c: [[R; PRESSURE_RANK]; N_TAPS],
    /// Mean pressure coefficient of each tap.
    pub cp_mean: [R; N_TAPS],
    /// Steady-state Kalman gain `K` (mode by tap), from the DARE solved on the host.
    pub gain: [[R; N_TAPS]; PRESSURE_RANK],
    /// Standard deviation of each tap's innovation at steady state.
    pub innovation_std: [R; N_TAPS],
    /// Innovation gate, in standard deviations: a larger innovation is rejected and flagged.
    pub gate_sigma: R,
    /// Consecutive rejections after which a channel is isolated as faulty.
    pub isolate_after: u16,
    /// Steps from the start during which every finite reading corrects the state, ungated:
    /// the filter starts at the mean pressures, and until its state has converged the gate
    /// would take good channels for faults (at 20 deg it rejected half of them and isolated
    /// them for 0.3 s). Fitted on the host from the filter's error dynamics
    /// (`host-tools fit`, `settle_steps`).
    pub settle_steps: u16,
    /// Map from filtered pressures to C_l at each breakpoint of the set's alpha schedule
    /// (`crate::schedule`; interpolated between them). One map for all alphas errs twice as
    /// much: the vortex suction that the taps see changes its share of the roll moment with
    /// alpha.
    pub cl_weights: [[R; N_TAPS]; N_ALPHA],
    /// Offset of that map at each breakpoint.
    pub cl_offset: [R; N_ALPHA],
}

/// The fusion filter (docs/equations.md, Fusion design): the error of the eGK estimate is
/// a first-order Gauss-Markov state `e[k+1] = rho e[k] + w`, observed by the pressure path as
/// `C_l,p - C_l,eGK = e + v`; `C_l,roll = C_l,eGK + e_hat`. The pressure path carries the trend
/// and bias, the eGK the fast content.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FusionParams<R = f32> {
    /// Correlation of the eGK error from step to step, `exp(-dt / T_e)`.
    pub rho: R,
    /// Steady-state Kalman gain of the scalar filter.
    pub gain: R,
}

/// The plant model of one jet: the paper's SINDy difference equation (eq. 5),
/// `C_l,AFC[k+1] = Xi Theta(C_l,AFC[k], Cmu[k], dCmu[k], alpha[k], C_l,slow[k])`, extended by
/// one slow state `C_l,slow[k+1] = p C_l,slow[k] + (1 - p) C_l,AFC[k]`.
///
/// Why the slow state: a first-order difference equation has one time constant, but the jet's
/// moment rises fast and then relaxes as the wake's counter-circulation builds up (the turn-on
/// overshoot of circulation control; docs/equations.md, Actuator and plant magnitudes). A term
/// linear in `C_l,slow` closes a second loop, which gives the plant two poles and a zero, the
/// form of that response.
/// A model without slow terms is the paper's eq. 5 exactly, whatever the pole.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PlantParams {
    /// Pole of the slow state, `exp(-dt / T_slow)`, in `[0, 1)`.
    pub slow_pole: f32,
    /// Largest Cmu of the data the model was fitted on (> 0): the plant's input is clamped to
    /// it, because a polynomial outside the range of its data means nothing (a Cmu reading
    /// beyond the supply's range is a sensor fault, and the controller never demands more).
    pub cmu_max: f32,
    /// The difference equation.
    pub model: SparseModel,
}

/// Feedforward and feedback controller blocks (paper Fig. 4, King/Williams architecture).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ControllerParams {
    /// Pole `exp(-dt / T_F)` of the first-order causality filter on the feedforward target.
    pub causality_pole: f32,
    /// Proportional gain of the feedback on the measured roll moment, Cl per Cl.
    pub feedback_kp: f32,
    /// Integral gain of the feedback, Cl per (Cl s).
    pub feedback_ki: f32,
    /// Largest momentum coefficient of each jet.
    pub cmu_max: f32,
    /// Bisection iterations of the per-step plant inversion.
    pub inversion_iterations: u8,
}

/// Response of one jet's momentum coefficient to the controller's Cmu demand: a dead time, then
/// a first-order lag with a gain (the valve and plenum; a first-order-plus-dead-time model, the
/// usual form of a valve's flow response, Seborg, Edgar & Mellichamp, Process Dynamics and
/// Control, 2nd ed., chapter 6; the `actuator_delay` and `actuator_lag` of the diagnosis
/// vocabulary, docs/diagnosis.md, Actuator delay and lag):
/// `Cmu[k] = pole Cmu[k-1] + (1 - pole) gain demand[k - 1 - delay_steps]`,
/// where `demand[j]` is the demand noted after step `j` ([`crate::Estimator::note_demand`]).
///
/// Fitted on the host from the dataset's commanded Cmu against the measured one
/// (`host-tools fit`); without command columns it is the identity (`delay_steps = 0`,
/// `pole = 0`, `gain = 1`: the measured Cmu is the last demand).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ActuatorResponse<R = f32> {
    /// Dead time, steps (below [`DEMAND_SLOTS`]).
    pub delay_steps: u8,
    /// Pole of the lag, `exp(-dt / T_valve)`, in `[0, 1)`.
    pub pole: R,
    /// Steady-state Cmu per unit demand, in `(0, 10]`.
    pub gain: R,
}

/// The range of roll moments measured by the balance in the fit data (the training part of every
/// run), which the estimator keeps its estimates within, with [`ENVELOPE_MARGIN`] on each side:
/// far outside the fitted inputs (garbage held or clamped at the input limits) the models would
/// otherwise extrapolate to moments the wing cannot make.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Envelope {
    /// `[lowest, highest]` disturbance moment: the balance's `C_l` in the roll runs (no blowing);
    /// bounds `C_l,roll`.
    pub cl_roll: [f32; 2],
    /// `[lowest, highest]` total moment: the balance's `C_l` in every run; bounds `C_l,linear`
    /// and `C_l`.
    pub cl: [f32; 2],
}

impl ActuatorResponse {
    /// The identity: the jet's Cmu is the last demand.
    pub const IDENTITY: Self = Self { delay_steps: 0, pole: 0.0, gain: 1.0 };
}

impl Envelope {
    /// `range` widened by [`ENVELOPE_MARGIN`] times its span on each side.
    #[must_use]
    pub const fn with_margin(range: [f32; 2]) -> [f32; 2] {
        let margin = ENVELOPE_MARGIN * (range[1] - range[0]);
        [range[0] - margin, range[1] + margin]
    }
}

impl<R: Real> PressureModel<R> {
    /// The same table in another scalar: exact from f32 to f64, rounded to nearest the other
    /// way (check the result with [`crate::blob::validate`] before flying it).
    #[must_use]
    pub fn cast<S: Real>(&self) -> PressureModel<S> {
        let to = |value: R| S::from_f64(value.to_f64());
        PressureModel {
            rank: self.rank,
            a: self.a.map(|row| row.map(to)),
            b: self.b.map(|row| row.map(to)),
            c: self.c.map(|row| row.map(to)),
            cp_mean: self.cp_mean.map(to),
            gain: self.gain.map(|row| row.map(to)),
            innovation_std: self.innovation_std.map(to),
            gate_sigma: to(self.gate_sigma),
            isolate_after: self.isolate_after,
            settle_steps: self.settle_steps,
            cl_weights: self.cl_weights.map(|row| row.map(to)),
            cl_offset: self.cl_offset.map(to),
        }
    }
}

impl<R: Real> EgkParams<R> {
    /// The same parameters in another scalar: exact from f32 to f64, rounded to nearest the
    /// other way.
    #[must_use]
    pub fn cast<S: Real>(&self) -> EgkParams<S> {
        let to = |value: R| S::from_f64(value.to_f64());
        EgkParams {
            tau1_s: to(self.tau1_s),
            tau2_s: to(self.tau2_s),
            breakdown_deg: to(self.breakdown_deg),
            steepness_per_deg: to(self.steepness_per_deg),
            sideslip_gain: to(self.sideslip_gain),
            clbeta_per_rad: to(self.clbeta_per_rad),
            clp: to(self.clp),
            clpdot: to(self.clpdot),
            clpp: to(self.clpp),
            vortex_gain: to(self.vortex_gain),
            bias: to(self.bias),
            half_span_time_s: to(self.half_span_time_s),
        }
    }
}

impl<R: Real> RateFilter<R> {
    /// The same poles in another scalar (exact from f32 to f64).
    #[must_use]
    pub fn cast<S: Real>(&self) -> RateFilter<S> {
        RateFilter {
            rate_pole: S::from_f64(self.rate_pole.to_f64()),
            accel_pole: S::from_f64(self.accel_pole.to_f64()),
        }
    }
}

//! The candidate effects of the balance stream: each a physical addition to the sim with a few
//! parameters, written as regressors of the balance residual (docs/diagnosis.md, Candidate
//! families, groups G0-G9), with a family of forms over its nonlinear parameters (delays, time
//! constants, frequencies) and discrete choices, profiled by least squares.
//!
//! One type per candidate behind [`BalanceCandidate`]: its forms, its columns (over the whole
//! run, so the held-out part sees the effect extended exactly as the fit left it) and its
//! physical parameters. A form is typed ([`Form`], [`Shape`]), never a list of named numbers.
//!
//! The regressors are built from the recorded inputs and the sim's own blocks, never from the
//! synthetic tunnel's code: the plant is re-run by estimator-core on a delayed or lagged Cmu, the
//! vortex lag filters the eGK moment, the structural mode filters the sim's load.

mod actuator;
mod aerodynamic;
mod structure;
mod tare;

use std::collections::BTreeMap;
use std::fmt;

use estimator_core::CoefficientSet;
pub use firmware_sim::effect::Block;
use firmware_sim::effect::Effect;

pub use self::actuator::{ActuatorDelay, ActuatorLag, fractional_delay};
pub use self::aerodynamic::{Coupling, Recalibration, RollDamping, VortexLag};
pub use self::structure::{
    BalanceResonance, BiasDrift, DRIFT_KNOT_SPACING_S, RESONANCE_DAMPING, band_pass, lowpass2, resonance_seeds_hz,
    resonator, step_times_s,
};
pub use self::tare::{GravityTare, InertialTare};
use super::streams::RunStreams;
pub use model_fit::fit::signals::first_order_lag;

/// A candidate effect of the balance stream, one type per effect.
pub trait BalanceCandidate: Sync + fmt::Debug {
    /// The effect the candidate stands for; `None` for recalibration (G0), which names no new
    /// effect.
    fn effect(&self) -> Option<Effect>;

    /// The experiment that separates this effect from its usual confusers
    /// (docs/diagnosis.md, Effect groups, "separator").
    fn separating_experiment(&self) -> &'static str;

    /// The family's regressors in words, for the report (what the grids below are grids of).
    fn regressors(&self) -> &'static str;

    /// The shapes of the family (every nonlinear parameter on its grid, every discrete choice).
    fn shapes(&self, sample_hz: f64, context: &Context<'_>) -> Vec<Shape>;

    /// Whether the family also holds one gain per angle of attack (the aerodynamic effects, when
    /// the recording has several).
    fn schedulable(&self) -> bool {
        false
    }

    /// Whether the effect keeps the static gain of the sim's path it acts on: a transport delay
    /// and a low-pass "of unit static gain" (docs/spec/diagnosis.md, What each name covers).
    /// Its columns are then the path with the effect less the path without, and their gains
    /// are about one ([`UNIT_GAIN_RANGE`]).
    fn unit_gain(&self) -> bool {
        false
    }

    /// Whether the effect may be named again on the remainder after it was named: the contract
    /// allows several of it at once (one or more structural modes; a delay or a lag per jet).
    fn repeatable(&self) -> bool {
        false
    }

    /// Finer shapes around `best`, a shape of [`shapes`](Self::shapes) that led the coarse grid,
    /// profiled after it (empty: the grid is already fine enough).
    fn refine(&self, _best: &Shape, _sample_hz: f64, _context: &Context<'_>) -> Vec<Shape> {
        Vec::new()
    }

    /// Whether `shape`, the family's best form, lies at an end of what the family profiles
    /// beyond the contract's range of the effect: the data then prefer a form further out, which
    /// is another effect, so the fit is never named
    /// ([`crate::diagnose::attribution::Profiled::plausible`]).
    fn beyond_its_range(&self, _shape: &Shape, _context: &Context<'_>) -> bool {
        false
    }

    /// Whether `beta`, the fitted gains of `shape`'s columns, are the effect the family stands
    /// for and not only columns that happen to span part of the sim's error
    /// ([`crate::diagnose::attribution::Profiled::plausible`]). By default: any gain, or gains
    /// within [`UNIT_GAIN_RANGE`] for an effect that keeps the sim's static gain
    /// ([`Self::unit_gain`]).
    fn admits(&self, _shape: &Shape, beta: &[f64]) -> bool {
        let (low, high) = UNIT_GAIN_RANGE;
        !self.unit_gain() || beta.iter().all(|gain| (low..=high).contains(gain))
    }

    /// The forms `shape` tends to at the ends of its profiled time constant, each of which is
    /// another effect's: the family's best form is named only where it beats every one of them
    /// by decisive evidence ([`crate::diagnose::attribution::Profiled::plausible`]), for
    /// otherwise the data cannot tell the effect from its limits. Empty (the default): the
    /// family's forms have no such limit.
    fn limits(&self, _shape: &Shape, _sample_hz: f64) -> Vec<Shape> {
        Vec::new()
    }

    /// The regression columns of `shape` for run number `run_idx`, one gain each; every column
    /// has the run's length and is zero where the effect cannot act (e.g. no blowing).
    fn columns(&self, shape: &Shape, run: &RunStreams, run_idx: usize, context: &Context<'_>) -> Vec<Vec<f64>>;

    /// The fitted coefficients of the base columns (one group of a scheduled form) as physical
    /// parameters. `columns` are the candidate's columns of every run at its form, `beta` their
    /// coefficients.
    fn params(&self, shape: &Shape, beta: &[f64], context: &Context<'_>, columns: &[Vec<Vec<f64>>]) -> Params;

    /// The effect's name (the vocabulary of docs/spec/diagnosis.md; `recalibration` for G0).
    fn name(&self) -> &'static str {
        self.effect().map_or("recalibration", Effect::name)
    }

    /// The block the effect belongs to (recalibration: the disturbance model's gains).
    fn block(&self) -> Block {
        self.effect().map_or(Block::Disturbance, Effect::block)
    }
}

/// A candidate (every one is a unit type, so a static reference).
pub type Candidate = &'static dyn BalanceCandidate;

/// Range of the gain of an effect that keeps the sim's static gain
/// ([`BalanceCandidate::unit_gain`]): one, within a factor of two. The sim's plant is fitted on
/// the rig's own recordings, so its static gain is known far better than that (the delays and
/// lags named right on both tunnels fitted 0.7 to 1.4); a gain outside it is another effect
/// that the columns happen to span.
pub const UNIT_GAIN_RANGE: (f64, f64) = (0.5, 2.0);

/// Every balance candidate.
pub const ALL: [Candidate; 10] = [
    &ActuatorDelay,
    &ActuatorLag,
    &InertialTare,
    &GravityTare,
    &RollDamping,
    &VortexLag,
    &Coupling,
    &BalanceResonance,
    &BiasDrift,
    &Recalibration,
];

/// Physical parameters of a fitted effect, by name.
pub type Params = Vec<(String, f64)>;

/// One form of a candidate's family: its shape and whether its gains are one per angle of
/// attack.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Form {
    /// Nonlinear parameters and discrete choices.
    pub shape: Shape,
    /// One gain per angle of attack instead of one for all.
    pub per_alpha: bool,
}

/// The nonlinear parameters and discrete choices of a form.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// Nothing to profile: the columns are fixed.
    Fixed,
    /// A weight moment whose sine and cosine parts are the same at every angle of attack, or
    /// each turn with the pitch as `a cos(alpha) + b sin(alpha)` (`pitched`).
    Weight {
        /// Whether the parts turn with the pitch.
        pitched: bool,
    },
    /// A pure delay of one jet or both, alone or followed by a short smoothing.
    Delay {
        /// Delay, s.
        delay_s: f64,
        /// The jets it acts on.
        jets: Jets,
        /// Time constant of a first-order smoothing after the delay, s (0: none).
        smoothing_s: f64,
    },
    /// A pure delay of each jet, each its own (a pneumatic line per jet).
    DelayPerJet {
        /// Delay of the port jet, s.
        port_s: f64,
        /// Delay of the starboard jet, s.
        starboard_s: f64,
    },
    /// A first-order lag of one jet or both.
    Lag {
        /// Time constant, s.
        tau_s: f64,
        /// The jets it acts on.
        jets: Jets,
    },
    /// A second-order low-pass of unit static gain, `1 / (tau^2 s^2 + 2 zeta tau s + 1)`: two
    /// real poles (`zeta >= 1`) or a lightly damped pair.
    SecondOrderLag {
        /// Time constant `1 / omega_n`, s.
        tau_s: f64,
        /// Damping ratio.
        zeta: f64,
        /// The jets it acts on.
        jets: Jets,
    },
    /// A valve whose opening is rate limited: the effective Cmu follows the recorded one at
    /// most as fast as a full stroke in `full_stroke_s`.
    RateLimit {
        /// Time of a stroke from zero to the largest recorded Cmu, s.
        full_stroke_s: f64,
        /// The jets it acts on.
        jets: Jets,
    },
    /// A slower flow state with its drive.
    SlowState {
        /// Time constant, s.
        tau_s: f64,
        /// The physical input driving the new state.
        drive: Drive,
        /// Whether the moment is the state or its deficit from the quasi-steady input.
        law: SlowLaw,
        /// The angles of attack at which the state acts (`None`: at every angle).
        at_alphas: Option<AngleSet>,
    },
    /// A second-order structural mode.
    Mode {
        /// Natural frequency, Hz.
        freq_hz: f64,
        /// Damping ratio.
        zeta: f64,
        /// Corner of the smoother before the acceleration that drives it, Hz
        /// ([`crate::diagnose::streams::MODE_DRIVE_CORNERS_HZ`]).
        drive_corner_hz: f64,
    },
    /// A structural mode rung by a load no input records (buffet, the flow's own unsteadiness):
    /// predicted one sample ahead from the residual's own past through the mode.
    Ringing {
        /// Natural frequency, Hz.
        freq_hz: f64,
        /// Damping ratio.
        zeta: f64,
    },
    /// A rate damping's law.
    Damping {
        /// How the moment grows with the rate.
        law: DampingLaw,
    },
    /// An inertial reaction left in the balance, seen directly or through the balance's own
    /// low-pass, with one gain or one per run (per mounting).
    Tare {
        /// One gain per run instead of one for all.
        per_run: bool,
        /// Corner of the balance's second-order Butterworth low-pass, Hz (`None`: seen
        /// directly).
        corner_hz: Option<f64>,
    },
    /// A disturbance-blowing interaction: its law in Cmu and its lag.
    Interaction {
        /// How the interaction grows with the blowing.
        law: CmuLaw,
        /// Time constant of a first-order lag of the interaction, s (0: instantaneous).
        lag_s: f64,
    },
    /// A smooth trend per run: powers of time up to `degree`.
    Trend {
        /// Highest power of time.
        degree: u8,
    },
    /// A zero that wanders: piecewise linear in time per run.
    Wander {
        /// Spacing of the knots, s.
        knot_spacing_s: f64,
    },
    /// A zero that settles exponentially per run, `1 - exp(-t / tau)`.
    Settle {
        /// Time constant, s.
        tau_s: f64,
    },
    /// A zero that steps: per run, up to `count` steps at the times that fit the training part
    /// best (greedy binary segmentation of the residual).
    Steps {
        /// Steps per run.
        count: u8,
        /// Runs of the recording (every run's step times are profiled).
        runs: u16,
    },
}

/// Which jets an input-path effect acts on: a pneumatic line or valve may be one jet's, or
/// shared.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Jets {
    /// Both jets alike.
    Both,
    /// The port jet only.
    Port,
    /// The starboard jet only.
    Starboard,
}

impl Jets {
    /// The jet choices a recording supports: one jet alone only when both jets blow.
    #[must_use]
    pub fn choices(context: &Context<'_>) -> &'static [Self] {
        if context.two_jets { &[Self::Both, Self::Port, Self::Starboard] } else { &[Self::Both] }
    }

    /// The choice's name in reports.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Both => "both",
            Self::Port => "port",
            Self::Starboard => "starboard",
        }
    }

    /// The recorded Cmu of both jets with `modify` applied to the chosen ones.
    #[must_use]
    pub fn apply(self, cmu: &[Vec<f64>; 2], modify: impl Fn(&[f64]) -> Vec<f64>) -> [Vec<f64>; 2] {
        let acts = |side: usize| match self {
            Self::Both => true,
            Self::Port => side == 0,
            Self::Starboard => side == 1,
        };
        [0, 1].map(|side| if acts(side) { modify(&cmu[side]) } else { cmu[side].clone() })
    }
}

/// How a disturbance-blowing interaction grows with the blowing: linearly in Cmu, or in its
/// square root (the jet's velocity ratio, which sets the circulation change of a Coanda jet;
/// Englar 1975 for the circulation control's lift in sqrt(Cmu)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CmuLaw {
    /// In Cmu.
    Linear,
    /// In sqrt(Cmu).
    SquareRoot,
}

impl CmuLaw {
    /// The law's name in reports.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Linear => "linear",
            Self::SquareRoot => "square_root",
        }
    }
}

/// How a rate damping grows with the reduced roll rate `p_hat`: the linear derivative, or the
/// quadratic `p_hat |p_hat|` of separated, high-incidence flow (Elzebda, Nayfeh & Mook, J.
/// Aircraft 26(8), 1989; docs/equations.md, Slender-wing roll moment forms).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DampingLaw {
    /// `C_l,p p_hat`.
    Linear,
    /// `C_l,p|p| p_hat |p_hat|`.
    Quadratic,
    /// `C_l,p3 p_hat^3` (a damping that stiffens with the rate, odd in it).
    Cubic,
}

impl DampingLaw {
    /// The law's name in reports.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Linear => "linear",
            Self::Quadratic => "quadratic",
            Self::Cubic => "cubic",
        }
    }
}

/// How a second flow state `x` (`tau x' + x = u`) acts on the moment: as itself, `K x`, or
/// as its deficit from the quasi-steady value of its drive, `K (x - u)` (the flow lags what the
/// motion would give at rest: a moment that vanishes in steady motion).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlowLaw {
    /// `K x`.
    State,
    /// `K (x - u)`.
    Deficit,
}

impl SlowLaw {
    /// The law's name in reports.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::State => "state",
            Self::Deficit => "deficit",
        }
    }
}

/// What drives a second flow state (one at a time: the lags of the sideslip and of the rate
/// together span the roll angle itself, a static moment, not a lag).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Drive {
    /// The sideslip that rolling at incidence makes, `asin(sin alpha sin phi)`.
    Sideslip,
    /// The reduced roll rate `p b / (2 U)`.
    RollRate,
    /// The roll angle itself, one gain at every angle of attack (a state that follows the
    /// attitude, not the sideslip it makes at incidence).
    RollAngle,
    /// The vortex state itself, as the eGK's moment shows it (the contract's "driven ... by the
    /// vortex state itself": a slower state of the half-wings' lift that follows the fast one).
    VortexState,
}

impl Drive {
    /// Every drive of the slow state.
    pub const ALL: [Self; 4] = [Self::Sideslip, Self::RollRate, Self::RollAngle, Self::VortexState];
}

impl Drive {
    /// The drive's name in reports.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Sideslip => "sideslip",
            Self::RollRate => "roll_rate",
            Self::RollAngle => "roll_angle",
            Self::VortexState => "vortex_state",
        }
    }
}

/// A form's parameter in a report: a number or a choice.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FormValue {
    /// A number (a profiled parameter, a degree, a spacing).
    Number(f64),
    /// A discrete choice.
    Choice(&'static str),
    /// A flag.
    Flag(bool),
    /// Some of the recording's angles of attack.
    Angles(AngleSet),
}

/// Where `alpha_deg` stands among the recording's angles `alphas_deg` (`None`: not among them).
fn alpha_slot(alphas_deg: &[f64], alpha_deg: f64) -> Option<usize> {
    alphas_deg.iter().position(|alpha| (alpha - alpha_deg).abs() < 1e-6)
}

/// A set of the recording's angles of attack, as bits over [`Context::alphas_deg`] (ascending):
/// where an effect that does not act at every angle acts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AngleSet(u16);

impl AngleSet {
    /// Most angles a set can name (the bits of its mask).
    pub const CAPACITY: usize = 16;

    /// Every set of `n` angles but the empty and the full one, when there are at most
    /// `every_set_up_to` angles; beyond that, every band of neighbouring angles but all of them
    /// (`n (n + 1) / 2 - 1` sets instead of `2^n - 2`).
    #[must_use]
    pub fn proper_sets(n: usize, every_set_up_to: usize) -> Vec<Self> {
        let n = n.min(Self::CAPACITY);
        let full = ((1u32 << n) - 1) as u16;
        let mut masks: Vec<u16> = if n <= every_set_up_to {
            (1..full).collect()
        } else {
            (0..n)
                .flat_map(|low| (low..n).map(move |high| ((1u32 << (high + 1)) - (1u32 << low)) as u16))
                .filter(|mask| *mask != full)
                .collect()
        };
        masks.sort_unstable();
        masks.into_iter().map(Self).collect()
    }

    /// Whether the set holds the angle `alpha_deg` of `alphas_deg` (false for an angle not among
    /// them).
    #[must_use]
    pub fn holds(self, alpha_deg: f64, alphas_deg: &[f64]) -> bool {
        alpha_slot(alphas_deg, alpha_deg).is_some_and(|slot| slot < Self::CAPACITY && self.0 & (1 << slot) != 0)
    }

    /// The angles of the set, deg, ascending.
    #[must_use]
    pub fn angles_deg(self, alphas_deg: &[f64]) -> Vec<f64> {
        alphas_deg
            .iter()
            .take(Self::CAPACITY)
            .enumerate()
            .filter(|(slot, _)| self.0 & (1 << slot) != 0)
            .map(|(_, a)| *a)
            .collect()
    }
}

impl fmt::Display for FormValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Number(value) => write!(f, "{value:.4}"),
            Self::Choice(choice) => f.write_str(choice),
            Self::Flag(flag) => write!(f, "{flag}"),
            Self::Angles(set) => write!(f, "angle set {:#06x}", set.0),
        }
    }
}

impl FormValue {
    /// As JSON (a non-finite number is `null`; a set of angles, its angles out of the
    /// recording's `alphas_deg`).
    #[must_use]
    pub fn to_json(self, alphas_deg: &[f64]) -> serde_json::Value {
        match self {
            Self::Number(value) => serde_json::json!(value.is_finite().then_some(value)),
            Self::Choice(choice) => serde_json::json!(choice),
            Self::Flag(flag) => serde_json::json!(flag),
            Self::Angles(set) => serde_json::json!(set.angles_deg(alphas_deg)),
        }
    }
}

impl Form {
    /// How many continuous parameters the form profiles on its grid (they count in the
    /// complexity penalty; discrete choices count through their columns).
    #[must_use]
    pub const fn n_profiled(&self) -> usize {
        match self.shape {
            Shape::Fixed
            | Shape::Weight { .. }
            | Shape::Damping { .. }
            | Shape::Trend { .. }
            | Shape::Wander { .. } => 0,
            Shape::Lag { .. } | Shape::RateLimit { .. } | Shape::Settle { .. } => 1,
            Shape::Delay { smoothing_s, .. } => 1 + (smoothing_s > 0.0) as usize,
            Shape::DelayPerJet { .. } => 2,
            Shape::SecondOrderLag { .. } => 2,
            Shape::SlowState { at_alphas, .. } => 1 + at_alphas.is_some() as usize,
            Shape::Tare { corner_hz, .. } => corner_hz.is_some() as usize,
            Shape::Interaction { lag_s, .. } => (lag_s > 0.0) as usize,
            // Every step's time is profiled, in every run.
            Shape::Steps { count, runs } => count as usize * runs as usize,
            Shape::Mode { .. } => 3,
            Shape::Ringing { .. } => 2,
        }
    }

    /// The first profiled parameter, for the report's profile plot.
    #[must_use]
    pub const fn coordinate(&self) -> Option<(&'static str, f64)> {
        match self.shape {
            Shape::Fixed | Shape::Weight { .. } | Shape::Damping { .. } | Shape::Steps { .. } => None,
            Shape::Delay { delay_s, .. } => Some(("delay_s", delay_s)),
            Shape::DelayPerJet { port_s, starboard_s, .. } => Some(("delay_s", port_s.max(starboard_s))),
            Shape::Lag { tau_s, .. }
            | Shape::SecondOrderLag { tau_s, .. }
            | Shape::SlowState { tau_s, .. }
            | Shape::Settle { tau_s } => Some(("tau_s", tau_s)),
            Shape::RateLimit { full_stroke_s, .. } => Some(("full_stroke_s", full_stroke_s)),
            Shape::Mode { freq_hz, .. } | Shape::Ringing { freq_hz, .. } => Some(("freq_hz", freq_hz)),
            Shape::Tare { corner_hz, .. } => match corner_hz {
                Some(corner_hz) => Some(("corner_hz", corner_hz)),
                None => None,
            },
            Shape::Interaction { lag_s, .. } => Some(("lag_s", lag_s)),
            Shape::Trend { degree } => Some(("degree", degree as f64)),
            Shape::Wander { knot_spacing_s } => Some(("knot_spacing_s", knot_spacing_s)),
        }
    }

    /// The form's parameters and choices by name, for the report and the JSON.
    #[must_use]
    pub fn entries(&self) -> Vec<(&'static str, FormValue)> {
        let mut out = match self.shape {
            Shape::Fixed => Vec::new(),
            Shape::Weight { pitched } => vec![("pitched", FormValue::Flag(pitched))],
            Shape::Damping { law } => vec![("law", FormValue::Choice(law.name()))],
            Shape::Delay { delay_s, jets, smoothing_s } => vec![
                ("delay_s", FormValue::Number(delay_s)),
                ("jets", FormValue::Choice(jets.name())),
                ("smoothing_s", FormValue::Number(smoothing_s)),
            ],
            // The longer delay is the effect's `delay_s`, as a delay of one jet names that jet's.
            Shape::DelayPerJet { port_s, starboard_s } => vec![
                ("delay_s", FormValue::Number(port_s.max(starboard_s))),
                ("delay_port_s", FormValue::Number(port_s)),
                ("delay_stbd_s", FormValue::Number(starboard_s)),
                ("jets", FormValue::Choice("each")),
            ],
            Shape::Lag { tau_s, jets } => {
                vec![
                    ("tau_s", FormValue::Number(tau_s)),
                    ("jets", FormValue::Choice(jets.name())),
                    ("order", FormValue::Number(1.0)),
                ]
            }
            Shape::SecondOrderLag { tau_s, zeta, jets } => vec![
                ("tau_s", FormValue::Number(tau_s)),
                ("zeta", FormValue::Number(zeta)),
                ("jets", FormValue::Choice(jets.name())),
                ("order", FormValue::Number(2.0)),
            ],
            Shape::RateLimit { full_stroke_s, jets } => {
                vec![("full_stroke_s", FormValue::Number(full_stroke_s)), ("jets", FormValue::Choice(jets.name()))]
            }
            Shape::SlowState { tau_s, drive, law, at_alphas } => {
                let mut entries = vec![
                    ("tau_s", FormValue::Number(tau_s)),
                    ("drive", FormValue::Choice(drive.name())),
                    ("law", FormValue::Choice(law.name())),
                ];
                if let Some(set) = at_alphas {
                    entries.push(("at_alpha_deg", FormValue::Angles(set)));
                }
                entries
            }
            Shape::Mode { freq_hz, zeta, drive_corner_hz } => vec![
                ("freq_hz", FormValue::Number(freq_hz)),
                ("zeta", FormValue::Number(zeta)),
                ("drive_corner_hz", FormValue::Number(drive_corner_hz)),
            ],
            Shape::Ringing { freq_hz, zeta } => vec![
                ("freq_hz", FormValue::Number(freq_hz)),
                ("zeta", FormValue::Number(zeta)),
                ("drive", FormValue::Choice("unrecorded")),
            ],
            Shape::Tare { per_run, corner_hz } => {
                let mut entries = vec![("per_run", FormValue::Flag(per_run))];
                if let Some(corner_hz) = corner_hz {
                    entries.push(("corner_hz", FormValue::Number(corner_hz)));
                }
                entries
            }
            Shape::Interaction { law, lag_s } => {
                vec![("cmu_law", FormValue::Choice(law.name())), ("lag_s", FormValue::Number(lag_s))]
            }
            Shape::Trend { degree } => vec![("degree", FormValue::Number(f64::from(degree)))],
            Shape::Wander { knot_spacing_s } => vec![("knot_spacing_s", FormValue::Number(knot_spacing_s))],
            Shape::Settle { tau_s } => vec![("settle_tau_s", FormValue::Number(tau_s))],
            Shape::Steps { count, .. } => vec![("steps_per_run", FormValue::Number(f64::from(count)))],
        };
        if self.per_alpha {
            out.push(("per_alpha", FormValue::Flag(true)));
        }
        out
    }
}

/// Every form of `candidate`'s family: its shapes, each also with one gain per angle of attack
/// where the family is scheduled and the recording has several angles. Within a family the form
/// is chosen by its complexity-penalised evidence, not by its fit alone.
#[must_use]
pub fn forms(candidate: Candidate, sample_hz: f64, context: &Context<'_>) -> Vec<Form> {
    let scheduled = candidate.schedulable() && context.alphas_deg.len() >= 2;
    candidate
        .shapes(sample_hz, context)
        .into_iter()
        .flat_map(|shape| {
            let one = Form { shape, per_alpha: false };
            let per_alpha = Form { shape, per_alpha: true };
            if scheduled { vec![one, per_alpha] } else { vec![one] }
        })
        .collect()
}

/// What `candidate`'s family searched on this recording, for the report: how many forms, and
/// every parameter of its forms with its range (numbers: least, greatest and how many values)
/// or its choices.
#[must_use]
pub fn family_summary(candidate: Candidate, sample_hz: f64, context: &Context<'_>) -> (usize, String) {
    let forms = forms(candidate, sample_hz, context);
    let mut numbers: BTreeMap<&'static str, Vec<f64>> = BTreeMap::new();
    let mut choices: BTreeMap<&'static str, Vec<String>> = BTreeMap::new();
    let mut angle_sets: BTreeMap<&'static str, Vec<AngleSet>> = BTreeMap::new();
    for form in &forms {
        for (name, value) in form.entries().into_iter().filter(|(name, _)| *name != "per_alpha") {
            match value {
                FormValue::Number(x) => numbers.entry(name).or_default().push(x),
                FormValue::Angles(set) => {
                    let seen = angle_sets.entry(name).or_default();
                    if !seen.contains(&set) {
                        seen.push(set);
                    }
                }
                other => {
                    let text = other.to_string();
                    let seen = choices.entry(name).or_default();
                    if !seen.contains(&text) {
                        seen.push(text);
                    }
                }
            }
        }
    }
    let mut parts: Vec<String> = vec![candidate.regressors().to_owned()];
    parts.extend(numbers.into_iter().map(|(name, mut values)| {
        values.sort_by(f64::total_cmp);
        values.dedup();
        let (low, high) = (values.first().copied().unwrap_or(0.0), values.last().copied().unwrap_or(0.0));
        if values.len() == 1 {
            format!("{name} {low:.4}")
        } else {
            format!("{name} {low:.4} to {high:.4} ({} values)", values.len())
        }
    }));
    parts.extend(choices.into_iter().map(|(name, values)| format!("{name}: {}", values.join(" or "))));
    parts.extend(angle_sets.into_iter().map(|(name, sets)| {
        format!("{name}: every angle or {} sets of them (of {:?})", sets.len(), context.alphas_deg)
    }));
    if forms.first().is_some_and(|form| !candidate.refine(&form.shape, sample_hz, context).is_empty()) {
        parts.push("the leading forms refined on a finer grid of the same parameters".into());
    }
    if candidate.repeatable() {
        parts.push("may be named again on the remainder (several at once)".into());
    }
    if candidate.schedulable() && context.alphas_deg.len() < 2 {
        parts.push("one gain (one angle of attack)".into());
    } else if candidate.schedulable() {
        parts.push("one gain for all angles or one per angle".into());
    }
    (forms.len(), parts.join("; "))
}

/// The regression columns of `candidate` in `form` for run number `run_idx`; with one gain per
/// angle of attack, each base column is repeated per alpha and zero at the other alphas.
#[must_use]
pub fn columns(
    candidate: Candidate,
    form: &Form,
    run: &RunStreams,
    run_idx: usize,
    context: &Context<'_>,
) -> Vec<Vec<f64>> {
    let base = candidate.columns(&form.shape, run, run_idx, context);
    if !form.per_alpha {
        return base;
    }
    let n = run.len();
    let group = alpha_slot(&context.alphas_deg, run.alpha_deg);
    let mut out = Vec::with_capacity(base.len() * context.alphas_deg.len());
    for column in base {
        for slot in 0..context.alphas_deg.len() {
            out.push(if Some(slot) == group { column.clone() } else { vec![0.0; n] });
        }
    }
    out
}

/// The fitted coefficients of `candidate` in `form` as physical parameters, with the form's
/// own parameters; with one gain per angle of attack every gain is reported per alpha
/// (`clp@20`). `columns` are the candidate's columns of every run at its form.
#[must_use]
pub fn physical_params(
    candidate: Candidate,
    form: &Form,
    beta: &[f64],
    context: &Context<'_>,
    columns: &[Vec<Vec<f64>>],
) -> BTreeMap<String, serde_json::Value> {
    let mut out: BTreeMap<String, serde_json::Value> = form
        .entries()
        .into_iter()
        .filter(|(name, _)| *name != "per_alpha")
        .map(|(name, value)| (name.to_owned(), value.to_json(&context.alphas_deg)))
        .collect();
    let number = |value: f64| serde_json::json!(value.is_finite().then_some(value));
    if form.per_alpha {
        let groups = context.alphas_deg.len().max(1);
        for (group, alpha) in context.alphas_deg.iter().enumerate() {
            // Base column `c` of group `g` is column `c * groups + g`.
            let group_beta: Vec<f64> = beta.iter().skip(group).step_by(groups).copied().collect();
            for (name, value) in candidate.params(&form.shape, &group_beta, context, columns) {
                out.insert(format!("{name}@{alpha}"), number(value));
            }
        }
    } else {
        for (name, value) in candidate.params(&form.shape, beta, context, columns) {
            out.insert(name, number(value));
        }
    }
    out
}

/// The shortest time constant of a slower flow state, s: twice the eGK's lag ("2 to 50 times
/// slower than the eGK's lag", docs/spec/diagnosis.md), at least 50 ms. The eGK's lag is read
/// at the recorded angle of attack where its vortex state carries the most moment (the largest
/// `|K_v|`): there the fit identifies it. Where the vortices hardly move the moment, the fit
/// keeps its prior lag, which says nothing of the rig's flow (a prior of 0.18 s at low angles,
/// beside one of 36 ms fitted where the vortices act, would put the floor at 0.35 s).
#[must_use]
pub fn slow_tau_min_s(set: &CoefficientSet, alphas_deg: impl Iterator<Item = f64>) -> f64 {
    alphas_deg
        .map(|alpha_deg| estimator_core::egk::params_at(set, alpha_deg as f32))
        .max_by(|a, b| a.vortex_gain.abs().total_cmp(&b.vortex_gain.abs()))
        .map_or(SLOW_TAU_MIN_S, |params| (2.0 * f64::from(params.tau1_s)).max(SLOW_TAU_MIN_S))
}

/// The least of [`slow_tau_min_s`], s: no rig's second flow state is faster.
const SLOW_TAU_MIN_S: f64 = 0.05;

/// Names each coefficient in order (the gains of candidates whose columns are their parameters).
fn gains(names: &[&str], beta: &[f64]) -> Params {
    names.iter().zip(beta).map(|(name, value)| ((*name).to_owned(), *value)).collect()
}

/// `n` points spaced logarithmically from `low` to `high`.
#[must_use]
pub fn log_grid(low: f64, high: f64, n: usize) -> Vec<f64> {
    if n < 2 {
        return vec![low];
    }
    let ratio = (high / low).ln() / (n - 1) as f64;
    (0..n).map(|idx| low * (ratio * idx as f64).exp()).collect()
}

/// `n` points spaced logarithmically between the neighbours of `value` on a logarithmic grid
/// whose ratio between points is `step_ratio` (a refinement of one coarse cell either side).
pub(crate) fn around(value: f64, step_ratio: f64, n: usize, low: f64, high: f64) -> Vec<f64> {
    log_grid((value / step_ratio).max(low), (value * step_ratio).min(high), n)
}

/// The ratio between neighbours of `log_grid(low, high, n)`.
pub(crate) fn grid_ratio(low: f64, high: f64, n: usize) -> f64 {
    (high / low).powf(1.0 / (n.max(2) - 1) as f64)
}

/// What the regressors need besides the run itself.
#[derive(Debug, Clone)]
pub struct Context<'a> {
    /// The sim's coefficient set (the plant is re-run on modified Cmu).
    pub set: &'a CoefficientSet,
    /// `q S b`, N m per unit C_l.
    pub moment_scale_nm: f64,
    /// `b / (2 U)`, s.
    pub half_span_time_s: f64,
    /// Largest recorded Cmu of the dataset (scales the coupling terms).
    pub cmu_ref: f64,
    /// Number of runs (per-run columns).
    pub n_runs: usize,
    /// Shortest time constant of the vortex-lag candidate, s ([`slow_tau_min_s`]): twice the
    /// sim's own eGK lag, so that the candidate is a slower state, not the eGK's (or a rate
    /// damping) again.
    pub slow_tau_min_s: f64,
    /// Lowest natural frequency of the balance-resonance candidate, Hz ([`resonance_min_hz`]).
    pub resonance_min_hz: f64,
    /// Peaks of the balance residual's spectrum that the resonance family adds to its grid,
    /// Hz ([`resonance_seeds_hz`]).
    pub resonance_seeds_hz: Vec<f64>,
    /// The recording's angles of attack, deg, ascending (the groups of a per-alpha gain).
    pub alphas_deg: Vec<f64>,
    /// Duration of the longest run, s (the drift's knots).
    pub longest_run_s: f64,
    /// Whether both jets blow somewhere in the recording (an effect of one jet alone can be
    /// told from one of both).
    pub two_jets: bool,
}

impl Context<'_> {
    /// The reduced roll rate `p b / (2 U)` of a run.
    fn p_hat(&self, run: &RunStreams) -> Vec<f64> {
        run.phi_dot_rad_s.iter().map(|rate| rate * self.half_span_time_s).collect()
    }
}

/// Lowest frequency the balance-resonance candidate may take, Hz: an octave above the motion's
/// band, twice the frequency below which 99 % of the roll angle's variance lies (Welch PSD over
/// the training parts of the rolling runs), and at least 2 Hz.
///
/// Why: below its natural frequency a mode driven by the load and the motion responds as their
/// second derivatives scaled, so a "mode" inside or at the edge of the motion's band is an
/// acceleration-like filter of the moment that can absorb an inertial tare or any structural
/// error of the sim; it cannot be told from them. A balance built for dynamic tests has its
/// first mode well above the motion it measures, or it would distort every reading the test is
/// for. A mode that is really inside the band is left to the other candidates, or to
/// `unattributed`.
#[must_use]
pub fn resonance_min_hz(runs: &[RunStreams]) -> f64 {
    const FLOOR_HZ: f64 = 2.0;
    // A missing sample counts as zero: a few of them barely move a spectrum.
    let cleaned: Vec<Vec<f64>> = runs
        .iter()
        .filter(|run| run.rolls())
        .map(|run| run.phi_rad[run.training.clone()].iter().map(|v| if v.is_finite() { *v } else { 0.0 }).collect())
        .collect();
    let segments: Vec<&[f64]> = cleaned.iter().map(Vec::as_slice).collect();
    let Some(sample_hz) = runs.first().map(|run| run.sample_hz) else { return FLOOR_HZ };
    let shortest = segments.iter().map(|segment| segment.len()).min().unwrap_or(0);
    // Windows of about 4 s (0.25 Hz bins), shorter for short runs.
    let window = ((4.0 * sample_hz) as usize).min(shortest / 2).max(4);
    let Some(spectrum) = crate::diagnose::ledger::welch_psd(&segments, sample_hz, window) else { return FLOOR_HZ };
    let total: f64 = spectrum.psd.iter().sum();
    if total.is_nan() || total <= 0.0 {
        return FLOOR_HZ;
    }
    let mut cumulative = 0.0;
    for (freq_hz, power) in spectrum.freq_hz.iter().zip(&spectrum.psd) {
        cumulative += power;
        if cumulative >= 0.99 * total {
            return (2.0 * freq_hz).max(FLOOR_HZ);
        }
    }
    FLOOR_HZ
}

/// `a - b`, element by element.
fn difference(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x - y).collect()
}

/// A context for the candidates' unit tests: the built-in coefficient set, `q S b` 2 N m, `b /
/// (2 U)` 0.01 s, two runs at 0 and 20 deg.
#[cfg(test)]
pub(crate) fn test_context() -> Context<'static> {
    Context {
        set: &estimator_core::coeffs::BUILT_IN,
        moment_scale_nm: 2.0,
        half_span_time_s: 0.01,
        cmu_ref: 0.02,
        n_runs: 2,
        slow_tau_min_s: 0.1,
        resonance_min_hz: 4.0,
        resonance_seeds_hz: Vec::new(),
        alphas_deg: vec![0.0, 20.0],
        longest_run_s: 10.0,
        two_jets: true,
    }
}

/// Least squares of `target` on `columns` (normal equations solved by SVD, for the candidates'
/// unit tests: the minimum-norm solution where a test run makes two columns proportional, as
/// a roll angle and an eGK moment that is a multiple of it).
#[cfg(test)]
pub(crate) fn test_fit(columns: &[Vec<f64>], target: &[f64]) -> Vec<f64> {
    let k = columns.len();
    let gram: nalgebra::DMatrix<f64> =
        nalgebra::DMatrix::from_fn(k, k, |i, j| columns[i].iter().zip(&columns[j]).map(|(a, b)| a * b).sum());
    let rhs = nalgebra::DVector::from_fn(k, |i, _| columns[i].iter().zip(target).map(|(a, b)| a * b).sum());
    let scale = gram.diagonal().max().max(f64::MIN_POSITIVE);
    gram.svd(true, true).solve(&rhs, 1e-12 * scale).expect("both factors computed").iter().copied().collect()
}

/// What is left of `target` after `columns` times `beta`, as a sum of squares (for the
/// candidates' unit tests).
#[cfg(test)]
pub(crate) fn test_left(columns: &[Vec<f64>], beta: &[f64], target: &[f64]) -> f64 {
    (0..target.len()).map(|i| (target[i] - columns.iter().zip(beta).map(|(c, b)| c[i] * b).sum::<f64>()).powi(2)).sum()
}

/// [`test_fit`] of every run's columns, stacked run after run as `target` is: what is left (as
/// [`test_left`]) and the coefficients.
#[cfg(test)]
pub(crate) fn test_fit_runs(per_run: &[Vec<Vec<f64>>], target: &[f64]) -> (f64, Vec<f64>) {
    let columns: Vec<Vec<f64>> =
        (0..per_run[0].len()).map(|c| per_run.iter().flat_map(|cols| cols[c].clone()).collect()).collect();
    let beta = test_fit(&columns, target);
    (test_left(&columns, &beta, target), beta)
}

#[cfg(test)]
mod tests;

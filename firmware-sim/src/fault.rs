//! Sensor fault injection on the estimator's inputs, shared by the SIL harness and the host
//! replays: a pressure channel stuck, dead (NaN), biased or spiking; the balance or the roll
//! encoder dropping samples; the blowing measurement missing.
//!
//! A fault is written as `KIND:CHANNEL[=VALUE][@START]`, `START` in seconds from the start of
//! the run (default 0, an optional `s` suffix):
//!
//! | spec | effect from `START` on |
//! | --- | --- |
//! | `stuck:cp07@10s` | `cp07` holds the value it had at `START` |
//! | `dead:cp03@5s` | `cp03` reads NaN |
//! | `bias:cp02=0.3@5s` | `cp02` reads 0.3 (Cp) too high |
//! | `spike:cp09=2.0@5s` | `cp09` reads 2.0 (Cp) too high at `START`, then at random samples, 10 per second on average |
//! | `drop:cl=0.2` | the balance's `C_l` is missing (NaN) in 20 % of the samples, at random |
//! | `drop:phi=0.2` | the roll encoder's angle is missing in 20 % of the samples, at random |
//! | `missing:cmu` | both blowing measurements read NaN |
//!
//! Random choices come from a ChaCha stream of the injector's seed, so a faulty replay is as
//! reproducible as a clean one.
//!
//! # Examples
//!
//! ```
//! use firmware_sim::fault::{FaultInjector, FaultSpec};
//! use estimator_core::Input;
//!
//! let spec: FaultSpec = "bias:cp02=0.3@0.5s".parse().unwrap();
//! let mut injector = FaultInjector::new(&[spec], 1000.0, 7);
//! let mut input = Input { phi_deg: 0.0, alpha_deg: 10.0, cmu_port: 0.0, cmu_stbd: 0.0, cp: [-0.5; 12] };
//! let mut balance_cl = 0.01;
//! injector.apply(1.0, &mut input, &mut balance_cl);
//! assert!((input.cp[1] - -0.2).abs() < 1e-6);
//! ```

use std::fmt;
use std::str::FromStr;

use estimator_core::Input;
use estimator_core::coeffs::N_TAPS;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Mean rate of the spikes of a spiking channel after the first one, per second.
pub const SPIKE_RATE_HZ: f64 = 10.0;

/// What fails and how.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultKind {
    /// Pressure channel `tap` (0-based) holds its value at the onset.
    Stuck {
        /// The channel, 0-based (`cp01` is 0).
        tap: usize,
    },
    /// Pressure channel `tap` reads NaN.
    Dead {
        /// The channel, 0-based.
        tap: usize,
    },
    /// Pressure channel `tap` reads `offset` too high.
    Bias {
        /// The channel, 0-based.
        tap: usize,
        /// Offset, Cp.
        offset: f64,
    },
    /// Pressure channel `tap` reads `amplitude` too high at the onset, then at random samples
    /// ([`SPIKE_RATE_HZ`]).
    Spike {
        /// The channel, 0-based.
        tap: usize,
        /// Spike height, Cp.
        amplitude: f64,
    },
    /// The balance drops a share of its samples (NaN `C_l`).
    DropBalance {
        /// Share of the samples dropped, 0..=1.
        fraction: f64,
    },
    /// The roll encoder drops a share of its samples (NaN roll angle).
    DropRoll {
        /// Share of the samples dropped, 0..=1.
        fraction: f64,
    },
    /// The blowing measurement is missing (NaN Cmu of both jets).
    MissingCmu,
}

/// One fault and when it starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultSpec {
    /// What fails.
    pub kind: FaultKind,
    /// Onset, s from the start of the run.
    pub start_s: f64,
}

/// Why a fault spec could not be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("fault `{spec}`: {reason}")]
pub struct FaultSpecError {
    /// The spec as given.
    pub spec: String,
    /// What is wrong, and what is expected.
    pub reason: String,
}

/// Applies a set of faults to the inputs of consecutive samples.
#[derive(Debug, Clone)]
pub struct FaultInjector {
    specs: Vec<FaultSpec>,
    /// Probability of a spike at one sample after the first.
    spike_probability: f64,
    /// The value a stuck channel holds, once its fault has started.
    held_cp: [Option<f32>; N_TAPS],
    /// Whether a spiking channel has had its first (onset) spike.
    spiked: [bool; N_TAPS],
    rng: ChaCha8Rng,
}

impl FaultSpec {
    /// The pressure channel this fault affects (0-based), if any.
    #[must_use]
    pub const fn tap(&self) -> Option<usize> {
        match self.kind {
            FaultKind::Stuck { tap } | FaultKind::Dead { tap } => Some(tap),
            FaultKind::Bias { tap, .. } | FaultKind::Spike { tap, .. } => Some(tap),
            _ => None,
        }
    }

    /// The kind's name as written in a spec (`stuck`, `dead`, `bias`, `spike`, `drop`,
    /// `missing`).
    #[must_use]
    pub const fn kind_name(&self) -> &'static str {
        match self.kind {
            FaultKind::Stuck { .. } => "stuck",
            FaultKind::Dead { .. } => "dead",
            FaultKind::Bias { .. } => "bias",
            FaultKind::Spike { .. } => "spike",
            FaultKind::DropBalance { .. } | FaultKind::DropRoll { .. } => "drop",
            FaultKind::MissingCmu => "missing",
        }
    }
}

impl fmt::Display for FaultSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.kind {
            FaultKind::Stuck { tap } => write!(f, "stuck:cp{:02}", tap + 1)?,
            FaultKind::Dead { tap } => write!(f, "dead:cp{:02}", tap + 1)?,
            FaultKind::Bias { tap, offset } => write!(f, "bias:cp{:02}={offset}", tap + 1)?,
            FaultKind::Spike { tap, amplitude } => write!(f, "spike:cp{:02}={amplitude}", tap + 1)?,
            FaultKind::DropBalance { fraction } => write!(f, "drop:cl={fraction}")?,
            FaultKind::DropRoll { fraction } => write!(f, "drop:phi={fraction}")?,
            FaultKind::MissingCmu => write!(f, "missing:cmu")?,
        }
        write!(f, "@{}s", self.start_s)
    }
}

impl FromStr for FaultSpec {
    type Err = FaultSpecError;

    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        let fail = |reason: &str| FaultSpecError { spec: spec.to_owned(), reason: reason.to_owned() };
        let (body, start_s) = match spec.split_once('@') {
            Some((body, start)) => {
                let start = start.trim().strip_suffix('s').unwrap_or(start.trim());
                let start_s: f64 =
                    start.parse().map_err(|_| fail("the onset after `@` must be seconds, e.g. `@5s`"))?;
                if !(start_s.is_finite() && start_s >= 0.0) {
                    return Err(fail("the onset must be a finite time of at least 0 s"));
                }
                (body, start_s)
            }
            None => (spec, 0.0),
        };
        let (kind, target) = body.split_once(':').ok_or_else(|| fail("expected KIND:CHANNEL, e.g. `dead:cp03`"))?;
        let (channel, value) = match target.split_once('=') {
            Some((channel, value)) => {
                let value: f64 = value.trim().parse().map_err(|_| fail("the value after `=` must be a number"))?;
                if !value.is_finite() {
                    return Err(fail("the value after `=` must be finite"));
                }
                (channel.trim(), Some(value))
            }
            None => (target.trim(), None),
        };
        let kind = parse_kind(kind.trim(), channel, value).map_err(|reason| fail(&reason))?;
        Ok(Self { kind, start_s })
    }
}

/// The fault of `kind` on `channel` with the optional `value`.
fn parse_kind(kind: &str, channel: &str, value: Option<f64>) -> Result<FaultKind, String> {
    let tap = || parse_tap(channel);
    let needs = |what: &str| value.ok_or_else(|| format!("`{kind}` needs `={what}`"));
    let none = |fault: FaultKind| if value.is_some() { Err(format!("`{kind}` takes no value")) } else { Ok(fault) };
    match (kind, channel) {
        ("stuck", _) => none(FaultKind::Stuck { tap: tap()? }),
        ("dead", _) => none(FaultKind::Dead { tap: tap()? }),
        ("bias", _) => Ok(FaultKind::Bias { tap: tap()?, offset: needs("OFFSET_CP")? }),
        ("spike", _) => Ok(FaultKind::Spike { tap: tap()?, amplitude: needs("AMPLITUDE_CP")? }),
        ("drop", "cl" | "phi") => {
            let fraction = needs("FRACTION")?;
            if !(0.0..=1.0).contains(&fraction) {
                return Err("the dropped fraction must be in [0, 1]".into());
            }
            Ok(if channel == "cl" { FaultKind::DropBalance { fraction } } else { FaultKind::DropRoll { fraction } })
        }
        ("drop", _) => Err("`drop` applies to `cl` (the balance) or `phi` (the roll encoder)".into()),
        ("missing", "cmu") => none(FaultKind::MissingCmu),
        ("missing", _) => Err("`missing` applies to `cmu` (the blowing measurement)".into()),
        _ => Err("unknown kind; expected stuck, dead, bias, spike, drop or missing".into()),
    }
}

/// `cp01`..`cp12` to 0..=11.
fn parse_tap(channel: &str) -> Result<usize, String> {
    channel
        .strip_prefix("cp")
        .and_then(|digits| digits.parse::<usize>().ok())
        .filter(|number| (1..=N_TAPS).contains(number))
        .map(|number| number - 1)
        .ok_or_else(|| format!("expected a pressure channel cp01..cp{N_TAPS}, found `{channel}`"))
}

impl FaultInjector {
    /// An injector for `specs` at `sample_hz`, its random choices seeded by `seed`.
    #[must_use]
    pub fn new(specs: &[FaultSpec], sample_hz: f64, seed: u64) -> Self {
        let spike_probability = if sample_hz > 0.0 { (SPIKE_RATE_HZ / sample_hz).min(1.0) } else { 0.0 };
        Self {
            specs: specs.to_vec(),
            spike_probability,
            held_cp: [None; N_TAPS],
            spiked: [false; N_TAPS],
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// True when there is nothing to inject.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.specs.is_empty()
    }

    /// Applies every fault that has started by `t_s` to the sample's estimator `input` and
    /// balance reading `balance_cl`. Call once per sample, in order.
    pub fn apply(&mut self, t_s: f64, input: &mut Input, balance_cl: &mut f64) {
        for spec in &self.specs {
            if t_s < spec.start_s {
                continue;
            }
            match spec.kind {
                FaultKind::Stuck { tap } => input.cp[tap] = *self.held_cp[tap].get_or_insert(input.cp[tap]),
                FaultKind::Dead { tap } => input.cp[tap] = f32::NAN,
                FaultKind::Bias { tap, offset } => input.cp[tap] += offset as f32,
                FaultKind::Spike { tap, amplitude } => {
                    let first = !std::mem::replace(&mut self.spiked[tap], true);
                    if first || self.rng.random_bool(self.spike_probability) {
                        input.cp[tap] += amplitude as f32;
                    }
                }
                FaultKind::DropBalance { fraction } => {
                    if self.rng.random_bool(fraction) {
                        *balance_cl = f64::NAN;
                    }
                }
                FaultKind::DropRoll { fraction } => {
                    if self.rng.random_bool(fraction) {
                        input.phi_deg = f32::NAN;
                    }
                }
                FaultKind::MissingCmu => {
                    input.cmu_port = f32::NAN;
                    input.cmu_stbd = f32::NAN;
                }
            }
        }
    }
}

/// A copy of `run` with the faults of `specs` applied to its recorded channels (the pressures,
/// the roll angle, the blowing measurement and the balance), as the estimator's f32 inputs see
/// them: a value a fault changed is stored as the faulty f32 widened to f64, every other value
/// stays bit for bit, so replaying the copy steps the estimator on exactly the faulty inputs.
#[must_use]
pub fn apply_to_run(run: &crate::dataset::Run, specs: &[FaultSpec], seed: u64) -> crate::dataset::Run {
    let mut faulty = run.clone();
    let mut injector = FaultInjector::new(specs, run.meta.sample_hz, seed);
    let channels = &mut faulty.channels;
    for sample_idx in 0..channels.len() {
        let narrow = |column: &[f64]| column.get(sample_idx).map_or(f32::NAN, |&value| value as f32);
        let clean = Input {
            phi_deg: narrow(&channels.phi_deg),
            alpha_deg: 0.0,
            cmu_port: narrow(&channels.cmu_port),
            cmu_stbd: narrow(&channels.cmu_stbd),
            cp: core::array::from_fn(|tap| narrow(&channels.cp[tap])),
        };
        let (mut input, mut balance_cl) = (clean, channels.cl[sample_idx]);
        injector.apply(channels.t_s[sample_idx], &mut input, &mut balance_cl);
        channels.cl[sample_idx] = balance_cl;
        let store = |column: &mut Vec<f64>, before: f32, after: f32| {
            if before.to_bits() != after.to_bits() {
                column[sample_idx] = f64::from(after);
            }
        };
        store(&mut channels.phi_deg, clean.phi_deg, input.phi_deg);
        store(&mut channels.cmu_port, clean.cmu_port, input.cmu_port);
        store(&mut channels.cmu_stbd, clean.cmu_stbd, input.cmu_stbd);
        for tap in 0..N_TAPS {
            store(&mut channels.cp[tap], clean.cp[tap], input.cp[tap]);
        }
    }
    faulty
}

#[cfg(test)]
mod tests {
    use super::*;

    fn input() -> Input {
        Input { phi_deg: 5.0, alpha_deg: 10.0, cmu_port: 0.001, cmu_stbd: 0.0, cp: core::array::from_fn(|t| t as f32) }
    }

    #[test]
    fn specs_round_trip_through_display() {
        for text in [
            "stuck:cp07@10s",
            "dead:cp03@5s",
            "bias:cp02=0.3@5s",
            "spike:cp09=2@5s",
            "drop:cl=0.2@0s",
            "drop:phi=0.2@0s",
            "missing:cmu@0s",
        ] {
            let spec: FaultSpec = text.parse().unwrap();
            assert_eq!(spec.to_string(), text);
        }
        assert_eq!("dead:cp12".parse::<FaultSpec>().unwrap().start_s, 0.0);
    }

    #[test]
    fn bad_specs_say_what_is_expected() {
        for (text, needle) in [
            ("dead:cp13", "cp01..cp12"),
            ("bias:cp02", "needs `=OFFSET_CP`"),
            ("stuck:cp01=3", "takes no value"),
            ("drop:cl=1.5", "[0, 1]"),
            ("drop:cp01=0.1", "applies to `cl`"),
            ("melt:cp01", "unknown kind"),
            ("dead:cp01@-1", "at least 0 s"),
            ("dead", "KIND:CHANNEL"),
            ("bias:cp01=nan", "finite"),
        ] {
            let err = text.parse::<FaultSpec>().unwrap_err().to_string();
            assert!(err.starts_with(&format!("fault `{text}`: ")) && err.contains(needle), "{err}");
        }
    }

    #[test]
    fn faults_start_at_their_onset_and_stuck_holds_the_onset_value() {
        let specs: Vec<FaultSpec> =
            ["stuck:cp01@1", "dead:cp02@1", "bias:cp03=0.5@1", "missing:cmu@1"].map(|s| s.parse().unwrap()).to_vec();
        let mut injector = FaultInjector::new(&specs, 1000.0, 1);
        let (mut before, mut cl) = (input(), 0.1);
        injector.apply(0.5, &mut before, &mut cl);
        assert_eq!(before, input());
        let mut at_onset = input();
        at_onset.cp[0] = 42.0;
        injector.apply(1.0, &mut at_onset, &mut cl);
        let mut later = input();
        injector.apply(2.0, &mut later, &mut cl);
        assert_eq!(later.cp[0], 42.0);
        assert!(later.cp[1].is_nan() && later.cmu_port.is_nan() && later.cmu_stbd.is_nan());
        assert_eq!(later.cp[2], 2.5);
        assert_eq!(cl, 0.1);
    }

    #[test]
    fn drops_hit_about_the_given_share_and_spikes_start_at_the_onset() {
        let specs: Vec<FaultSpec> =
            ["drop:cl=0.2", "drop:phi=0.5", "spike:cp09=2@0"].map(|s| s.parse().unwrap()).to_vec();
        let mut injector = FaultInjector::new(&specs, 1000.0, 3);
        let (mut cl_dropped, mut phi_dropped, mut spikes) = (0, 0, 0);
        for k in 0..10_000 {
            let (mut sample, mut cl) = (input(), 0.1);
            injector.apply(k as f64 * 1e-3, &mut sample, &mut cl);
            cl_dropped += usize::from(cl.is_nan());
            phi_dropped += usize::from(sample.phi_deg.is_nan());
            if sample.cp[8] != 8.0 {
                assert!(k == 0 || spikes > 0, "the first spike is at the onset");
                spikes += 1;
            }
        }
        assert!((1800..2200).contains(&cl_dropped), "{cl_dropped}");
        assert!((4700..5300).contains(&phi_dropped), "{phi_dropped}");
        // 10 s at 10 per second.
        assert!((60..140).contains(&spikes), "{spikes}");
    }
}

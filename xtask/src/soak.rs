//! The soak run (`cargo xtask soak`): the estimator stepped for a long time on noisy synthetic
//! input with random faults (NaN, infinities, huge values, out-of-range angles, stuck, biased and
//! spiking pressure channels, dropped samples), next to a reference estimator stepped on the
//! same input without the faults. Every estimate must stay finite at every step, and once a
//! fault has been over for [`RECOVERY_STEPS`] the faulty estimator's `C_l` must agree with the
//! reference's within [`RECOVERED_ERROR_BOUND`]: no fault may leave a lasting trace in the state
//! (during a fault the envelope below bounds the error).
//!
//! The envelope: the faulty estimator's `C_l,roll`, `C_l,linear` and `C_l`
//! must stay within the coefficient set's envelope with its margin at every step, and every step
//! at which they had to be limited must be flagged `ESTIMATE_LIMITED`. Which steps had to be is
//! told by a third estimator, stepped on the same faulty input with the envelope opened to
//! `+-ENVELOPE_LIMIT` (the envelope limits outputs only, so its state is the faulty one's): a
//! step at which its estimate leaves the envelope is a limited step.
//!
//! Every estimator notes the soak's blowing level as the controller's demand after each step
//! (`Estimator::note_demand`), so a missing Cmu is predicted from it.
//!
//! The input is a smooth roll (two sines of slowly drifting frequency), the angle of attack of
//! the coefficient set's schedule, held blowing levels, and pressures around their means, all
//! with uniform noise. Fault episodes start at random steps (on average every 2,000 steps) and
//! last from one step to five seconds. The steps are split into `streams` independent runs of
//! consecutive steps (one per core), each with its own seed; a run never restarts its
//! estimators.
//!
//! The random numbers come from a xorshift generator seeded through `mix_seed`: the soak needs
//! about 20 draws per step, and a cheap generator keeps it arithmetic-bound on the estimator.

use std::time::Instant;

use estimator_core::blob::ENVELOPE_LIMIT;
use estimator_core::coeffs::{Envelope, N_TAPS};
use estimator_core::{CoefficientSet, Estimator, Health, Input, Output};
use firmware_sim::campaign::mix_seed;
use rayon::prelude::*;
use serde::Serialize;

/// Bound on |`C_l` faulty - `C_l` reference| from [`RECOVERY_STEPS`] after the last fault: a
/// thirtieth of the balance's noise (about 3e-4), and 1e-4 of the wing's largest moment (0.08).
/// Every stage forgets its past exponentially once its inputs are sound again, so a state a
/// fault corrupted for good (a stuck isolation, a wound-up filter, a held Cmu) breaks it;
/// measured: 3.7e-9 over 10^6 steps and 8.4e-8 over 2 x 10^7, f32 rounding
/// (`cargo xtask soak --steps 20000000`).
pub const RECOVERED_ERROR_BOUND: f64 = 1e-5;

/// Steps after the last fault from which the faulty estimator must agree with the reference
/// again (3 s at 1 kHz).
pub const RECOVERY_STEPS: u64 = 3_000;

/// Mean number of steps between the starts of two fault episodes.
const STEPS_PER_FAULT: u64 = 2_000;
/// Longest fault episode, steps (5 s at 1 kHz).
const MAX_FAULT_STEPS: u64 = 5_000;

/// How long and with which seed to soak.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SoakConfig {
    /// Steps in all (over every stream).
    pub steps: u64,
    /// Seed.
    pub seed: u64,
    /// Independent runs the steps are split into (run in parallel).
    pub streams: u64,
}

/// What the soak found.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SoakOutcome {
    /// Steps run, in all.
    pub steps: u64,
    /// Independent runs.
    pub streams: u64,
    /// Seed.
    pub seed: u64,
    /// Steps at which some estimate was not finite (must be 0).
    pub non_finite_steps: u64,
    /// Largest |`C_l` faulty - `C_l` reference| over every step.
    pub worst_error: f64,
    /// Steps at least [`RECOVERY_STEPS`] after the last fault ended.
    pub recovered_steps: u64,
    /// Largest |`C_l` faulty - `C_l` reference| over the recovered steps.
    pub worst_recovered_error: f64,
    /// Largest |`C_l`| of the faulty estimator.
    pub worst_abs_cl: f64,
    /// Fault episodes started.
    pub fault_episodes: u64,
    /// Steps at which the faulty estimator flagged a state reset.
    pub state_resets: u64,
    /// The bounds of `C_l` (the envelope of `C_l,linear` and `C_l` with its margin).
    pub cl_bounds: [f64; 2],
    /// Largest |`C_l`| of the estimator without the envelope, on the same faulty input.
    pub worst_abs_cl_unbounded: f64,
    /// Steps at which an estimate (`C_l,roll`, `C_l,linear` or `C_l`) had to be limited: the
    /// estimator without the envelope left it.
    pub limited_steps: u64,
    /// Steps the faulty estimator flagged `ESTIMATE_LIMITED` (also for its coupling limit).
    pub flagged_steps: u64,
    /// Limited steps not flagged (must be 0).
    pub unflagged_limited_steps: u64,
    /// Steps at which an estimate of the faulty estimator was beyond the envelope with its
    /// margin (must be 0).
    pub beyond_envelope_steps: u64,
    /// Wall time, s.
    pub elapsed_s: f64,
}

impl SoakOutcome {
    /// True when every estimate stayed finite, the error after recovery within
    /// [`RECOVERED_ERROR_BOUND`], every estimate within the envelope and every limited step
    /// flagged.
    #[must_use]
    pub fn passed(&self) -> bool {
        self.non_finite_steps == 0
            && self.worst_recovered_error <= RECOVERED_ERROR_BOUND
            && self.beyond_envelope_steps == 0
            && self.unflagged_limited_steps == 0
    }
}

/// Runs the soak with the tables `set`.
#[must_use]
pub fn soak(set: &CoefficientSet, config: &SoakConfig) -> SoakOutcome {
    let started = Instant::now();
    let streams = config.streams.clamp(1, config.steps.max(1));
    let partials: Vec<SoakOutcome> = (0..streams)
        .into_par_iter()
        .map(|stream| {
            let steps = config.steps / streams + u64::from(stream < config.steps % streams);
            soak_stream(set, steps, mix_seed(config.seed, stream))
        })
        .collect();
    let mut total = SoakOutcome { streams, seed: config.seed, ..SoakOutcome::empty(set) };
    for partial in &partials {
        total.steps += partial.steps;
        total.non_finite_steps += partial.non_finite_steps;
        total.worst_error = total.worst_error.max(partial.worst_error);
        total.recovered_steps += partial.recovered_steps;
        total.worst_recovered_error = total.worst_recovered_error.max(partial.worst_recovered_error);
        total.worst_abs_cl = total.worst_abs_cl.max(partial.worst_abs_cl);
        total.fault_episodes += partial.fault_episodes;
        total.state_resets += partial.state_resets;
        total.worst_abs_cl_unbounded = total.worst_abs_cl_unbounded.max(partial.worst_abs_cl_unbounded);
        total.limited_steps += partial.limited_steps;
        total.flagged_steps += partial.flagged_steps;
        total.unflagged_limited_steps += partial.unflagged_limited_steps;
        total.beyond_envelope_steps += partial.beyond_envelope_steps;
    }
    total.elapsed_s = started.elapsed().as_secs_f64();
    total
}

/// xorshift64* (Vigna 2016): uniform `u64`s; seeded non-zero.
#[derive(Debug, Clone)]
struct Xorshift(u64);

impl Xorshift {
    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in [0, 1).
    fn uniform(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in [-1, 1).
    fn signed(&mut self) -> f32 {
        2.0 * self.uniform() - 1.0
    }

    /// Uniform in `0..n`.
    fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n.max(1)
    }
}

/// One fault episode.
#[derive(Debug, Clone, Copy)]
struct Episode {
    kind: u64,
    /// The input field (0 phi, 1 alpha, 2 cmu port, 3 cmu stbd, 4.. cp) it hits.
    field: usize,
    /// A value it writes (the held value of a stuck channel, a bias, a special value).
    value: f32,
    remaining: u64,
}

/// Special values a broken sensor delivers.
const SPECIAL: [f32; 8] = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MAX, f32::MIN, 1e30, -1e30, 1e-40];

impl SoakOutcome {
    /// No step yet, with the bounds of `set`.
    fn empty(set: &CoefficientSet) -> Self {
        Self {
            steps: 0,
            streams: 1,
            seed: 0,
            non_finite_steps: 0,
            worst_error: 0.0,
            recovered_steps: 0,
            worst_recovered_error: 0.0,
            worst_abs_cl: 0.0,
            fault_episodes: 0,
            state_resets: 0,
            cl_bounds: Envelope::with_margin(set.envelope.cl).map(f64::from),
            worst_abs_cl_unbounded: 0.0,
            limited_steps: 0,
            flagged_steps: 0,
            unflagged_limited_steps: 0,
            beyond_envelope_steps: 0,
            elapsed_s: 0.0,
        }
    }

    /// Counts the envelope's checks of one step: `bounded` from the faulty estimator, `free` from
    /// the one without the envelope.
    fn count_envelope(&mut self, bounds: &[[f32; 2]; 2], bounded: &Output, free: &Output) {
        let [roll, total] = *bounds;
        let inside = |value: f32, [low, high]: [f32; 2]| value >= low && value <= high;
        let pairs = [(bounded.cl_roll, free.cl_roll, roll), (bounded.cl_linear, free.cl_linear, total)];
        let pairs = pairs.into_iter().chain([(bounded.cl, free.cl, total)]);
        let (mut limited, mut beyond) = (false, false);
        for (value, unbounded, range) in pairs {
            limited |= !inside(unbounded, range);
            beyond |= !inside(value, range);
        }
        let flagged = bounded.health.has(Health::ESTIMATE_LIMITED);
        self.limited_steps += u64::from(limited);
        self.flagged_steps += u64::from(flagged);
        self.unflagged_limited_steps += u64::from(limited && !flagged);
        self.beyond_envelope_steps += u64::from(beyond);
        self.worst_abs_cl_unbounded = self.worst_abs_cl_unbounded.max(f64::from(free.cl).abs());
    }
}

fn soak_stream(set: &CoefficientSet, steps: u64, seed: u64) -> SoakOutcome {
    let mut rng = Xorshift(seed | 1);
    let opened = Envelope { cl_roll: [-ENVELOPE_LIMIT, ENVELOPE_LIMIT], cl: [-ENVELOPE_LIMIT, ENVELOPE_LIMIT] };
    let unbounded_set = CoefficientSet { envelope: opened, ..*set };
    let (mut faulty, mut reference) = (Estimator::new(set), Estimator::new(set));
    let mut unbounded = Estimator::new(&unbounded_set);
    let bounds = [Envelope::with_margin(set.envelope.cl_roll), Envelope::with_margin(set.envelope.cl)];
    let n_alpha = usize::from(set.n_alpha).clamp(1, set.alpha_schedule_deg.len());
    let mut alpha_deg = set.alpha_schedule_deg[0];
    let mut cmu = [0.0f32; 2];
    let mut episodes: Vec<Episode> = Vec::new();
    let mut outcome = SoakOutcome { steps, seed, ..SoakOutcome::empty(set) };
    let mut last_fault_step = 0;
    for step in 0..steps {
        // Slow changes of the operating point: a new alpha every 20 s, new blowing every 0.5 s.
        if step % 20_000 == 0 {
            alpha_deg = set.alpha_schedule_deg[rng.below(n_alpha as u64) as usize];
        }
        if step % 500 == 0 {
            cmu = [0.009 * rng.uniform() * f32::from(rng.below(2) == 0), 0.0];
        }
        let clean = clean_input(set, step, alpha_deg, cmu, &mut rng);
        if rng.below(STEPS_PER_FAULT) == 0 {
            episodes.push(new_episode(&clean, &mut rng));
            outcome.fault_episodes += 1;
        }
        let mut input = clean;
        for episode in &mut episodes {
            apply(episode, &mut input, &mut rng);
            episode.remaining -= 1;
        }
        if !episodes.is_empty() {
            last_fault_step = step;
        }
        episodes.retain(|episode| episode.remaining > 0);
        let recovered = step >= last_fault_step + RECOVERY_STEPS;
        let (out, out_ref, out_free) = (faulty.step(&input), reference.step(&clean), unbounded.step(&input));
        for estimator in [&mut faulty, &mut reference, &mut unbounded] {
            estimator.note_demand(cmu);
        }
        if !out.estimates().iter().chain(out_ref.estimates().iter()).all(|value| value.is_finite()) {
            outcome.non_finite_steps += 1;
        }
        outcome.count_envelope(&bounds, &out, &out_free);
        outcome.state_resets += u64::from(out.health.has(Health::STATE_RESET));
        let error = (f64::from(out.cl) - f64::from(out_ref.cl)).abs();
        // `max` ignores NaN; a non-finite estimate is counted above.
        outcome.worst_error = outcome.worst_error.max(error);
        if recovered {
            outcome.recovered_steps += 1;
            outcome.worst_recovered_error = outcome.worst_recovered_error.max(error);
        }
        outcome.worst_abs_cl = outcome.worst_abs_cl.max(f64::from(out.cl).abs());
    }
    outcome
}

/// The fault-free noisy input of `step`.
fn clean_input(set: &CoefficientSet, step: u64, alpha_deg: f32, cmu: [f32; 2], rng: &mut Xorshift) -> Input {
    let t_s = step as f32 * set.dt_s;
    // Two sines whose frequencies drift over minutes (f32 time loses resolution after hours,
    // so the phase is taken modulo a 1000 s period).
    let t_mod_s = (step % 1_000_000) as f32 * set.dt_s;
    let phi_deg = 20.0 * (core::f32::consts::TAU * 0.4 * t_mod_s).sin()
        + 8.0 * (core::f32::consts::TAU * (1.3 + 0.2 * (t_s * 1e-3).sin()) * t_mod_s).sin()
        + 0.05 * rng.signed();
    let cp = core::array::from_fn(|tap| set.pressure.cp_mean[tap] + 0.002 * phi_deg + 0.01 * rng.signed());
    Input { phi_deg, alpha_deg, cmu_port: cmu[0] + 1e-5 * rng.signed(), cmu_stbd: cmu[1], cp }
}

fn new_episode(clean: &Input, rng: &mut Xorshift) -> Episode {
    let kind = rng.below(6);
    let field = rng.below(4 + N_TAPS as u64) as usize;
    let value = match kind {
        // Stuck: the value at the onset.
        0 => *field_mut(&mut clean.clone(), field),
        1 => 0.5 * rng.signed(),
        _ => SPECIAL[rng.below(SPECIAL.len() as u64) as usize],
    };
    let remaining = 1 + rng.below(MAX_FAULT_STEPS);
    Episode { kind, field, value, remaining }
}

/// Applies one episode to `input`: stuck, bias, a special value, dropped samples (30 %),
/// spikes (5 %), or every input at once at the special value.
fn apply(episode: &Episode, input: &mut Input, rng: &mut Xorshift) {
    match episode.kind {
        0 | 2 => *field_mut(input, episode.field) = episode.value,
        1 => *field_mut(input, episode.field) += episode.value,
        3 => {
            if rng.below(10) < 3 {
                *field_mut(input, episode.field) = f32::NAN;
            }
        }
        4 => {
            if rng.below(20) == 0 {
                *field_mut(input, episode.field) += 100.0 * rng.signed();
            }
        }
        _ => {
            for field in 0..4 + N_TAPS {
                *field_mut(input, field) = episode.value;
            }
        }
    }
}

fn field_mut(input: &mut Input, field: usize) -> &mut f32 {
    match field {
        0 => &mut input.phi_deg,
        1 => &mut input.alpha_deg,
        2 => &mut input.cmu_port,
        3 => &mut input.cmu_stbd,
        _ => &mut input.cp[(field - 4).min(N_TAPS - 1)],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_short_soak_stays_finite_and_bounded_and_sees_faults() {
        let config = SoakConfig { steps: 100_000, seed: 5, streams: 2 };
        let outcome = soak(&estimator_core::coeffs::DEFAULT, &config);
        assert_eq!(outcome.steps, 100_000);
        assert!(outcome.fault_episodes > 20, "{outcome:?}");
        assert!(outcome.passed(), "{outcome:?}");
        assert!(outcome.worst_error > 0.0, "faults must move the estimate: {outcome:?}");
    }

    /// The soak's garbage drives the estimate beyond the envelope (0.39 before it), every such
    /// step is limited and flagged, and no estimate leaves the envelope with its margin.
    #[test]
    fn the_soak_limits_and_flags_every_step_beyond_the_envelope() {
        let set = estimator_core::coeffs::DEFAULT;
        let outcome = soak(&set, &SoakConfig { steps: 200_000, seed: 3, streams: 2 });
        let [low, high] = outcome.cl_bounds;
        assert!(outcome.limited_steps > 0, "the garbage must reach beyond the envelope: {outcome:?}");
        assert!(outcome.worst_abs_cl_unbounded > high.max(-low), "{outcome:?}");
        assert!(outcome.worst_abs_cl <= high.max(-low), "{outcome:?}");
        assert_eq!((outcome.unflagged_limited_steps, outcome.beyond_envelope_steps), (0, 0), "{outcome:?}");
        assert!(outcome.flagged_steps >= outcome.limited_steps, "{outcome:?}");
        assert!(outcome.passed());
    }
}

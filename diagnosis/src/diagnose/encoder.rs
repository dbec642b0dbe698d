//! Whether the recorded roll angle is quantised coarser than its own motion per sample: an
//! encoder outside the diagnosis's vocabulary (docs/spec/diagnosis.md, "Outside the
//! vocabulary ... encoder backlash or quantisation": `unattributed`, with what its structure
//! is; docs/diagnosis.md, A coarse encoder).
//!
//! The roll rate and acceleration every model term is driven by are differences of the
//! recorded angle. An angle that moves in steps larger than it moves in a sample turns them
//! into spikes at the steps, so a candidate driven by the rate (a slow vortex state, a damping
//! law) fits the spikes and would be named for what the encoder did.
//!
//! The quantum is the median size of the angle's non-zero steps from sample to sample; the
//! motion per sample is the angle's travel over steps of `COARSE_STEP_S`, where a quantum
//! much smaller than that travel no longer matters, over the number of samples. A continuous
//! (or noisy) angle steps by about its motion per sample; a quantised one steps by its quantum
//! and holds in between.

use firmware_sim::dataset::RunKind;

use super::streams::RunStreams;
use stats::median_high;

/// The time step over which the angle's travel is its motion, s: a tenth of a second holds a
/// few degrees of a tunnel's roll motion, far more than any encoder quantum that spikes its
/// rate.
const COARSE_STEP_S: f64 = 0.1;

/// Least ratio of the quantum to the motion per sample that counts as a coarse encoder: the
/// rate from the angle's differences then comes in spikes of at least four times the rate
/// itself, held at zero in between. A noisy or finely resolved encoder steps by about its
/// motion per sample (a ratio near one; white noise on the angle gives its median difference,
/// about its own size, against a travel of at least the same).
const MIN_QUANTUM_TO_MOTION: f64 = 4.0;

/// A roll angle recorded in steps coarser than its motion per sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quantisation {
    /// The median non-zero step of the recorded angle from sample to sample, deg.
    pub quantum_deg: f64,
    /// The angle's motion per sample, deg (its travel over `COARSE_STEP_S` steps over the
    /// samples).
    pub motion_per_sample_deg: f64,
}

/// The encoder's quantisation, if the rolling runs' angle steps by at least
/// `MIN_QUANTUM_TO_MOTION` times its motion per sample (the median over those runs).
#[must_use]
pub fn quantisation(runs: &[RunStreams]) -> Option<Quantisation> {
    let mut per_run: Vec<Quantisation> = rolling(runs).filter_map(run_quantisation).collect();
    if per_run.is_empty() {
        return None;
    }
    let ratio = |q: &Quantisation| q.quantum_deg / q.motion_per_sample_deg;
    per_run.sort_by(|a, b| ratio(a).total_cmp(&ratio(b)));
    let median = per_run[per_run.len() / 2];
    (ratio(&median) >= MIN_QUANTUM_TO_MOTION).then_some(median)
}

/// The runs that roll the wing: only their angle says anything of the encoder.
fn rolling(runs: &[RunStreams]) -> impl Iterator<Item = &RunStreams> {
    runs.iter().filter(|run| matches!(run.kind, RunKind::Roll | RunKind::RollActuation))
}

/// Below this a step of the recorded angle is the file's rounding of one value, not a step, deg.
const RESOLUTION_DEG: f64 = 1e-9;

/// The run's recorded roll angle, deg.
fn angle_deg(run: &RunStreams) -> Vec<f64> {
    run.phi_rad.iter().map(|phi| phi.to_degrees()).collect()
}

/// One run's quantum and motion per sample (none for an angle that does not move).
fn run_quantisation(run: &RunStreams) -> Option<Quantisation> {
    let phi_deg = angle_deg(run);
    let mut steps: Vec<f64> = phi_deg
        .windows(2)
        .map(|pair| (pair[1] - pair[0]).abs())
        .filter(|step| step.is_finite() && *step > RESOLUTION_DEG)
        .collect();
    let quantum_deg = median_high(&mut steps)?;
    let coarse = ((COARSE_STEP_S * run.sample_hz).round() as usize).max(1);
    let (mut travel_deg, mut spanned) = (0.0, 0usize);
    for (a, b) in phi_deg.iter().step_by(coarse).zip(phi_deg.iter().skip(coarse).step_by(coarse)) {
        if (b - a).is_finite() {
            travel_deg += (b - a).abs();
            spanned += coarse;
        }
    }
    let motion_per_sample_deg = travel_deg / spanned.max(1) as f64;
    (motion_per_sample_deg > RESOLUTION_DEG).then_some(Quantisation { quantum_deg, motion_per_sample_deg })
}

/// Samples either side of a reversal's hold over which the angle's rate is taken, s: short
/// beside a roll motion's half period (a few seconds down to a tenth), long beside an encoder's
/// quantum steps.
const RATE_WINDOW_S: f64 = 0.01;

/// Least median ratio of the rate leaving a reversal's hold to the rate entering it that counts as
/// a play: a smooth motion passes a reversal at a rate linear in time through zero, so the two
/// are equal (ratio one, a quantum's rounding either way); a play lets the reading go only once
/// the angle has moved its width back, at `sqrt(2 a b)` for a deceleration `a`, while it entered
/// at the reversal itself, at nearly zero.
const MIN_EXIT_TO_ENTRY: f64 = 3.0;

/// Least median share of the rate just after a reversal's hold that the reading already has at
/// the hold's end (the rate over the first window after it, extrapolated back to the end with
/// the second window's change, over the first window's rate). A play releases the reading at the
/// angle's full rate: a kink, a share of `v / (v + a w / 2)` for a release rate `v` and a
/// deceleration `a`, 0.7 for a play of 0.02 deg on a 0.5 Hz swing of 30 deg and near one for
/// wider ones. A motion that leaves a hold from rest gains its rate smoothly and extrapolates to
/// about none at the hold's end (a ramp-and-hold rig: 0.41 at most on this project's tunnel).
const MIN_RELEASE_SHARE: f64 = 0.6;

/// Fewest reversals, over the rolling runs, for a median to say anything.
const MIN_REVERSALS: usize = 5;

/// A play (backlash) in the encoder's drive: at every reversal of the motion the reading holds
/// until the angle has moved the play's width back, then follows at the angle's full rate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Play {
    /// The median over the reversals of the rate leaving the hold over the rate entering it.
    pub exit_to_entry: f64,
    /// The median over the reversals of the share of its rate the reading has at the hold's end.
    pub release_share: f64,
    /// The median hold at a reversal, s.
    pub hold_s: f64,
    /// The play's width, deg: half the rate leaving the hold times the hold (the angle moved
    /// from rest at constant deceleration during it), the median over the reversals.
    pub width_deg: f64,
}

/// A play in the encoder, if at the reversals of the rolling runs' recorded angle the reading
/// leaves its hold at least `MIN_EXIT_TO_ENTRY` times faster than it entered it, already at
/// `MIN_RELEASE_SHARE` of that rate as the hold ends (medians over the reversals). Encoder backlash is outside the vocabulary (docs/spec/diagnosis.md);
/// every rate-driven candidate fits the kinks it puts into the rate.
#[must_use]
pub fn play(runs: &[RunStreams]) -> Option<Play> {
    let reversals: Vec<Reversal> = rolling(runs).flat_map(run_reversals).collect();
    if reversals.len() < MIN_REVERSALS {
        return None;
    }
    let median = |of: &dyn Fn(&Reversal) -> f64| median_high(&mut reversals.iter().map(of).collect::<Vec<_>>());
    let exit_to_entry = median(&|r| r.exit_rate / r.entry_rate)?;
    let release_share = median(&|r| r.release_rate / r.exit_rate)?;
    let hold_s = median(&|r| r.hold_s)?;
    let width_deg = median(&|r| 0.5 * r.exit_rate * r.hold_s)?;
    (exit_to_entry >= MIN_EXIT_TO_ENTRY && release_share >= MIN_RELEASE_SHARE).then_some(Play {
        exit_to_entry,
        release_share,
        hold_s,
        width_deg,
    })
}

/// One reversal of the recorded angle: two non-zero steps of opposite sign, the samples
/// between them its hold. Rates in deg/s, over `RATE_WINDOW_S`.
struct Reversal {
    /// Over the window before the hold.
    entry_rate: f64,
    /// Over the window after it.
    exit_rate: f64,
    /// At the hold's end: the exit rate less half its change to the next window (a constant
    /// acceleration extrapolated back half a window).
    release_rate: f64,
    /// The hold, s.
    hold_s: f64,
}

/// The reversals of one run's recorded angle.
fn run_reversals(run: &RunStreams) -> Vec<Reversal> {
    let phi_deg = angle_deg(run);
    let window = ((RATE_WINDOW_S * run.sample_hz).round() as usize).max(1);
    let dt_s = 1.0 / run.sample_hz;
    let step = |i: usize| phi_deg[i] - phi_deg[i - 1];
    let moving: Vec<usize> =
        (1..phi_deg.len()).filter(|&i| step(i).abs() > RESOLUTION_DEG && step(i).is_finite()).collect();
    moving
        .windows(2)
        .filter(|pair| step(pair[0]).signum() != step(pair[1]).signum())
        .filter(|pair| pair[0] > window && pair[1] + 2 * window < phi_deg.len())
        .filter_map(|pair| {
            let (last_in, first_out) = (pair[0], pair[1]);
            let rate = |from: usize| (phi_deg[from + window] - phi_deg[from]).abs() / (window as f64 * dt_s);
            let (entry_rate, exit_rate) = (rate(last_in - window), rate(first_out - 1));
            let release_rate = 1.5 * exit_rate - 0.5 * rate(first_out - 1 + window);
            let hold_s = (first_out - last_in) as f64 * dt_s;
            (entry_rate > 0.0 && exit_rate > 0.0).then_some(Reversal { entry_rate, exit_rate, release_rate, hold_s })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    use super::*;
    use crate::diagnose::streams::synthetic_run;

    const HZ: f64 = 1000.0;

    /// A roll run of 20 s: a 0.5 Hz swing of 30 deg, recorded through `record`.
    fn rolling(record: impl FnMut(f64) -> f64) -> RunStreams {
        let n = (20.0 * HZ) as usize;
        let mut run = synthetic_run(HZ, vec![vec![0.0; n]], vec![vec![0.0; n]]);
        run.kind = RunKind::Roll;
        run.phi_rad = (0..n)
            .map(|i| 30.0 * (std::f64::consts::TAU * 0.5 * i as f64 / HZ).sin())
            .map(record)
            .map(f64::to_radians)
            .collect();
        run
    }

    /// Recorded in steps of 5 deg (the swing moves about 0.06 deg a sample): a coarse
    /// encoder, its quantum 5 deg.
    #[test]
    fn an_angle_in_steps_of_five_degrees_is_a_coarse_encoder() {
        let found = quantisation(&[rolling(|phi| (phi / 5.0).round() * 5.0)]).expect("a coarse encoder");
        assert!((found.quantum_deg - 5.0).abs() < 1e-9, "{found:?}");
        assert!((found.motion_per_sample_deg - 0.06).abs() < 0.01, "{found:?}");
    }

    /// Resolved to 0.001 deg with 0.02 deg of noise, or to 0.01 deg (a 15-bit encoder): no
    /// coarse encoder.
    #[test]
    fn a_fine_or_noisy_angle_is_no_coarse_encoder() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let noise = Normal::new(0.0, 0.02).expect("a valid deviation");
        let noisy = rolling(|phi| ((phi + noise.sample(&mut rng)) * 1000.0).round() / 1000.0);
        assert_eq!(quantisation(&[noisy]), None);
        assert_eq!(quantisation(&[rolling(|phi| (phi * 100.0).round() / 100.0)]), None);
    }

    /// The play operator: the reading follows the angle only once it has moved half the
    /// width beyond it (Krasnosel'skii & Pokrovskii 1989).
    fn through_play(width_deg: f64) -> impl FnMut(f64) -> f64 {
        let mut reading: Option<f64> = None;
        move |phi| {
            let held = reading.unwrap_or(phi).clamp(phi - width_deg / 2.0, phi + width_deg / 2.0);
            reading = Some(held);
            (held * 1000.0).round() / 1000.0
        }
    }

    /// A play of 1 deg on the 0.5 Hz swing: the reading holds at each reversal and leaves it at
    /// the swing's rate after it has moved the width back; found, its width within 20 %.
    #[test]
    fn a_play_in_the_encoder_is_found_with_its_width() {
        let found = play(&[rolling(through_play(1.0))]).expect("a play");
        assert!(found.exit_to_entry >= 3.0, "{found:?}");
        assert!((found.width_deg - 1.0).abs() < 0.2, "{found:?}");
        // The angle takes sqrt(2 b / a) to move b back from rest, a = 30 deg (pi s^-1)^2.
        let hold_s = (2.0 * 1.0 / (30.0 * std::f64::consts::PI.powi(2))).sqrt();
        assert!((found.hold_s - hold_s).abs() < 0.2 * hold_s, "{found:?}");
    }

    /// A smooth swing recorded to 0.001 deg, with or without 0.02 deg of noise, or in coarse
    /// steps: no play.
    #[test]
    fn a_smooth_noisy_or_quantised_angle_has_no_play() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let noise = Normal::new(0.0, 0.02).expect("a valid deviation");
        assert_eq!(play(&[rolling(|phi| (phi * 1000.0).round() / 1000.0)]), None);
        assert_eq!(play(&[rolling(|phi| ((phi + noise.sample(&mut rng)) * 1000.0).round() / 1000.0)]), None);
        assert_eq!(play(&[rolling(|phi| (phi / 5.0).round() * 5.0)]), None);
    }

    /// A ramp-and-hold motion that settles into each hold slowly and leaves it from rest: it
    /// leaves faster than it arrived, as through a play, but without a kink; no play.
    #[test]
    fn a_motion_that_leaves_its_holds_from_rest_has_no_play() {
        let n = (20.0 * HZ) as usize;
        let dt_s = 1.0 / HZ;
        let mut run = synthetic_run(HZ, vec![vec![0.0; n]], vec![vec![0.0; n]]);
        run.kind = RunKind::Roll;
        // Every 2 s the target swaps between +-20 deg; after a hold of 0.7 s the rate grows at
        // 10,000 deg/s^2 towards 150 deg/s, and the angle settles into the target as
        // `rate = to_go / 20 ms`, whichever is slower.
        let (mut phi, mut rate, mut target) = (0.0_f64, 0.0_f64, -20.0_f64);
        run.phi_rad = (0..n)
            .map(|i| {
                let t_s = (i as f64 * dt_s) % 2.0;
                if i % (2.0 * HZ) as usize == 0 {
                    target = -target;
                    rate = 0.0;
                }
                if t_s >= 0.7 {
                    let to_go = target - phi;
                    rate = (rate.abs() + 10_000.0 * dt_s).min(150.0).min(to_go.abs() / 0.02) * to_go.signum();
                    phi += rate * dt_s;
                }
                ((phi * 100.0).round() / 100.0).to_radians()
            })
            .collect();
        let reversals = run_reversals(&run);
        let leaves_faster = reversals.iter().filter(|r| r.exit_rate >= MIN_EXIT_TO_ENTRY * r.entry_rate).count();
        assert!(2 * leaves_faster > reversals.len(), "the motion leaves its holds faster than it arrives");
        assert_eq!(play(&[run]), None);
    }

    /// Runs that hold the wing say nothing of the encoder, whatever their angle.
    #[test]
    fn held_runs_say_nothing_of_the_encoder() {
        let mut held = rolling(|phi| (phi / 5.0).round() * 5.0);
        held.kind = RunKind::Actuation;
        assert_eq!(quantisation(&[held]), None);
        let mut held = rolling(through_play(1.0));
        held.kind = RunKind::Actuation;
        assert_eq!(play(&[held]), None);
    }
}

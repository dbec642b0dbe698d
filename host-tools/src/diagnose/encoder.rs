//! Whether the recorded roll angle is quantised coarser than its own motion per sample: an
//! encoder outside the diagnosis's vocabulary (shared/spec/diagnosis.md, "Outside the
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
    let mut per_run: Vec<Quantisation> = runs
        .iter()
        .filter(|run| matches!(run.kind, RunKind::Roll | RunKind::RollActuation))
        .filter_map(run_quantisation)
        .collect();
    if per_run.is_empty() {
        return None;
    }
    let ratio = |q: &Quantisation| q.quantum_deg / q.motion_per_sample_deg;
    per_run.sort_by(|a, b| ratio(a).total_cmp(&ratio(b)));
    let median = per_run[per_run.len() / 2];
    (ratio(&median) >= MIN_QUANTUM_TO_MOTION).then_some(median)
}

/// One run's quantum and motion per sample (none for an angle that does not move).
fn run_quantisation(run: &RunStreams) -> Option<Quantisation> {
    let phi_deg: Vec<f64> = run.phi_rad.iter().map(|phi| phi.to_degrees()).collect();
    // Below this a step is the file's rounding of one value, not a step of the angle.
    let resolution_deg = 1e-9;
    let mut steps: Vec<f64> = phi_deg
        .windows(2)
        .map(|pair| (pair[1] - pair[0]).abs())
        .filter(|step| step.is_finite() && *step > resolution_deg)
        .collect();
    if steps.is_empty() {
        return None;
    }
    steps.sort_by(f64::total_cmp);
    let quantum_deg = steps[steps.len() / 2];
    let coarse = ((COARSE_STEP_S * run.sample_hz).round() as usize).max(1);
    let (mut travel_deg, mut spanned) = (0.0, 0usize);
    for (a, b) in phi_deg.iter().step_by(coarse).zip(phi_deg.iter().skip(coarse).step_by(coarse)) {
        if (b - a).is_finite() {
            travel_deg += (b - a).abs();
            spanned += coarse;
        }
    }
    let motion_per_sample_deg = travel_deg / spanned.max(1) as f64;
    (motion_per_sample_deg > resolution_deg).then_some(Quantisation { quantum_deg, motion_per_sample_deg })
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

    /// Runs that hold the wing say nothing of the encoder, whatever their angle.
    #[test]
    fn held_runs_say_nothing_of_the_encoder() {
        let mut held = rolling(|phi| (phi / 5.0).round() * 5.0);
        held.kind = RunKind::Actuation;
        assert_eq!(quantisation(&[held]), None);
    }
}

//! The residual streams of a diagnosis: what the sim (the fitted models driven by the recorded
//! inputs alone) predicts for each run, and where the recording departs from it.
//!
//! The balance stream is `C_l,measured - (C_l,eGK + C_l,AFC + coupling)` with every block run by
//! estimator-core exactly as it flies, but with the pressure channels withheld: the sim is the
//! model of the experiment, so the disturbance comes from the eGK ODE and nothing is corrected
//! by the taps (docs/spec/diagnosis.md, "Sim"). The sensor stream is the one-step innovation
//! of each pressure channel under the pressure model's steady-state Kalman filter
//! (docs/diagnosis.md, Pressure innovations per channel), recomputed in f64 with an innovation gate
//! so that one bad channel does not leak into the others.

use std::ops::Range;
use std::sync::Arc;

use rayon::prelude::*;

use estimator_core::coeffs::N_TAPS;
use estimator_core::plant::Plant;
use estimator_core::{CoefficientSet, Estimator, Input};
use firmware_sim::dataset::{Dataset, Run, RunKind};

use super::regression::Interleave;
use estimator_core::pressure::PressureFilter;
use model_fit::fit::pressure::{PressureTable, filter_step};
use model_fit::fit::signals::{differentiate, hold_missing, zero_phase_lowpass_extended};
use model_fit::fit::split::Split;
use model_fit::replay::input_at;

/// Corner of the zero-phase smoother applied to the roll angle before it is differentiated for
/// the candidate regressors, Hz: above the roll motion's content (holds with ramps of a few
/// hertz), below the encoder noise that a second derivative would amplify.
const KINEMATICS_CORNER_HZ: f64 = 40.0;

/// Corners of the smoother before the roll acceleration that drives a structural mode, Hz, the
/// first the kinematics' own. A mode's added response `(H - 1) u` is small where the motion
/// lives (about `2 zeta f / f_n` of the acceleration) and whole above the mode, where an
/// encoder's quantisation, differentiated twice, is all there is: an acceleration smoothed only
/// above the motion's content gives a regressor that is mostly noise, and its gain comes out a
/// fifth to a twentieth of the true one (errors in variables). The candidate profiles the corner
/// with the mode, so a motion with content up to the mode keeps it.
pub const MODE_DRIVE_CORNERS_HZ: [f64; 4] = [KINEMATICS_CORNER_HZ, 16.0, 8.0, 4.0];

/// Corner of the smoother applied to each pressure channel before its time derivative is taken
/// (the regressor of a tubing lag), Hz.
const PRESSURE_CORNER_HZ: f64 = 20.0;

/// Blocks of a run over which [`RunStreams::steady_mean_alone`] takes its batch means.
const STEADY_MEAN_BLOCKS: usize = 10;

/// Standard errors from zero a run's mean innovation must stand to be a level the run holds
/// ([`RunStreams::steady_mean_alone`]; two-sided, about 5 % by chance with nine degrees of
/// freedom at 2.26, so 2 is a little lenient toward keeping a level).
const STEADY_MEAN_Z: f64 = 2.0;

/// The key of a kind of run at one angle of attack (`roll@20`), by which the signature keeps
/// what the sim's own runs of that kind show and a recording's runs are paired with them.
pub(super) fn kind_alpha_key(kind: &str, alpha_deg: f64) -> String {
    format!("{kind}@{alpha_deg}")
}

/// Everything the diagnosis needs of one run.
#[derive(Debug, Clone)]
pub struct RunStreams {
    /// The run's file, as in the manifest.
    pub file: String,
    /// Kind of run.
    pub kind: RunKind,
    /// Angle of attack, deg.
    pub alpha_deg: f64,
    /// Sample rate, Hz.
    pub sample_hz: f64,
    /// Training samples: candidates are fitted here, less the selection blocks.
    pub training: Range<usize>,
    /// Selection samples, interleaved blocks of the training part: which effect is named, and
    /// whether there is a gap at all, is decided here.
    pub select: Interleave,
    /// Held-out samples: the named effects' shrink is reported here and nothing is chosen.
    pub heldout: Range<usize>,
    /// Time from the start of the run, s.
    pub t_s: Vec<f64>,
    /// Roll angle, rad (missing samples held).
    pub phi_rad: Vec<f64>,
    /// Roll rate from the smoothed angle, rad/s.
    pub phi_dot_rad_s: Vec<f64>,
    /// Roll acceleration from the smoothed angle, rad/s^2.
    pub phi_ddot_rad_s2: Vec<f64>,
    /// Roll acceleration from the angle smoothed at each of [`MODE_DRIVE_CORNERS_HZ`] after the
    /// first (which is [`Self::phi_ddot_rad_s2`]'s), rad/s^2; see [`Self::acceleration_at`].
    pub phi_ddot_smoother_rad_s2: Vec<Vec<f64>>,
    /// Port and starboard Cmu as recorded (missing samples held, never negative).
    pub cmu: [Vec<f64>; 2],
    /// Sim: eGK disturbance moment.
    pub cl_egk: Vec<f64>,
    /// Sim: plant moment of each jet.
    pub cl_afc_side: [Vec<f64>; 2],
    /// Sim: coupling operator's correction.
    pub coupling: Vec<f64>,
    /// Measured balance moment (NaN where missing).
    pub cl_measured: Vec<f64>,
    /// Balance residual `measured - sim` (NaN where the balance is missing).
    pub residual: Vec<f64>,
    /// Raw pressure channels (NaN where missing).
    pub cp: Vec<Vec<f64>>,
    /// One-step innovation of each pressure channel (NaN where the channel is missing).
    pub innovation: Vec<Vec<f64>>,
    /// One-step innovation of each pressure channel from the filter run without that channel
    /// (NaN where it is missing): the filter's modes follow the channels that correct them, so
    /// a lag or a drift of a channel shows whole only in what the other channels expect of it.
    pub innovation_alone: Vec<Vec<f64>>,
    /// [`Self::innovation_alone`] less its mean on the sim's own recording, for runs of this
    /// kind at this angle of attack ([`super::Signature::pressure_alone_mean`]; as
    /// `innovation_alone` without a signature that has it): the channel's departure from
    /// what it read where nothing was wrong. The pressure model's mean error differs from run
    /// to run by as much as a biased or mis-scaled channel reads wrong from the start, and a
    /// fault present from the start has no onset to tell it by; the model's error repeats on
    /// every recording of the rig, the fault does not.
    pub departure_alone: Vec<Vec<f64>>,
    /// Smoothed time derivative of each measured pressure channel, 1/s.
    pub cp_dot: Vec<Vec<f64>>,
    /// The diagnosis filter, to run again with other channels withheld
    /// ([`RunStreams::innovation_without`]).
    pub replay: PressureReplay,
}

/// How the diagnosis's pressure filter runs again on one recording with channels withheld.
#[derive(Debug, Clone)]
pub enum PressureReplay {
    /// The filter's model and its inputs that [`RunStreams`] does not hold.
    Filter {
        /// The diagnosis filter's model (wide gate, no isolation).
        model: Arc<PressureTable>,
        /// The roll rate from the fit's rate filter, rad/s (the filter's input, not the
        /// zero-phase kinematics).
        phi_dot_rad_s: Vec<f64>,
    },
    /// The expectation is known whatever is withheld: the innovations are
    /// [`RunStreams::innovation_alone`] (the diagnosis modules' synthetic runs).
    #[cfg(test)]
    Known,
}

impl RunStreams {
    /// The key of this run's kind at its angle of attack (`roll@20`).
    #[must_use]
    pub fn kind_alpha_key(&self) -> String {
        kind_alpha_key(self.kind.as_str(), self.alpha_deg)
    }

    /// Takes `own_mean` (per channel, the sim's own mean of [`Self::innovation_alone`] on runs
    /// like this one) off [`Self::departure_alone`].
    pub fn remove_own_mean(&mut self, own_mean: &[f64]) {
        for ((departure, alone), mean) in self.departure_alone.iter_mut().zip(&self.innovation_alone).zip(own_mean) {
            if mean.is_finite() {
                *departure = alone.iter().map(|value| value - mean).collect();
            }
        }
    }

    /// Per channel, the mean of [`Self::innovation_alone`] over its finite samples (NaN for a
    /// channel without any).
    #[must_use]
    pub fn mean_alone(&self) -> Vec<f64> {
        self.innovation_alone
            .iter()
            .map(|channel| {
                let (sum, n) = channel
                    .iter()
                    .filter(|value| value.is_finite())
                    .fold((0.0, 0usize), |(sum, n), value| (sum + value, n + 1));
                if n == 0 { f64::NAN } else { sum / n as f64 }
            })
            .collect()
    }

    /// Per channel, [`Self::mean_alone`] where the run holds it throughout: at least
    /// `STEADY_MEAN_Z` standard errors from zero, the standard error from the scatter of the
    /// means of `STEADY_MEAN_BLOCKS` consecutive blocks (the batch-means estimate, which holds
    /// under the model error's slow correlation; Schmeiser 1982); 0 elsewhere. A level the sim
    /// reaches in part of a run only (a transient of the blowing it fits poorly) is no level of
    /// that kind of run: another recording of it need not repeat it.
    #[must_use]
    pub fn steady_mean_alone(&self) -> Vec<f64> {
        self.innovation_alone
            .iter()
            .map(|channel| {
                let block_len = channel.len() / STEADY_MEAN_BLOCKS;
                let means: Vec<f64> = (0..STEADY_MEAN_BLOCKS)
                    .filter_map(|block| {
                        let (sum, n) = channel[block * block_len..(block + 1) * block_len]
                            .iter()
                            .filter(|value| value.is_finite())
                            .fold((0.0, 0usize), |(sum, n), value| (sum + value, n + 1));
                        (n > 0).then(|| sum / n as f64)
                    })
                    .collect();
                if block_len == 0 || means.len() < 2 {
                    return 0.0;
                }
                let k = means.len() as f64;
                let mean = means.iter().sum::<f64>() / k;
                let variance = means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (k - 1.0);
                let standard_error = (variance / k).sqrt();
                if mean.abs() >= STEADY_MEAN_Z * standard_error { mean } else { 0.0 }
            })
            .collect()
    }

    /// One-step innovation of each pressure channel from the filter run with the channels
    /// marked in `left_out` withheld (read as missing): what the other channels expect of each
    /// withheld one. A lag of a group of channels shows whole only without the whole group,
    /// since the filter's modes follow every channel that corrects them.
    #[must_use]
    pub fn innovation_without(&self, left_out: &[bool]) -> Vec<Vec<f64>> {
        match &self.replay {
            PressureReplay::Filter { model, phi_dot_rad_s } => {
                let inputs =
                    FilterInputs { phi_rad: &self.phi_rad, phi_dot_rad_s, cmu: &self.cmu, alpha_deg: self.alpha_deg };
                innovations(model, &inputs, &self.cp, left_out)
            }
            #[cfg(test)]
            PressureReplay::Known => self.innovation_alone.clone(),
        }
    }

    /// Each channel's one-step innovation from the filter run without it, on the readings `cp`
    /// (one series per channel, as [`Self::cp`]) instead of the recorded ones: what the other
    /// channels, read as `cp`, expect of each (as [`Self::innovation_alone`] for the recording).
    #[must_use]
    pub fn innovations_alone_on(&self, cp: &[Vec<f64>]) -> Vec<Vec<f64>> {
        use rayon::prelude::*;
        match &self.replay {
            PressureReplay::Filter { model, phi_dot_rad_s } => {
                let inputs =
                    FilterInputs { phi_rad: &self.phi_rad, phi_dot_rad_s, cmu: &self.cmu, alpha_deg: self.alpha_deg };
                (0..cp.len())
                    .into_par_iter()
                    .map(|tap| {
                        let left_out: Vec<bool> = (0..cp.len()).map(|other| other == tap).collect();
                        innovations(model, &inputs, cp, &left_out).swap_remove(tap)
                    })
                    .collect()
            }
            // The expectation is the recording's whatever the readings: the recorded reading less
            // its innovation.
            #[cfg(test)]
            PressureReplay::Known => cp
                .iter()
                .zip(self.cp.iter().zip(&self.innovation_alone))
                .map(|(new, (old, nu))| new.iter().zip(old.iter().zip(nu)).map(|(n, (o, v))| n - (o - v)).collect())
                .collect(),
        }
    }

    /// The roll acceleration smoothed at `corner_hz`, one of [`MODE_DRIVE_CORNERS_HZ`] (`None`
    /// for another corner).
    #[must_use]
    pub fn acceleration_at(&self, corner_hz: f64) -> Option<&[f64]> {
        match MODE_DRIVE_CORNERS_HZ.iter().position(|c| *c == corner_hz)? {
            0 => Some(&self.phi_ddot_rad_s2),
            slot => self.phi_ddot_smoother_rad_s2.get(slot - 1).map(Vec::as_slice),
        }
    }

    /// Number of samples.
    #[must_use]
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// True without samples.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// The sim's total moment at each sample.
    #[must_use]
    pub fn cl_sim(&self) -> Vec<f64> {
        (0..self.len())
            .map(|idx| self.cl_egk[idx] + self.cl_afc_side[0][idx] + self.cl_afc_side[1][idx] + self.coupling[idx])
            .collect()
    }

    /// The sim's plant moment (both jets).
    #[must_use]
    pub fn cl_afc(&self) -> Vec<f64> {
        (0..self.len()).map(|idx| self.cl_afc_side[0][idx] + self.cl_afc_side[1][idx]).collect()
    }

    /// True when the run excites the roll motion.
    #[must_use]
    pub fn rolls(&self) -> bool {
        matches!(self.kind, RunKind::Roll | RunKind::RollActuation | RunKind::Static)
    }

    /// True when the run excites the blowing.
    #[must_use]
    pub fn blows(&self) -> bool {
        matches!(self.kind, RunKind::Actuation | RunKind::RollActuation | RunKind::Static)
    }

    /// The training samples less the selection blocks: where candidates are fitted.
    pub fn fit_samples(&self) -> impl Iterator<Item = usize> + '_ {
        self.training.clone().filter(|&idx| self.is_fit_sample(idx))
    }

    /// Whether sample `idx` is one of [`Self::fit_samples`].
    #[must_use]
    pub fn is_fit_sample(&self, idx: usize) -> bool {
        self.training.contains(&idx) && !self.select.contains(idx)
    }

    /// Re-runs the sim's plants on other Cmu sequences (one per jet), as the core steps them.
    #[must_use]
    pub fn plant_response(&self, set: &CoefficientSet, cmu: &[Vec<f64>; 2]) -> Vec<f64> {
        let [port, stbd] = self.plant_sides(set, cmu);
        port.iter().zip(&stbd).map(|(a, b)| a + b).collect()
    }

    /// Re-runs the sim's plants on other Cmu sequences (one per jet): each jet's moment.
    #[must_use]
    pub fn plant_sides(&self, set: &CoefficientSet, cmu: &[Vec<f64>; 2]) -> [Vec<f64>; 2] {
        let alpha_rad = self.alpha_deg.to_radians() as f32;
        [0, 1].map(|side| {
            let mut plant = Plant::new();
            cmu[side].iter().map(|&c| f64::from(plant.step(&set.plant[side], c as f32, alpha_rad).0)).collect()
        })
    }
}

/// Builds the streams of every run.
#[must_use]
pub fn build(dataset: &Dataset, set: &CoefficientSet, split: &Split) -> Vec<RunStreams> {
    use rayon::prelude::*;
    dataset.runs.par_iter().map(|run| build_run(run, set, split)).collect()
}

fn build_run(run: &Run, set: &CoefficientSet, split: &Split) -> RunStreams {
    let n = run.channels.len();
    let sample_hz = run.meta.sample_hz;
    let dt_s = 1.0 / sample_hz;
    let t0 = run.channels.t_s.first().copied().unwrap_or(0.0);
    let t_s: Vec<f64> = run.channels.t_s.iter().map(|t| t - t0).collect();

    // The sim: the core with the pressure channels withheld.
    let mut estimator = Estimator::new(set);
    let (mut cl_egk, mut afc_port, mut afc_stbd, mut coupling) =
        (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    for idx in 0..n {
        let input = Input { cp: [f32::NAN; N_TAPS], ..input_at(run, idx) };
        let output = estimator.step(&input);
        cl_egk.push(f64::from(output.cl_egk));
        afc_port.push(f64::from(output.cl_afc_port));
        afc_stbd.push(f64::from(output.cl_afc_stbd));
        coupling.push(f64::from(output.coupling));
    }
    let cl_measured = run.channels.cl.clone();
    let residual: Vec<f64> = (0..n)
        .map(|idx| {
            let measured = cl_measured[idx];
            if measured.is_finite() {
                measured - (cl_egk[idx] + afc_port[idx] + afc_stbd[idx] + coupling[idx])
            } else {
                f64::NAN
            }
        })
        .collect();

    let phi_rad: Vec<f64> = hold_missing(&run.channels.phi_deg, 0.0).iter().map(|phi| phi.to_radians()).collect();
    let smooth_phi = zero_phase_lowpass_extended(&phi_rad, KINEMATICS_CORNER_HZ.min(0.4 * sample_hz), sample_hz);
    let phi_dot_rad_s = central_difference(&smooth_phi, dt_s);
    let phi_ddot_rad_s2 = central_difference(&phi_dot_rad_s, dt_s);
    let phi_ddot_smoother_rad_s2 =
        MODE_DRIVE_CORNERS_HZ[1..].iter().map(|corner_hz| acceleration(&phi_rad, *corner_hz, sample_hz)).collect();
    let cmu = [hold_missing(&run.channels.cmu_port, 0.0), hold_missing(&run.channels.cmu_stbd, 0.0)]
        .map(|cmu| cmu.into_iter().map(|value| value.max(0.0)).collect::<Vec<f64>>());

    let cp: Vec<Vec<f64>> = run.channels.cp.iter().map(Clone::clone).collect();
    let mut table = PressureTable::from_set(set);
    table.model.gate_sigma = GATE_SIGMA;
    table.model.isolate_after = u16::MAX;
    let model = Arc::new(table);
    let (filter_phi_dot_rad_s, _) = differentiate(&phi_rad, &set.rate_filter, dt_s);
    let inputs = FilterInputs {
        phi_rad: &phi_rad,
        phi_dot_rad_s: &filter_phi_dot_rad_s,
        cmu: &cmu,
        alpha_deg: run.meta.alpha_deg,
    };
    let innovation = innovations(&model, &inputs, &cp, &[]);
    let innovation_alone: Vec<Vec<f64>> = (0..N_TAPS)
        .into_par_iter()
        .map(|tap| {
            let left_out: Vec<bool> = (0..N_TAPS).map(|other| other == tap).collect();
            innovations(&model, &inputs, &cp, &left_out).swap_remove(tap)
        })
        .collect();
    let cp_dot = cp.iter().map(|channel| pressure_derivative(channel, sample_hz)).collect();

    RunStreams {
        file: run.meta.file.display().to_string(),
        kind: run.meta.kind,
        alpha_deg: run.meta.alpha_deg,
        sample_hz,
        training: split.training(n),
        select: Interleave::over(split.training(n), sample_hz),
        heldout: split.heldout(n),
        t_s,
        phi_rad,
        phi_dot_rad_s,
        phi_ddot_rad_s2,
        phi_ddot_smoother_rad_s2,
        cmu,
        cl_egk,
        cl_afc_side: [afc_port, afc_stbd],
        coupling,
        cl_measured,
        residual,
        cp,
        innovation,
        departure_alone: innovation_alone.clone(),
        innovation_alone,
        cp_dot,
        replay: PressureReplay::Filter { model, phi_dot_rad_s: filter_phi_dot_rad_s },
    }
}

/// Central difference (one-sided at the ends).
#[must_use]
pub fn central_difference(values: &[f64], dt_s: f64) -> Vec<f64> {
    let n = values.len();
    (0..n)
        .map(|idx| match (idx.checked_sub(1), (idx + 1 < n).then_some(idx + 1)) {
            (Some(prev), Some(next)) => (values[next] - values[prev]) / (2.0 * dt_s),
            (None, Some(next)) => (values[next] - values[idx]) / dt_s,
            (Some(prev), None) => (values[idx] - values[prev]) / dt_s,
            (None, None) => 0.0,
        })
        .collect()
}

/// Innovation gate of the diagnosis's filter, in steady-state standard deviations: wide, so
/// that only a gross fault (which would otherwise drag the shared modes) is kept out.
const GATE_SIGMA: f64 = 6.0;

/// The pressure filter's inputs besides the readings, per sample.
struct FilterInputs<'a> {
    phi_rad: &'a [f64],
    phi_dot_rad_s: &'a [f64],
    cmu: &'a [Vec<f64>; 2],
    alpha_deg: f64,
}

/// The pressure filter's one-step innovations per channel, `cp - (C (A a + B u) + cp_mean)`:
/// the core's filter in f64 ([`filter_step`]) with a wider gate and no isolation, so that every channel's innovation is reported and one bad channel
/// does not drag the others. The channels marked in `left_out` are withheld from the filter
/// (read as missing) and their innovations are what the other channels expect of them.
fn innovations(model: &PressureTable, inputs: &FilterInputs<'_>, cp: &[Vec<f64>], left_out: &[bool]) -> Vec<Vec<f64>> {
    let n = inputs.phi_rad.len();
    let mut filter = PressureFilter::at_start(&model.model);
    let mut out: Vec<Vec<f64>> = (0..N_TAPS).map(|_| Vec::with_capacity(n)).collect();
    for idx in 0..n {
        let drive = [inputs.phi_rad[idx], inputs.phi_dot_rad_s[idx], inputs.cmu[0][idx], inputs.cmu[1][idx], 1.0];
        let measured: [f64; N_TAPS] = std::array::from_fn(|tap| cp.get(tap).map_or(f64::NAN, |channel| channel[idx]));
        let filtered: [f64; N_TAPS] =
            std::array::from_fn(
                |tap| if left_out.get(tap).copied().unwrap_or(false) { f64::NAN } else { measured[tap] },
            );
        // Only the innovations are used: the map to C_l (and so alpha) does not matter here.
        let step = filter_step(&mut filter, model, &drive, &filtered, inputs.alpha_deg);
        for (tap, channel) in out.iter_mut().enumerate() {
            channel.push(if measured[tap].is_finite() { measured[tap] - step.predicted_cp[tap] } else { f64::NAN });
        }
    }
    out
}

/// The smoothed time derivative of one pressure channel, 1/s: zero-phase smoothed at
/// `PRESSURE_CORNER_HZ`, then central differences (NaN where the channel is missing). The
/// regressor of a tubing lag, `p = y + tau y'` ([`RunStreams::cp_dot`]).
#[must_use]
pub fn pressure_derivative(channel: &[f64], sample_hz: f64) -> Vec<f64> {
    let smooth = zero_phase_lowpass_extended(channel, PRESSURE_CORNER_HZ.min(0.4 * sample_hz), sample_hz);
    let mut derivative = central_difference(&smooth, 1.0 / sample_hz);
    for (value, raw) in derivative.iter_mut().zip(channel) {
        if !raw.is_finite() {
            *value = f64::NAN;
        }
    }
    derivative
}

/// The roll acceleration of `phi_rad`, rad/s^2: the angle smoothed without phase at `corner_hz`
/// (at most 0.4 of the sample rate, the ends extended by odd reflection), differentiated twice.
#[must_use]
pub fn acceleration(phi_rad: &[f64], corner_hz: f64, sample_hz: f64) -> Vec<f64> {
    let dt_s = 1.0 / sample_hz;
    let smooth = zero_phase_lowpass_extended(phi_rad, corner_hz.min(0.4 * sample_hz), sample_hz);
    central_difference(&central_difference(&smooth, dt_s), dt_s)
}

/// A run for the diagnosis modules' own tests: the split every diagnosis uses (four fifths
/// training with interleaved selection blocks, the last fifth held out), still wing, no blowing,
/// and the given pressure readings and innovations (the filter's expectation is their
/// difference).
#[cfg(test)]
pub(crate) fn synthetic_run(sample_hz: f64, cp: Vec<Vec<f64>>, innovation: Vec<Vec<f64>>) -> RunStreams {
    let n = cp.first().map_or(0, Vec::len);
    let training = 0..n * 4 / 5;
    let zeros = vec![0.0; n];
    RunStreams {
        file: "synthetic.csv".into(),
        kind: RunKind::Static,
        alpha_deg: 10.0,
        sample_hz,
        select: Interleave::over(training.clone(), sample_hz),
        training,
        heldout: n * 4 / 5..n,
        t_s: (0..n).map(|i| i as f64 / sample_hz).collect(),
        phi_rad: zeros.clone(),
        phi_dot_rad_s: zeros.clone(),
        phi_ddot_rad_s2: zeros.clone(),
        phi_ddot_smoother_rad_s2: MODE_DRIVE_CORNERS_HZ[1..].iter().map(|_| zeros.clone()).collect(),
        cmu: [zeros.clone(), zeros.clone()],
        cl_egk: zeros.clone(),
        cl_afc_side: [zeros.clone(), zeros.clone()],
        coupling: zeros.clone(),
        cl_measured: zeros.clone(),
        residual: zeros.clone(),
        cp_dot: cp.iter().map(|channel| pressure_derivative(channel, sample_hz)).collect(),
        cp,
        innovation_alone: innovation.clone(),
        departure_alone: innovation.clone(),
        innovation,
        replay: PressureReplay::Known,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The derivative of `t^2` is `2 t` exactly inside the run (central differences) and one
    /// sample's slope at the ends.
    #[test]
    fn central_differences_are_exact_for_a_parabola_inside_the_run() {
        let dt_s = 0.01;
        let values: Vec<f64> = (0..50).map(|i| (i as f64 * dt_s).powi(2)).collect();
        let slope = central_difference(&values, dt_s);
        for (idx, value) in slope.iter().enumerate().take(49).skip(1) {
            assert!((value - 2.0 * idx as f64 * dt_s).abs() < 1e-9, "{idx}: {value}");
        }
        assert!((slope[0] - dt_s).abs() < 1e-9 && (slope[49] - (values[49] - values[48]) / dt_s).abs() < 1e-12);
        assert_eq!(central_difference(&[3.0], dt_s), vec![0.0]);
    }

    /// A roll of 1 Hz and 0.3 rad, read in steps of 0.005 deg: its acceleration smoothed at
    /// 4 Hz is within 3 % of the motion's RMS away from the ends; at 40 Hz the quantisation,
    /// differentiated twice, is far larger. Within about a period of the corner of a run's ends
    /// a low corner errs (odd reflection keeps the angle's value and slope there, not its
    /// curvature; a reflection about a local parabola did no better on the second tunnel's
    /// rolls): measured and bounded here, so that a change shows.
    #[test]
    fn the_acceleration_of_a_quantised_roll_is_resolved_at_a_low_corner_away_from_the_ends() {
        let (sample_hz, n) = (1000.0, 5_300);
        let omega = std::f64::consts::TAU;
        let quantum_rad = 0.005f64.to_radians();
        let t = |i: usize| i as f64 / sample_hz;
        let phi: Vec<f64> =
            (0..n).map(|i| ((0.3 * (omega * t(i) + 0.4).sin()) / quantum_rad).round() * quantum_rad).collect();
        let truth: Vec<f64> = (0..n).map(|i| -0.3 * omega * omega * (omega * t(i) + 0.4).sin()).collect();
        let rms = (truth.iter().map(|a| a * a).sum::<f64>() / n as f64).sqrt();
        let worst = |corner_hz: f64, samples: std::ops::Range<usize>| {
            let estimate = acceleration(&phi, corner_hz, sample_hz);
            samples.map(|i| (estimate[i] - truth[i]).abs()).fold(0.0, f64::max) / rms
        };
        let inside = 250..n - 250;
        assert!(worst(4.0, inside.clone()) < 0.03, "{}", worst(4.0, inside.clone()));
        assert!(worst(40.0, inside.clone()) > 5.0 * worst(4.0, inside.clone()), "{}", worst(40.0, inside));
        assert!(worst(4.0, 0..n) < 1.5, "{}", worst(4.0, 0..n));
        assert_eq!(MODE_DRIVE_CORNERS_HZ[0], KINEMATICS_CORNER_HZ);
    }
}

//! The pressure path: a time-shifted (delay-embedded), reduced linear model of the 12 surface
//! pressures with control inputs (DMDc), corrected every step by the measured pressures through
//! a steady-state Kalman gain, then mapped linearly to `C_l,roll,p` (paper section III.A after
//! B. W. Brunton et al., J. Neurosci. Methods 258, 2016; docs/equations.md, Time-shifted pressure
//! model and its Kalman filter).
//!
//! The gain `K` comes from the discrete algebraic Riccati equation solved in f64 on the host, so
//! the target propagates no covariance: per step this is `A a + B u`, the 12 innovations, and
//! `K nu` (Anderson & Moore, Optimal Filtering, ch. 4). Each channel is updated on its own:
//! a missing channel (NaN) skips its update, and a channel whose innovation exceeds
//! `gate_sigma` times its steady-state standard deviation is rejected and flagged; after
//! `isolate_after` consecutive rejections it is isolated until it passes the gate as many times
//! in a row. The gate is armed once the filter has settled from its start at the mean pressures
//! (`settle_steps`; until then every finite reading is used and the step is flagged
//! `PRESSURE_SETTLING`).
//!
//! A stuck channel (a frozen ADC or a blocked tube) can stay inside the gate for a long time,
//! because its innovation only grows as the true pressure moves away. But a live pressure
//! reading carries sensor noise (sigma about 0.01 Cp against a 12-bit quantum of about 0.001):
//! the same bit pattern [`STUCK_AFTER_STEPS`] times in a row happens only when the reading is
//! frozen. Such a channel fails the gate (rejected, then isolated like any other) until its
//! value changes.

use crate::coeffs::{N_ALPHA, N_PRESSURE_INPUTS, N_TAPS, PRESSURE_RANK, PressureModel};
use crate::health::Health;
use crate::real::Real;
use crate::schedule::SchedulePosition;

/// Every tap's bit.
const ALL_TAPS: u16 = (1 << N_TAPS) - 1;

/// Largest Euclidean norm the reduced state may reach before it is treated as diverged and
/// reset (its square is checked: a sum of squares costs one multiply-add per mode, and a NaN
/// or an overflow fails the comparison as well).
const STATE_LIMIT: f32 = 1.0e6;

/// Consecutive bit-identical readings after which a channel counts as stuck (20 ms at 1 kHz,
/// within the 50 ms in which a faulty channel must be flagged). With noise of 10 quanta, 20
/// equal readings in a row of a live channel have a probability far below 1e-20.
pub const STUCK_AFTER_STEPS: u8 = 20;

/// The pressure filter's state, in the scalar `R` (f32 on the target, f64 in the host's fit
/// and diagnosis; [`crate::real`]).
///
/// Loops run over the full [`PRESSURE_RANK`] (unused modes are zero rows and columns), so that
/// they unroll and vectorise; `rank` only documents how many modes the fit used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PressureFilter<R: Real = f32> {
    modes: [R; PRESSURE_RANK],
    /// `w^T C` at each breakpoint of the alpha schedule: the roll-moment map applied to the
    /// modes directly, so the step does not rebuild the 12 filtered pressures.
    mode_weights: [[R; PRESSURE_RANK]; N_ALPHA],
    /// `w . cp_mean + w0` at each breakpoint.
    cl_constant: [R; N_ALPHA],
    /// `gate_sigma * innovation_std`: the largest accepted innovation of each tap.
    gate_limit: [R; N_TAPS],
    /// Consecutive rejections (or, for an isolated channel, consecutive passes) per channel.
    streak: [u16; N_TAPS],
    /// Channels whose streak is not zero.
    streaking: u16,
    isolated: u16,
    /// Bit pattern of each channel's last finite reading.
    last_bits: [R::Bits; N_TAPS],
    /// Consecutive readings of each channel equal to the one before (saturating): a channel
    /// is stuck at `STUCK_AFTER_STEPS - 1` repeats, its `STUCK_AFTER_STEPS`-th equal reading.
    repeats: [u8; N_TAPS],
    /// Channels whose `repeats` is not zero.
    repeating: u16,
    /// Steps left before the gate is armed (`PressureModel::settle_steps`).
    settling: u16,
}

/// Result of one pressure step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PressureEstimate<R = f32> {
    /// `C_l,roll,p` from the filtered pressures.
    pub cl: R,
    /// True when at least one channel corrected the prediction this step.
    pub measured: bool,
}

/// The filter at the mean pressures, no channel isolated, for `$model`, in the scalar `$r`:
/// one body for the f32 `const` constructor and the generic one.
macro_rules! filter_at_start {
    ($r:ty, $model:expr) => {{
        let model = $model;
        let zero = <$r as Real>::ZERO;
        let mut mode_weights = [[zero; PRESSURE_RANK]; N_ALPHA];
        let mut cl_constant = model.cl_offset;
        let mut gate_limit = [zero; N_TAPS];
        let mut tap = 0;
        while tap < N_TAPS {
            let mut breakpoint = 0;
            while breakpoint < N_ALPHA {
                let weight = model.cl_weights[breakpoint][tap];
                let mut mode = 0;
                while mode < PRESSURE_RANK {
                    mode_weights[breakpoint][mode] += weight * model.c[tap][mode];
                    mode += 1;
                }
                cl_constant[breakpoint] += weight * model.cp_mean[tap];
                breakpoint += 1;
            }
            gate_limit[tap] = model.gate_sigma * model.innovation_std[tap];
            tap += 1;
        }
        PressureFilter {
            modes: [zero; PRESSURE_RANK],
            mode_weights,
            cl_constant,
            gate_limit,
            streak: [0; N_TAPS],
            streaking: 0,
            isolated: 0,
            last_bits: [<$r as Real>::NO_READING_BITS; N_TAPS],
            repeats: [0; N_TAPS],
            repeating: 0,
            settling: model.settle_steps,
        }
    }};
}

impl PressureFilter {
    /// At the mean pressures, no channel isolated, for the given model (`const`, so the
    /// estimator can live in a `static`).
    #[must_use]
    pub const fn new(model: &PressureModel) -> Self {
        filter_at_start!(f32, model)
    }
}

impl<R: Real> PressureFilter<R> {
    /// At the mean pressures, no channel isolated, for the given model: [`PressureFilter::new`]
    /// in any scalar.
    #[must_use]
    pub fn at_start(model: &PressureModel<R>) -> Self {
        filter_at_start!(R, model)
    }

    /// True when the constants derived from the model (the roll-moment map of the modes, its
    /// constant and the gate limits) are finite: finite tables can overflow in their products.
    #[must_use]
    pub fn derived_constants_are_finite(&self) -> bool {
        self.cl_constant
            .iter()
            .chain(self.mode_weights.iter().flatten())
            .chain(&self.gate_limit)
            .all(|value| value.is_finite())
    }

    /// The reduced state.
    #[must_use]
    pub const fn modes(&self) -> &[R; PRESSURE_RANK] {
        &self.modes
    }

    /// The filtered pressures `C a + cp_mean` of the present state.
    #[must_use]
    pub fn filtered_cp(&self, model: &PressureModel<R>) -> [R; N_TAPS] {
        output(&model.c, &model.cp_mean, &self.modes)
    }

    /// Predicts with the inputs `u`, corrects with the measured pressures `cp` and returns the
    /// pressure-based roll moment with the map at `at` in the alpha schedule. Channel bits of
    /// `health` are set here.
    pub fn step(
        &mut self,
        model: &PressureModel<R>,
        at: SchedulePosition<R>,
        inputs: &[R; N_PRESSURE_INPUTS],
        cp: &[R; N_TAPS],
        health: &mut Health,
    ) -> PressureEstimate<R> {
        self.step_observed(model, at, inputs, cp, health, |_| {})
    }

    /// [`PressureFilter::step`], showing `expected` the pressures the model predicts for this
    /// step before any reading corrects them (`C (A a + B u) + cp_mean`; the innovation of a
    /// reading is the reading minus this): the host's fit scores them, and its diagnosis reads
    /// what the other channels expect of a withheld one.
    #[inline(always)]
    pub fn step_observed(
        &mut self,
        model: &PressureModel<R>,
        at: SchedulePosition<R>,
        inputs: &[R; N_PRESSURE_INPUTS],
        cp: &[R; N_TAPS],
        health: &mut Health,
        mut expected: impl FnMut(&[R; N_TAPS]),
    ) -> PressureEstimate<R> {
        let predicted = predict(&model.a, &model.b, &self.modes, inputs);
        // Branch-free over the taps: a missing reading gives a NaN or infinite innovation,
        // which fails the gate (a NaN compares false) and is zeroed below before it is used.
        let mut innovation = output(&model.c, &model.cp_mean, &predicted);
        expected(&innovation);
        let mut pass_mask = 0u16;
        for (tap, ((value, &measured), &limit)) in innovation.iter_mut().zip(cp).zip(&self.gate_limit).enumerate() {
            let nu = measured - *value;
            *value = nu;
            pass_mask |= u16::from(nu.abs() <= limit) << tap;
        }
        // A passing channel has a finite innovation, hence a finite reading: only the channels
        // that failed need a look of their own (one or two in a fault or at start-up).
        let finite_mask = set_bits(!pass_mask & ALL_TAPS).fold(ALL_TAPS, |mask, tap| {
            let finite = cp.get(tap).is_some_and(|value| Real::is_finite(*value));
            if finite { mask } else { mask & !(1 << tap) }
        });
        pass_mask &= finite_mask;
        health.cp_missing |= !finite_mask & ALL_TAPS;
        // While the filter settles from the mean pressures, and when every measured channel
        // fails at once (a jump of the inputs), the prediction is off, not the sensors: accept
        // them all rather than lose the filter.
        if self.settling != 0 {
            self.settling -= 1;
            health.set(Health::PRESSURE_SETTLING);
            pass_mask = finite_mask;
        } else if pass_mask == 0 {
            pass_mask = finite_mask;
        }
        // A frozen reading never passes, even when all are frozen (the whole front end hung).
        pass_mask &= !self.stuck_mask(cp, finite_mask);
        let used_mask = self.track_faults(model, finite_mask, pass_mask, health);
        for tap in set_bits(!used_mask & ALL_TAPS) {
            if let Some(value) = innovation.get_mut(tap) {
                *value = R::ZERO;
            }
        }
        let measured = used_mask != 0;
        self.modes = correct(&model.gain, &predicted, &innovation);
        let limit = R::from_f32(STATE_LIMIT);
        let within_limit = dot(&self.modes, &self.modes) <= limit * limit;
        if !within_limit {
            self.modes = [R::ZERO; PRESSURE_RANK];
            health.set(Health::STATE_RESET);
        }
        health.cp_isolated = self.isolated;
        let map_at = |breakpoint: usize| {
            let breakpoint = breakpoint.min(N_ALPHA - 1);
            dot(&self.mode_weights[breakpoint], &self.modes) + self.cl_constant[breakpoint]
        };
        let lower = map_at(at.lower);
        let cl = if at.weight == R::ZERO { lower } else { lower + at.weight * (map_at(at.upper) - lower) };
        if !cl.is_finite() {
            // Only with tables whose products overflow (validation rejects them): never pass
            // on a non-finite estimate.
            self.modes = [R::ZERO; PRESSURE_RANK];
            health.set(Health::STATE_RESET);
            return PressureEstimate { cl: R::ZERO, measured: false };
        }
        PressureEstimate { cl, measured }
    }

    /// Counts each channel's bit-identical repeats and returns the channels that are stuck
    /// ([`STUCK_AFTER_STEPS`] equal readings in a row). A missing reading (NaN, infinite; not
    /// in `finite_mask`) neither counts nor breaks the streak, so dropouts cannot hide a frozen
    /// channel.
    fn stuck_mask(&mut self, cp: &[R; N_TAPS], finite_mask: u16) -> u16 {
        // Zipped iterators, not indices: the optimiser then needs no bounds check (and the
        // step keeps its link-time proof of no panic path); selects rather than branches keep
        // the loop cheap on the M4F.
        let mut repeated = 0u16;
        let channels = cp.iter().zip(self.last_bits.iter_mut()).enumerate();
        if finite_mask == ALL_TAPS {
            for (tap, (value, last_bits)) in channels {
                let bits = value.bits();
                repeated |= u16::from(bits == *last_bits) << tap;
                *last_bits = bits;
            }
        } else {
            for (tap, (value, last_bits)) in channels {
                let bits = value.bits();
                repeated |= u16::from(bits == *last_bits) << tap;
                *last_bits = if finite_mask & (1 << tap) != 0 { bits } else { *last_bits };
            }
        }
        repeated &= finite_mask;
        // Only channels that repeated now or had a run of repeats going change their count (the
        // usual step has none); a count is non-zero after the update exactly when the channel
        // repeated, and only a channel that repeated can be stuck.
        let touched = (repeated | self.repeating) & finite_mask;
        self.repeating = (self.repeating & !touched) | repeated;
        let mut stuck = 0u16;
        for tap in set_bits(touched) {
            if let Some(repeats) = self.repeats.get_mut(tap) {
                *repeats = if repeated & (1 << tap) != 0 { repeats.saturating_add(1) } else { 0 };
                stuck |= u16::from(*repeats >= STUCK_AFTER_STEPS - 1) << tap;
            }
        }
        stuck
    }

    /// Updates each measured channel's streak and isolation from whether it passed the gate,
    /// flags rejections, and returns the channels that correct the prediction this step.
    fn track_faults(&mut self, model: &PressureModel<R>, finite_mask: u16, pass_mask: u16, health: &mut Health) -> u16 {
        // The usual step: every measured channel passes and none is isolated or has a streak
        // running, so every streak stays zero and nothing changes.
        if pass_mask == finite_mask && self.isolated == 0 && self.streaking & finite_mask == 0 {
            return pass_mask;
        }
        health.cp_rejected |= finite_mask & !pass_mask;
        // A rejection of a healthy channel, or a pass of an isolated one, extends its streak;
        // any other measured channel's streak ends. Only the set bits are visited: one or two
        // channels in a fault, not all twelve.
        let extending = finite_mask & !(pass_mask ^ self.isolated) & ALL_TAPS;
        let ending = finite_mask & (pass_mask ^ self.isolated) & self.streaking;
        for tap in set_bits(ending) {
            if let Some(streak) = self.streak.get_mut(tap) {
                *streak = 0;
            }
        }
        self.streaking &= !ending;
        let isolate_after = model.isolate_after.max(1);
        for tap in set_bits(extending) {
            if let Some(streak) = self.streak.get_mut(tap) {
                let bit = 1u16 << tap;
                *streak = streak.saturating_add(1);
                if *streak >= isolate_after {
                    self.isolated ^= bit;
                    *streak = 0;
                    self.streaking &= !bit;
                } else {
                    self.streaking |= bit;
                }
            }
        }
        pass_mask & !self.isolated
    }
}

/// The indices of the set bits of `mask`, lowest first.
fn set_bits(mut mask: u16) -> impl Iterator<Item = usize> {
    core::iter::from_fn(move || {
        if mask == 0 {
            return None;
        }
        let index = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        Some(index)
    })
}

// The three matrix products below are functions of their own (`inline(never)`), each given
// its matrix: fully unrolled, every coefficient then loads with a small offset from that
// matrix's address. Inlined into the step, the loads were addressed from the start of the
// 2.6 kB coefficient set, beyond the 1 kB reach of the M4F's VLDR, and each needed an address
// computation of its own, which doubled the instructions per multiply-add. A zero row (a mode
// past the model's rank) gives zero.

/// `A a + B u`.
#[cfg(all(target_os = "none", not(feature = "nalgebra")))]
#[inline(never)]
fn predict<R: Real>(
    a: &[[R; PRESSURE_RANK]; PRESSURE_RANK],
    b: &[[R; N_PRESSURE_INPUTS]; PRESSURE_RANK],
    modes: &[R; PRESSURE_RANK],
    inputs: &[R; N_PRESSURE_INPUTS],
) -> [R; PRESSURE_RANK] {
    core::array::from_fn(|row| dot(&a[row], modes) + dot(&b[row], inputs))
}

/// `C a + cp_mean`: the pressures the model expects.
#[cfg(all(target_os = "none", not(feature = "nalgebra")))]
#[inline(never)]
fn output<R: Real>(c: &[[R; PRESSURE_RANK]; N_TAPS], cp_mean: &[R; N_TAPS], modes: &[R; PRESSURE_RANK]) -> [R; N_TAPS] {
    core::array::from_fn(|tap| dot(&c[tap], modes) + cp_mean[tap])
}

/// `a + K nu`: the corrected state.
#[cfg(all(target_os = "none", not(feature = "nalgebra")))]
#[inline(never)]
fn correct<R: Real>(
    gain: &[[R; N_TAPS]; PRESSURE_RANK],
    predicted: &[R; PRESSURE_RANK],
    innovation: &[R; N_TAPS],
) -> [R; PRESSURE_RANK] {
    core::array::from_fn(|mode| predicted[mode] + dot(&gain[mode], innovation))
}

// On the host the same products run column by column ([`by_columns`]): every row's sum gets
// the same operations in the same order as `dot` (the host replay stays bit-identical to the
// firmware in QEMU, which the firmware tests check), but the rows are independent chains that
// the host's vector units run side by side instead of one dependent chain per row.

/// `A a + B u`, on the host.
#[cfg(all(not(target_os = "none"), not(feature = "nalgebra")))]
fn predict<R: Real>(
    a: &[[R; PRESSURE_RANK]; PRESSURE_RANK],
    b: &[[R; N_PRESSURE_INPUTS]; PRESSURE_RANK],
    modes: &[R; PRESSURE_RANK],
    inputs: &[R; N_PRESSURE_INPUTS],
) -> [R; PRESSURE_RANK] {
    let (from_modes, from_inputs) = (by_columns(a, modes), by_columns(b, inputs));
    core::array::from_fn(|row| from_modes[row] + from_inputs[row])
}

/// `C a + cp_mean`, on the host.
#[cfg(all(not(target_os = "none"), not(feature = "nalgebra")))]
fn output<R: Real>(c: &[[R; PRESSURE_RANK]; N_TAPS], cp_mean: &[R; N_TAPS], modes: &[R; PRESSURE_RANK]) -> [R; N_TAPS] {
    let products = by_columns(c, modes);
    core::array::from_fn(|tap| products[tap] + cp_mean[tap])
}

/// `a + K nu`, on the host.
#[cfg(all(not(target_os = "none"), not(feature = "nalgebra")))]
fn correct<R: Real>(
    gain: &[[R; N_TAPS]; PRESSURE_RANK],
    predicted: &[R; PRESSURE_RANK],
    innovation: &[R; N_TAPS],
) -> [R; PRESSURE_RANK] {
    let products = by_columns(gain, innovation);
    core::array::from_fn(|mode| predicted[mode] + products[mode])
}

/// `m x` with each row summed as [`dot`] sums it (from `-0.0`, in column order), computed
/// column by column so that the rows' sums are independent.
#[cfg(not(target_os = "none"))]
#[inline(always)]
fn by_columns<R: Real, const N: usize, const M: usize>(m: &[[R; M]; N], x: &[R; M]) -> [R; N] {
    let mut sums = [R::NEG_ZERO; N];
    for (column, &value) in x.iter().enumerate() {
        for (sum, row) in sums.iter_mut().zip(m) {
            if let Some(&entry) = row.get(column) {
                *sum += entry * value;
            }
        }
    }
    sums
}

/// `A a + B u` by nalgebra (the measurement variant that `cargo xtask weigh` weighs).
#[cfg(feature = "nalgebra")]
#[inline(never)]
fn predict<R: Real>(
    a: &[[R; PRESSURE_RANK]; PRESSURE_RANK],
    b: &[[R; N_PRESSURE_INPUTS]; PRESSURE_RANK],
    modes: &[R; PRESSURE_RANK],
    inputs: &[R; N_PRESSURE_INPUTS],
) -> [R; PRESSURE_RANK] {
    let driven = R::mat_vec_add(b, inputs, &[R::ZERO; PRESSURE_RANK]);
    R::mat_vec_add(a, modes, &driven)
}

/// `C a + cp_mean` by nalgebra.
#[cfg(feature = "nalgebra")]
#[inline(never)]
fn output<R: Real>(c: &[[R; PRESSURE_RANK]; N_TAPS], cp_mean: &[R; N_TAPS], modes: &[R; PRESSURE_RANK]) -> [R; N_TAPS] {
    R::mat_vec_add(c, modes, cp_mean)
}

/// `a + K nu` by nalgebra.
#[cfg(feature = "nalgebra")]
#[inline(never)]
fn correct<R: Real>(
    gain: &[[R; N_TAPS]; PRESSURE_RANK],
    predicted: &[R; PRESSURE_RANK],
    innovation: &[R; N_TAPS],
) -> [R; PRESSURE_RANK] {
    R::mat_vec_add(gain, innovation, predicted)
}

/// Dot product, summed in order. It starts from `-0.0`, the identity of addition
/// (`-0.0 + x == x` for every `x`, signed zeros included), so the first product is not added
/// to a zero that would need its own instruction.
#[cfg_attr(any(feature = "nalgebra", not(target_os = "none")), allow(dead_code))]
fn dot<R: Real, const N: usize>(a: &[R; N], b: &[R; N]) -> R {
    a.iter().zip(b).fold(R::NEG_ZERO, |sum, (&x, &y)| sum + x * y)
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // Index loops read like the matrix formulas they check.
mod tests {
    use super::*;
    use crate::prior::PRIOR;

    type Matrix = Vec<Vec<f64>>;

    fn zeros(rows: usize, cols: usize) -> Matrix {
        vec![vec![0.0; cols]; rows]
    }

    fn mul(a: &Matrix, b: &Matrix) -> Matrix {
        let mut out = zeros(a.len(), b[0].len());
        for i in 0..a.len() {
            for j in 0..b[0].len() {
                out[i][j] = (0..b.len()).map(|k| a[i][k] * b[k][j]).sum();
            }
        }
        out
    }

    fn transpose(a: &Matrix) -> Matrix {
        (0..a[0].len()).map(|j| (0..a.len()).map(|i| a[i][j]).collect()).collect()
    }

    fn add(a: &Matrix, b: &Matrix, sign: f64) -> Matrix {
        a.iter().zip(b).map(|(ra, rb)| ra.iter().zip(rb).map(|(x, y)| x + sign * y).collect()).collect()
    }

    /// Gauss-Jordan inverse with partial pivoting (test reference only).
    fn inverse(a: &Matrix) -> Matrix {
        let n = a.len();
        let mut work: Matrix = a
            .iter()
            .enumerate()
            .map(|(i, row)| {
                let mut extended = row.clone();
                extended.extend((0..n).map(|j| f64::from(u8::from(i == j))));
                extended
            })
            .collect();
        for col in 0..n {
            let pivot = (col..n).max_by(|&x, &y| work[x][col].abs().total_cmp(&work[y][col].abs())).unwrap();
            work.swap(col, pivot);
            let scale = work[col][col];
            work[col].iter_mut().for_each(|value| *value /= scale);
            for row in 0..n {
                if row != col {
                    let factor = work[row][col];
                    let pivot_row = work[col].clone();
                    work[row].iter_mut().zip(&pivot_row).for_each(|(value, p)| *value -= factor * p);
                }
            }
        }
        work.into_iter().map(|row| row[n..].to_vec()).collect()
    }

    /// A small deterministic generator (xorshift) and Box-Muller normals.
    struct Noise(u64);

    impl Noise {
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }

        fn normal(&mut self) -> f64 {
            let (u1, u2) = (self.uniform().max(1e-300), self.uniform());
            (-2.0 * u1.ln()).sqrt() * (core::f64::consts::TAU * u2).cos()
        }
    }

    const RANK: usize = 4;

    /// A stable rank-4 system (two damped oscillators) observed by the 12 taps.
    fn system(noise: &mut Noise) -> (Matrix, Matrix) {
        let rotation = |radius: f64, angle: f64| {
            [[radius * angle.cos(), -radius * angle.sin()], [radius * angle.sin(), radius * angle.cos()]]
        };
        let mut a = zeros(RANK, RANK);
        for (block, (radius, angle)) in [(0.995, 0.02), (0.98, 0.07)].into_iter().enumerate() {
            let r = rotation(radius, angle);
            for i in 0..2 {
                for j in 0..2 {
                    a[2 * block + i][2 * block + j] = r[i][j];
                }
            }
        }
        let c = (0..N_TAPS).map(|_| (0..RANK).map(|_| noise.normal() * 0.3).collect()).collect();
        (a, c)
    }

    /// The steady-state filter (the core, f32, with the converged gain) against the
    /// time-varying Kalman filter (f64, covariance propagated from a large prior): once the
    /// time-varying gain has converged, their estimates agree.
    #[test]
    fn steady_state_filter_matches_a_converged_time_varying_filter() {
        let mut noise = Noise(0x1234_5678_9abc_def1);
        let (a, c) = system(&mut noise);
        let (q_std, r_std) = (0.01, 0.05);
        let q: Matrix =
            (0..RANK).map(|i| (0..RANK).map(|j| if i == j { q_std * q_std } else { 0.0 }).collect()).collect();
        let r: Matrix =
            (0..N_TAPS).map(|i| (0..N_TAPS).map(|j| if i == j { r_std * r_std } else { 0.0 }).collect()).collect();
        // Riccati recursion of the prior covariance to convergence: the steady-state gain.
        let gain_of = |p_prior: &Matrix| {
            let innovation_cov = add(&mul(&mul(&c, p_prior), &transpose(&c)), &r, 1.0);
            (mul(&mul(p_prior, &transpose(&c)), &inverse(&innovation_cov)), innovation_cov)
        };
        let update = |p_prior: &Matrix, gain: &Matrix| add(p_prior, &mul(&mul(gain, &c), p_prior), -1.0);
        let mut p_prior: Matrix =
            (0..RANK).map(|i| (0..RANK).map(|j| if i == j { 10.0 } else { 0.0 }).collect()).collect();
        let initial_prior = p_prior.clone();
        for _ in 0..5000 {
            let (gain, _) = gain_of(&p_prior);
            p_prior = add(&mul(&mul(&a, &update(&p_prior, &gain)), &transpose(&a)), &q, 1.0);
        }
        let (steady_gain, innovation_cov) = gain_of(&p_prior);

        let mut model = PRIOR.pressure;
        model.rank = RANK as u8;
        model.gate_sigma = 1e6;
        for i in 0..RANK {
            for j in 0..RANK {
                model.a[i][j] = a[i][j] as f32;
            }
            for tap in 0..N_TAPS {
                model.gain[i][tap] = steady_gain[i][tap] as f32;
            }
        }
        for tap in 0..N_TAPS {
            model.c[tap][..RANK].iter_mut().zip(&c[tap]).for_each(|(dst, src)| *dst = *src as f32);
            model.innovation_std[tap] = innovation_cov[tap][tap].sqrt() as f32;
        }

        let mut core = PressureFilter::new(&model);
        let (mut truth, mut tv_state, mut tv_prior) = (vec![1.0, 0.0, -0.5, 0.5], vec![0.0; RANK], initial_prior);
        let mut worst_late = 0.0f64;
        for step in 0..1500 {
            truth = mul(&a, &truth.iter().map(|&v| vec![v]).collect())
                .into_iter()
                .map(|row| row[0] + q_std * noise.normal())
                .collect();
            let measured: Vec<f64> = c
                .iter()
                .map(|row| row.iter().zip(&truth).map(|(x, y)| x * y).sum::<f64>() + r_std * noise.normal())
                .collect();
            // Time-varying filter: predict, gain from the propagated covariance, update.
            let predicted: Vec<f64> = a.iter().map(|row| row.iter().zip(&tv_state).map(|(x, y)| x * y).sum()).collect();
            if step > 0 {
                tv_prior = add(&mul(&mul(&a, &tv_prior), &transpose(&a)), &q, 1.0);
            }
            let (gain, _) = gain_of(&tv_prior);
            let innovation: Vec<f64> = (0..N_TAPS)
                .map(|tap| measured[tap] - c[tap].iter().zip(&predicted).map(|(x, y)| x * y).sum::<f64>())
                .collect();
            tv_state = (0..RANK)
                .map(|i| predicted[i] + (0..N_TAPS).map(|tap| gain[i][tap] * innovation[tap]).sum::<f64>())
                .collect();
            tv_prior = update(&tv_prior, &gain);

            let cp: [f32; N_TAPS] = core::array::from_fn(|tap| measured[tap] as f32);
            let _ = core.step(&model, SchedulePosition::FIRST, &[0.0; N_PRESSURE_INPUTS], &cp, &mut Health::default());
            if step >= 1000 {
                for i in 0..RANK {
                    worst_late = worst_late.max((f64::from(core.modes()[i]) - tv_state[i]).abs());
                }
            }
        }
        // State magnitude is about 1; the filters agree to f32 round-off plus the remaining
        // difference of the time-varying gain from the steady one.
        assert!(worst_late < 1e-4, "{worst_late}");
    }

    #[test]
    fn missing_channel_skips_its_update_and_is_flagged() {
        let model = crate::prior::full_size_fixture().pressure;
        let mut with_gap = PressureFilter::new(&model);
        let mut reference = PressureFilter::new(&model);
        let mut cp = model.cp_mean;
        cp[3] += 0.01;
        let mut gap = cp;
        gap[3] = f32::NAN;
        let mut health = Health::default();
        let _ = with_gap.step(&model, SchedulePosition::FIRST, &[0.0; N_PRESSURE_INPUTS], &gap, &mut health);
        // From rest, the prediction of every tap is its mean: measuring exactly that is a zero
        // innovation.
        let mut cp_without = cp;
        cp_without[3] = model.cp_mean[3];
        let _ = reference.step(
            &model,
            SchedulePosition::FIRST,
            &[0.0; N_PRESSURE_INPUTS],
            &cp_without,
            &mut Health::default(),
        );
        assert_eq!(health.cp_missing, 1 << 3);
        assert_eq!(with_gap.modes(), reference.modes(), "a missing channel is a zero innovation");
    }

    /// The mean pressures with a tiny alternating offset: live channels never repeat a reading
    /// bit for bit (see [`STUCK_AFTER_STEPS`]), and the offset is far inside the gate.
    fn live(model: &PressureModel, step: usize) -> [f32; N_TAPS] {
        let wiggle = if step.is_multiple_of(2) { 1e-4 } else { -1e-4 };
        core::array::from_fn(|tap| model.cp_mean[tap] + wiggle)
    }

    /// The map to `C_l` follows the schedule: between two breakpoints the estimate is the
    /// interpolation of their maps' values on the same state.
    #[test]
    fn map_to_cl_interpolates_between_breakpoints() {
        let mut model = crate::prior::full_size_fixture().pressure;
        model.cl_offset[1] = model.cl_offset[0] + 0.01;
        let cp = live(&model, 0);
        let estimate = |at: SchedulePosition| {
            let mut filter = PressureFilter::new(&model);
            filter.step(&model, at, &[0.0; N_PRESSURE_INPUTS], &cp, &mut Health::default()).cl
        };
        let low = estimate(SchedulePosition { lower: 0, upper: 0, weight: 0.0 });
        let high = estimate(SchedulePosition { lower: 1, upper: 1, weight: 0.0 });
        let middle = estimate(SchedulePosition { lower: 0, upper: 1, weight: 0.25 });
        assert_ne!(low, high);
        assert!((middle - (low + 0.25 * (high - low))).abs() < 1e-7, "{low} {high} {middle}");
        let beyond = estimate(SchedulePosition { lower: 99, upper: 99, weight: 0.0 });
        assert!(beyond.is_finite(), "an index past the schedule is clamped, never a panic");
    }

    /// Until the filter has settled from its start at the mean pressures, every finite reading
    /// corrects it and the step is flagged; then the gate is armed and a biased channel fails.
    #[test]
    fn every_channel_corrects_while_settling_then_the_gate_is_armed() {
        let mut model = crate::prior::full_size_fixture().pressure;
        model.settle_steps = 5;
        let mut filter = PressureFilter::new(&model);
        for step in 0..8 {
            let mut cp = live(&model, step);
            cp[6] += 1.0;
            let mut health = Health::default();
            let estimate = filter.step(&model, SchedulePosition::FIRST, &[0.0; N_PRESSURE_INPUTS], &cp, &mut health);
            let settling = step < 5;
            assert!(estimate.measured);
            assert_eq!(health.has(Health::PRESSURE_SETTLING), settling, "step {step}");
            assert_eq!(health.cp_rejected, if settling { 0 } else { 1 << 6 }, "step {step}");
        }
    }

    #[test]
    fn biased_channel_is_rejected_then_isolated_while_others_keep_correcting() {
        let model = crate::prior::full_size_fixture().pressure;
        let mut filter = PressureFilter::new(&model);
        let mut last = Health::default();
        for step in 0..usize::from(model.isolate_after) + 5 {
            let mut cp = live(&model, step);
            cp[6] += 1.0;
            last = Health::default();
            let estimate = filter.step(&model, SchedulePosition::FIRST, &[0.0; N_PRESSURE_INPUTS], &cp, &mut last);
            assert!(estimate.measured && estimate.cl.is_finite());
            assert_eq!(last.cp_rejected, 1 << 6, "step {step}");
        }
        assert_eq!(last.cp_isolated, 1 << 6);
        // Back to normal: re-admitted after as many passes in a row.
        for step in 0..usize::from(model.isolate_after) + 1 {
            last = Health::default();
            let _ =
                filter.step(&model, SchedulePosition::FIRST, &[0.0; N_PRESSURE_INPUTS], &live(&model, step), &mut last);
        }
        assert_eq!(last.cp_isolated, 0);
    }

    #[test]
    fn stuck_channel_is_rejected_after_its_repeats_and_a_frozen_front_end_is_unused() {
        let model = crate::prior::full_size_fixture().pressure;
        let mut filter = PressureFilter::new(&model);
        let frozen_cp = model.cp_mean[2] + 0.003;
        for step in 0..usize::from(STUCK_AFTER_STEPS) + 3 {
            let mut cp = live(&model, step);
            cp[2] = frozen_cp;
            let mut health = Health::default();
            let estimate = filter.step(&model, SchedulePosition::FIRST, &[0.0; N_PRESSURE_INPUTS], &cp, &mut health);
            assert!(estimate.measured);
            let stuck = step + 1 >= usize::from(STUCK_AFTER_STEPS);
            assert_eq!(health.channel_faulty(2), stuck, "step {step}");
            assert_eq!(health.cp_rejected & !(1 << 2), 0, "step {step}: only the stuck channel");
        }
        // Every channel frozen: nothing corrects the prediction.
        let mut health = Health::default();
        let mut estimate =
            filter.step(&model, SchedulePosition::FIRST, &[0.0; N_PRESSURE_INPUTS], &model.cp_mean, &mut health);
        for _ in 0..STUCK_AFTER_STEPS {
            health = Health::default();
            estimate =
                filter.step(&model, SchedulePosition::FIRST, &[0.0; N_PRESSURE_INPUTS], &model.cp_mean, &mut health);
        }
        assert!(!estimate.measured);
        assert_eq!(health.cp_rejected, (1 << N_TAPS) - 1);
    }

    #[test]
    fn dropouts_do_not_hide_a_stuck_channel() {
        let model = crate::prior::full_size_fixture().pressure;
        let mut filter = PressureFilter::new(&model);
        let mut flagged_at = None;
        for step in 0..60 {
            let mut cp = live(&model, step);
            cp[5] = if step % 3 == 2 { f32::NAN } else { model.cp_mean[5] + 0.003 };
            let mut health = Health::default();
            let _ = filter.step(&model, SchedulePosition::FIRST, &[0.0; N_PRESSURE_INPUTS], &cp, &mut health);
            if health.channel_faulty(5) && flagged_at.is_none() {
                flagged_at = Some(step);
            }
        }
        // 20 finite readings among the first 30 samples (every third one is missing).
        assert_eq!(flagged_at, Some(28));
    }
}

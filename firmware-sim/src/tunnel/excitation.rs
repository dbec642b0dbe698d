//! Random inputs with holds (paper Fig. 6, after Brunton et al.; Kaiser's `prbs.m` in
//! SINDY-MPC): a piecewise-constant signal whose levels and hold durations are drawn at random.
//!
//! Holds let the flow settle so that quasi-steady effects are identified, and the switches
//! excite the transients. The sequences are functions of continuous time, so delays and
//! substeps read them exactly.

use rand::Rng;
use serde::Deserialize;

/// How to draw a random sequence with holds.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HoldDesign {
    /// Levels to draw from, with replacement; a level listed twice is twice as likely.
    /// When empty, levels are drawn uniformly from `[range_min, range_max]`.
    #[serde(default)]
    pub levels: Vec<f64>,
    /// Lower end of the uniform level range (used when `levels` is empty).
    #[serde(default)]
    pub range_min: f64,
    /// Upper end of the uniform level range (used when `levels` is empty).
    #[serde(default)]
    pub range_max: f64,
    /// Shortest hold, s.
    pub hold_min_s: f64,
    /// Longest hold, s.
    pub hold_max_s: f64,
    /// The sequence is zero before this time, s (the paper delays the blowing 8 s).
    #[serde(default)]
    pub delay_s: f64,
    /// Sign-balanced: every hold also appears, in random order, with the opposite level for the
    /// same duration, so that odd responses (a roll moment to a roll angle) average to zero over
    /// the run, as an experimenter designs a roll input without a net bias.
    #[serde(default)]
    pub symmetric: bool,
    /// Balanced levels: listed levels are dealt from shuffled decks (each appears equally often
    /// in every round), which keeps the run's mean level close to the design's.
    #[serde(default)]
    pub balanced: bool,
}

impl HoldDesign {
    /// Roll command: uniform in +-30 deg, holds of 0.2 to 1.2 s; through the roll servo this
    /// gives content up to about 3 Hz (paper section II: +-30 deg, up to 3 Hz).
    #[must_use]
    pub fn paper_roll_deg() -> Self {
        Self {
            levels: Vec::new(),
            range_min: -30.0,
            range_max: 30.0,
            hold_min_s: 0.2,
            hold_max_s: 1.2,
            delay_s: 0.0,
            symmetric: true,
            balanced: false,
        }
    }

    /// Blowing command: Cmu in {0, 1/4, 1/2, 3/4, 1} x 0.009 with extra weight on zero so that
    /// indicator-gated terms see both states, holds of 0.3 to 2 s, delayed 8 s from the roll
    /// signal (paper section V).
    #[must_use]
    pub fn paper_blowing(cmu_max: f64) -> Self {
        let fractions = [0.0, 0.0, 0.25, 0.5, 0.75, 1.0];
        Self {
            levels: fractions.iter().map(|fraction| fraction * cmu_max).collect(),
            range_min: 0.0,
            range_max: cmu_max,
            hold_min_s: 0.3,
            hold_max_s: 2.0,
            delay_s: 8.0,
            symmetric: false,
            balanced: true,
        }
    }

    /// Draws a sequence that covers `[0, duration_s]`.
    pub fn draw(&self, duration_s: f64, rng: &mut impl Rng) -> HoldSequence {
        let holds = self.draw_holds(duration_s - self.delay_s, rng);
        let mut switch_times_s = Vec::with_capacity(holds.len());
        let mut levels = Vec::with_capacity(holds.len());
        let mut t_s = self.delay_s;
        for (level, hold_s) in holds {
            if t_s > duration_s {
                break;
            }
            switch_times_s.push(t_s);
            levels.push(level);
            t_s += hold_s;
        }
        HoldSequence { switch_times_s, levels }
    }

    /// `(level, duration)` pairs that fill `span_s`; when symmetric, each pair also appears
    /// with the opposite level, in shuffled order.
    fn draw_holds(&self, span_s: f64, rng: &mut impl Rng) -> Vec<(f64, f64)> {
        let hold_span_s = (self.hold_max_s - self.hold_min_s).max(0.0);
        let shortest_s = self.hold_min_s.max(1e-3);
        let target_s = if self.symmetric { 0.5 * span_s } else { span_s };
        let mut holds = Vec::new();
        let mut deck = Vec::new();
        let mut covered_s = 0.0;
        while covered_s <= target_s {
            let hold_s = shortest_s + hold_span_s * rng.random::<f64>();
            holds.push((self.draw_level(&mut deck, rng), hold_s));
            covered_s += hold_s;
        }
        if self.symmetric {
            let mirrored: Vec<(f64, f64)> = holds.iter().map(|&(level, hold_s)| (-level, hold_s)).collect();
            holds.extend(mirrored);
            for idx in (1..holds.len()).rev() {
                holds.swap(idx, rng.random_range(0..=idx));
            }
        }
        holds
    }

    fn draw_level(&self, deck: &mut Vec<f64>, rng: &mut impl Rng) -> f64 {
        if self.balanced && !self.levels.is_empty() {
            if deck.is_empty() {
                deck.extend_from_slice(&self.levels);
            }
            return deck.swap_remove(rng.random_range(0..deck.len()));
        }
        if self.levels.is_empty() {
            // Levels are rounded to 1e-4 of the range, the resolution of a logged command.
            let fraction = (rng.random::<f64>() * 1e4).round() / 1e4;
            self.range_min + (self.range_max - self.range_min) * fraction
        } else {
            self.levels[rng.random_range(0..self.levels.len())]
        }
    }
}

/// A piecewise-constant signal: `levels[i]` holds from `switch_times_s[i]` to the next switch.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct HoldSequence {
    switch_times_s: Vec<f64>,
    levels: Vec<f64>,
}

impl HoldSequence {
    /// A signal that is zero at all times.
    #[must_use]
    pub fn zero() -> Self {
        Self::default()
    }

    /// The value at time `t_s`: zero before the first switch.
    #[must_use]
    pub fn value_at(&self, t_s: f64) -> f64 {
        let n_before = self.switch_times_s.partition_point(|&switch_s| switch_s <= t_s);
        match n_before.checked_sub(1) {
            Some(idx) => self.levels[idx],
            None => 0.0,
        }
    }

    /// Average of the signal over `[0, duration_s]`.
    #[must_use]
    pub fn time_average(&self, duration_s: f64) -> f64 {
        let mut integral = 0.0;
        for (idx, (&start_s, &level)) in self.switch_times_s.iter().zip(&self.levels).enumerate() {
            let end_s = self.switch_times_s.get(idx + 1).copied().unwrap_or(duration_s).min(duration_s);
            integral += level * (end_s - start_s).max(0.0);
        }
        if duration_s > 0.0 { integral / duration_s } else { 0.0 }
    }

    /// Number of holds.
    #[must_use]
    pub fn n_holds(&self) -> usize {
        self.levels.len()
    }

    /// A signal built from its holds: `levels[i]` from `switch_times_s[i]` (increasing) on.
    #[must_use]
    pub fn from_holds(switch_times_s: Vec<f64>, levels: Vec<f64>) -> Self {
        let n_holds = switch_times_s.len().min(levels.len());
        let (mut switch_times_s, mut levels) = (switch_times_s, levels);
        switch_times_s.truncate(n_holds);
        levels.truncate(n_holds);
        Self { switch_times_s, levels }
    }

    /// Holds `level` from `t_s` on (later than every earlier switch); a level equal to the
    /// current one adds no switch. This is how a closed loop logs its commands as it goes.
    pub fn hold_from(&mut self, t_s: f64, level: f64) {
        if self.levels.last().is_none_or(|&last| last.to_bits() != level.to_bits()) {
            self.switch_times_s.push(t_s);
            self.levels.push(level);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn roll_levels_stay_in_range_and_hold() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let sequence = HoldDesign::paper_roll_deg().draw(50.0, &mut rng);
        assert!(sequence.n_holds() > 50);
        for sample_idx in 0..50_000 {
            let value = sequence.value_at(sample_idx as f64 * 1e-3);
            assert!((-30.0..=30.0).contains(&value));
        }
        assert!(sequence.time_average(50.0).abs() < 0.5);
    }

    #[test]
    fn blowing_is_zero_before_its_delay_and_takes_listed_levels() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let design = HoldDesign::paper_blowing(0.009);
        let sequence = design.draw(50.0, &mut rng);
        assert_eq!(sequence.value_at(7.999), 0.0);
        let mut seen_nonzero = false;
        for sample_idx in 8_000..50_000 {
            let value = sequence.value_at(sample_idx as f64 * 1e-3);
            assert!(design.levels.contains(&value));
            seen_nonzero |= value > 0.0;
        }
        assert!(seen_nonzero);
    }

    #[test]
    fn same_seed_same_sequence() {
        let design = HoldDesign::paper_roll_deg();
        let first = design.draw(10.0, &mut ChaCha8Rng::seed_from_u64(9));
        let second = design.draw(10.0, &mut ChaCha8Rng::seed_from_u64(9));
        assert_eq!(first, second);
    }
}

//! Seeded test signals shared by the ledger's unit tests.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// `len` samples of seeded standard white Gaussian noise.
pub(crate) fn white(seed: u64, len: usize) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..len).map(|_| StandardNormal.sample(&mut rng)).collect()
}

/// A seeded AR(1) series `x[t] = phi·x[t−1] + w[t]`, started from its stationary distribution.
pub(crate) fn ar1(seed: u64, len: usize, phi: f64) -> Vec<f64> {
    let noise = white(seed, len);
    let mut out = Vec::with_capacity(len);
    let mut state = noise.first().copied().unwrap_or(0.0) / (1.0 - phi * phi).sqrt();
    for (idx, w) in noise.iter().enumerate() {
        if idx > 0 {
            state = phi * state + w;
        }
        out.push(state);
    }
    out
}

/// Seeded white noise through a lightly damped second-order resonator at `freq_hz`
/// (poles at radius `radius` and angle `2π f/fs`), after a burn-in of 2000 samples.
pub(crate) fn resonance(seed: u64, len: usize, freq_hz: f64, sample_hz: f64, radius: f64) -> Vec<f64> {
    let burn_in = 2000;
    let noise = white(seed, len + burn_in);
    let a1 = 2.0 * radius * (2.0 * std::f64::consts::PI * freq_hz / sample_hz).cos();
    let a2 = -radius * radius;
    let (mut y1, mut y2) = (0.0, 0.0);
    let mut out = Vec::with_capacity(len);
    for (idx, w) in noise.iter().enumerate() {
        let y = a1 * y1 + a2 * y2 + w;
        y2 = y1;
        y1 = y;
        if idx >= burn_in {
            out.push(y);
        }
    }
    out
}

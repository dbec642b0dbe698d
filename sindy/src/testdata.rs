//! Deterministic synthetic data for the unit tests (no random-number crate in the library).

use estimator_core::coeffs::MAX_VARS;

/// A xorshift64* generator (Vigna, "An experimental exploration of Marsaglia's xorshift
/// generators, scrambled", ACM TOMS 42(4), 2016).
pub(crate) struct Rng(u64);

impl Rng {
    /// A generator from a non-zero seed.
    pub(crate) fn new(seed: u64) -> Self {
        Self(seed.max(1))
    }

    /// A uniform value in [0, 1).
    pub(crate) fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A uniform value in [-1, 1).
    pub(crate) fn symmetric(&mut self) -> f64 {
        2.0 * self.uniform() - 1.0
    }
}

/// `n` samples of two variables uniform in [-1, 1) and the target
/// `1 + 2 x0 - 0.05 x1^2 + noise * e` with e uniform in [-1, 1).
pub(crate) fn static_regression(n: usize, noise: f64, seed: u64) -> (Vec<[f64; MAX_VARS]>, Vec<f64>) {
    let mut rng = Rng::new(seed);
    let mut samples = Vec::with_capacity(n);
    let mut y = Vec::with_capacity(n);
    for _ in 0..n {
        let (x0, x1) = (rng.symmetric(), rng.symmetric());
        samples.push([x0, x1, 0.0, 0.0, 0.0, 0.0, 0.0]);
        y.push(1.0 + 2.0 * x0 - 0.05 * x1 * x1 + noise * rng.symmetric());
    }
    (samples, y)
}

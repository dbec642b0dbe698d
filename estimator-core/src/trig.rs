//! Sine and cosine of the roll angle in f32 arithmetic only.
//!
//! libm's `sinf`/`cosf` (the musl port) reduce the argument and evaluate their polynomials in
//! f64, which the Cortex-M4F emulates in software: on the target that costs thousands of
//! instructions per step. The roll angle is clamped to +-90 deg before it gets here, so no
//! argument reduction is needed: the Taylor polynomials of degree 11 (sine) and 12 (cosine),
//! evaluated by Horner's rule in f32, are accurate to a few ulps on [-pi/2, pi/2] (the
//! truncation error is below (pi/2)^13 / 13! = 5.7e-8 and (pi/2)^14 / 14! = 6.4e-9;
//! Abramowitz & Stegun 4.3.65-66).

use core::f32::consts::FRAC_PI_2;

/// Taylor coefficients `(-1)^n / (2n+1)!` of the sine, from `x^3` up.
const SIN: [f32; 5] = [-1.0 / 6.0, 1.0 / 120.0, -1.0 / 5_040.0, 1.0 / 362_880.0, -1.0 / 39_916_800.0];

/// Taylor coefficients `(-1)^n / (2n)!` of the cosine, from `x^2` up.
const COS: [f32; 6] = [-1.0 / 2.0, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40_320.0, -1.0 / 3_628_800.0, 1.0 / 479_001_600.0];

/// `(sin x, cos x)` for `|x| <= pi/2` (larger arguments are clamped to that range).
///
/// Horner's rule in `x^2` with multiplications only (a division costs 14 cycles on the M4F).
#[must_use]
pub fn sin_cos(x: f32) -> (f32, f32) {
    let x = x.clamp(-FRAC_PI_2, FRAC_PI_2);
    let x2 = x * x;
    let sin_tail = SIN.iter().rev().fold(0.0f32, |acc, &c| acc * x2 + c);
    let cos_tail = COS.iter().rev().fold(0.0f32, |acc, &c| acc * x2 + c);
    (x + x * x2 * sin_tail, 1.0 + x2 * cos_tail)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_f64_sine_and_cosine_to_a_few_ulps_over_the_roll_range() {
        let mut worst = 0.0f64;
        for step in -20_000..=20_000 {
            let x = step as f32 * (FRAC_PI_2 / 20_000.0);
            let (sin, cos) = sin_cos(x);
            let exact = f64::from(x);
            worst = worst.max((f64::from(sin) - exact.sin()).abs()).max((f64::from(cos) - exact.cos()).abs());
        }
        // A few ulps of 1.0 (f32 epsilon is 1.2e-7).
        assert!(worst < 4e-7, "{worst}");
    }

    #[test]
    fn clamps_beyond_the_range_and_keeps_odd_and_even_symmetry() {
        assert_eq!(sin_cos(10.0), sin_cos(FRAC_PI_2));
        let (s, c) = sin_cos(0.3);
        let (s_neg, c_neg) = sin_cos(-0.3);
        assert_eq!((s, c), (-s_neg, c_neg));
        assert_eq!(sin_cos(0.0), (0.0, 1.0));
    }
}

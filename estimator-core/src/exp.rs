//! The exponential in f32 arithmetic only.
//!
//! The eGK's breakdown curve needs `exp` twice a step. libm's `tanhf` goes through `expm1f`
//! (about 70 instructions on the M4F, and `expf` computes in f64, which the M4F emulates in
//! software). Here: Cody-Waite argument reduction `x = n ln2 + r`, `|r| <= ln2 / 2`, with
//! `ln2` split in a high part of few bits (so `n ln2_hi` is exact) and a low part (Cody &
//! Waite, Software Manual for the Elementary Functions, 1980, ch. 6), then the Taylor
//! polynomial of degree 7 for `e^r` by Horner's rule (truncation below
//! `(ln2/2)^8 / 8! = 5e-9`, under the f32 unit round-off), and the scaling by `2^n` through
//! the exponent bits.

/// `log2(e)`.
const LOG2_E: f32 = core::f32::consts::LOG2_E;
/// High part of `ln 2` with 9 significant bits: `n * LN2_HI` is exact for `|n| <= 2^14`.
const LN2_HI: f32 = 0.693_359_4;
/// `ln 2 - LN2_HI`.
const LN2_LO: f32 = -2.121_944_4e-4;
/// `1.5 * 2^23`: adding and subtracting it rounds an f32 below `2^22` to the nearest integer.
const ROUNDER: f32 = 12_582_912.0;
/// Taylor coefficients `1 / k!` of `e^r`, from `r^2` to `r^7`.
const TAYLOR: [f32; 6] = [1.0 / 2.0, 1.0 / 6.0, 1.0 / 24.0, 1.0 / 120.0, 1.0 / 720.0, 1.0 / 5_040.0];

/// `e^x` for f32 `x`: the argument is limited to `[-87, 88]`, so the result stays a normal
/// float (at most `1.7e38`, at least `1.6e-38`); a NaN gives a NaN.
#[must_use]
pub fn exp(x: f32) -> f32 {
    // `clamp` lets a NaN through; with constant bounds its assertion is compiled out.
    let x = x.clamp(-87.0, 88.0);
    let n = (x * LOG2_E + ROUNDER) - ROUNDER;
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let tail = TAYLOR.iter().rev().fold(0.0f32, |acc, &c| acc * r + c);
    let poly = 1.0 + r + r * r * tail;
    // `n` is an integer in [-126, 127] here (NaN converts to 0), so the biased exponent is in
    // [1, 254]: a normal power of two.
    let scale = f32::from_bits((((n as i32) + 127) as u32) << 23);
    poly * scale
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_f64_exponential_to_a_few_ulps() {
        let (mut worst_ulps, mut worst_x) = (0.0f64, 0.0f32);
        for step in -86_990..=87_990 {
            let x = step as f32 * 1e-3;
            let exact = f64::from(x).exp();
            let ulp = f64::from(f32::EPSILON) * exact;
            let ulps = (f64::from(exp(x)) - exact).abs() / ulp;
            if ulps > worst_ulps {
                (worst_ulps, worst_x) = (ulps, x);
            }
        }
        assert!(worst_ulps < 2.0, "{worst_ulps} ulps at {worst_x}");
    }

    #[test]
    fn limits_and_nan() {
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(exp(1000.0), exp(88.0));
        assert_eq!(exp(-1000.0), exp(-87.0));
        assert!(exp(f32::INFINITY).is_finite() && exp(f32::NEG_INFINITY) > 0.0);
        assert!(exp(f32::NAN).is_nan());
    }
}

//! The scalar the stages compute in: f32 on the target, f64 on the host.
//!
//! The fit, the evaluation and the diagnosis run the same stages as the flying estimator, in
//! f64, so that an identification is not limited by f32 round-off and a change to a stage
//! reaches the host with it (one definition of each equation; the stages are generic over the
//! scalar as adskalman-rs is over nalgebra's `RealField`). The f32 instantiation keeps the
//! core's own [`crate::exp::exp`] and [`crate::trig::sin_cos`] (no f64 arithmetic, which the
//! Cortex-M4F emulates in software); f64 uses libm's correctly rounded functions. The two agree
//! to f32 round-off, which the host-tools test `core_stages_in_f32_and_f64` checks on faulty
//! inputs.

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// A floating-point scalar of the core's stages: f32 or f64.
///
/// Only what the stages use: arithmetic, comparisons, the constants and functions below, and
/// conversions from the f32 tables and to f64 (exact both).
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialEq
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + 'static
{
    /// 0.
    const ZERO: Self;
    /// -0, the identity of addition (`-0 + x == x` for every `x`, signed zeros included).
    const NEG_ZERO: Self;
    /// 1.
    const ONE: Self;
    /// Not a number.
    const NAN: Self;
    /// `pi / 2`.
    const FRAC_PI_2: Self;
    /// `180 / pi`: degrees per radian.
    const DEG_PER_RAD: Self;
    /// `pi / 180`: radians per degree (as `to_radians` multiplies).
    const RAD_PER_DEG: Self;

    /// The nearest value to `value` (exact for f64; rounded to nearest for f32).
    fn from_f64(value: f64) -> Self;
    /// `value` exactly (an f32 table entry).
    fn from_f32(value: f32) -> Self;
    /// The value as f64 (exact).
    fn to_f64(self) -> f64;
    /// True when neither infinite nor NaN.
    fn is_finite(self) -> bool;
    /// `|self|`.
    #[must_use]
    fn abs(self) -> Self;
    /// `self` limited to `[low, high]` (a NaN stays NaN).
    #[must_use]
    fn clamp(self, low: Self, high: Self) -> Self;
    /// True for a NaN.
    fn is_nan(self) -> bool;
    /// Square root.
    #[must_use]
    fn sqrt(self) -> Self;
    /// `e^self` (f32: [`crate::exp::exp`], its argument limited to `[-87, 88]`).
    #[must_use]
    fn exp(self) -> Self;
    /// `(sin, cos)` of an angle limited to `[-pi/2, pi/2]` (f32: [`crate::trig::sin_cos`]).
    fn sin_cos(self) -> (Self, Self);
    /// Arc sine.
    #[must_use]
    fn asin(self) -> Self;
    /// Arc tangent.
    #[must_use]
    fn atan(self) -> Self;
    /// The bit pattern of a value: equal patterns are the same reading.
    type Bits: Copy + Debug + PartialEq;
    /// A NaN's pattern, which no finite value has.
    const NO_READING_BITS: Self::Bits;
    /// The bit pattern.
    fn bits(self) -> Self::Bits;

    /// `m x + y` for a row-major `N x M` matrix `m`, by nalgebra's fixed-size product (the
    /// `nalgebra` measurement variant of the pressure filter).
    #[cfg(feature = "nalgebra")]
    fn mat_vec_add<const N: usize, const M: usize>(m: &[[Self; M]; N], x: &[Self; M], y: &[Self; N]) -> [Self; N];
}

/// [`Real::mat_vec_add`] with nalgebra: the row-major table viewed as its column-major
/// transpose, without a copy, and `tr_mul` (each output a dot product of a table row).
#[cfg(feature = "nalgebra")]
macro_rules! nalgebra_mat_vec_add {
    ($t:ty) => {
        fn mat_vec_add<const N: usize, const M: usize>(m: &[[$t; M]; N], x: &[$t; M], y: &[$t; N]) -> [$t; N] {
            use nalgebra::{Const, SMatrixView, SVectorView};
            let transposed = SMatrixView::<$t, M, N>::from_slice_generic(m.as_flattened(), Const::<M>, Const::<N>);
            let x = SVectorView::<$t, M>::from_slice_generic(x, Const::<M>, Const::<1>);
            let product = transposed.tr_mul(&x);
            let mut out = *y;
            for (out, value) in out.iter_mut().zip(product.iter()) {
                *out += *value;
            }
            out
        }
    };
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const NEG_ZERO: Self = -0.0;
    const ONE: Self = 1.0;
    const NAN: Self = f32::NAN;
    const FRAC_PI_2: Self = core::f32::consts::FRAC_PI_2;
    const DEG_PER_RAD: Self = 180.0 / core::f32::consts::PI;
    const RAD_PER_DEG: Self = core::f32::consts::PI / 180.0;

    #[inline]
    fn from_f64(value: f64) -> Self {
        value as f32
    }
    #[inline]
    fn from_f32(value: f32) -> Self {
        value
    }
    #[inline]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    #[inline]
    fn is_finite(self) -> bool {
        f32::is_finite(self)
    }
    #[inline]
    fn abs(self) -> Self {
        f32::abs(self)
    }
    #[inline]
    fn clamp(self, low: Self, high: Self) -> Self {
        f32::clamp(self, low, high)
    }
    #[inline]
    fn is_nan(self) -> bool {
        f32::is_nan(self)
    }
    #[cfg(not(feature = "micromath"))]
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrtf(self)
    }
    #[cfg(not(feature = "micromath"))]
    #[inline]
    fn exp(self) -> Self {
        crate::exp::exp(self)
    }
    #[cfg(not(feature = "micromath"))]
    #[inline]
    fn sin_cos(self) -> (Self, Self) {
        crate::trig::sin_cos(self)
    }
    #[cfg(not(feature = "micromath"))]
    #[inline]
    fn asin(self) -> Self {
        libm::asinf(self)
    }
    #[cfg(not(feature = "micromath"))]
    #[inline]
    fn atan(self) -> Self {
        libm::atanf(self)
    }
    #[cfg(feature = "micromath")]
    #[inline]
    fn sqrt(self) -> Self {
        micromath::F32Ext::sqrt(self)
    }
    #[cfg(feature = "micromath")]
    #[inline]
    fn exp(self) -> Self {
        micromath::F32Ext::exp(self)
    }
    #[cfg(feature = "micromath")]
    #[inline]
    fn sin_cos(self) -> (Self, Self) {
        (micromath::F32Ext::sin(self), micromath::F32Ext::cos(self))
    }
    #[cfg(feature = "micromath")]
    #[inline]
    fn asin(self) -> Self {
        micromath::F32Ext::asin(self)
    }
    #[cfg(feature = "micromath")]
    #[inline]
    fn atan(self) -> Self {
        micromath::F32Ext::atan(self)
    }
    #[cfg(feature = "nalgebra")]
    nalgebra_mat_vec_add!(f32);
    type Bits = u32;
    const NO_READING_BITS: u32 = 0x7fc0_0000;
    #[inline]
    fn bits(self) -> u32 {
        self.to_bits()
    }
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const NEG_ZERO: Self = -0.0;
    const ONE: Self = 1.0;
    const NAN: Self = f64::NAN;
    const FRAC_PI_2: Self = core::f64::consts::FRAC_PI_2;
    const DEG_PER_RAD: Self = 180.0 / core::f64::consts::PI;
    const RAD_PER_DEG: Self = core::f64::consts::PI / 180.0;

    #[inline]
    fn from_f64(value: f64) -> Self {
        value
    }
    #[inline]
    fn from_f32(value: f32) -> Self {
        f64::from(value)
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn is_finite(self) -> bool {
        f64::is_finite(self)
    }
    #[inline]
    fn abs(self) -> Self {
        f64::abs(self)
    }
    #[inline]
    fn clamp(self, low: Self, high: Self) -> Self {
        f64::clamp(self, low, high)
    }
    #[inline]
    fn is_nan(self) -> bool {
        f64::is_nan(self)
    }
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
    #[inline]
    fn exp(self) -> Self {
        libm::exp(self)
    }
    #[inline]
    fn sin_cos(self) -> (Self, Self) {
        let angle = self.clamp(-Self::FRAC_PI_2, Self::FRAC_PI_2);
        (libm::sin(angle), libm::cos(angle))
    }
    #[inline]
    fn asin(self) -> Self {
        libm::asin(self)
    }
    #[inline]
    fn atan(self) -> Self {
        libm::atan(self)
    }
    #[cfg(feature = "nalgebra")]
    nalgebra_mat_vec_add!(f64);
    type Bits = u64;
    const NO_READING_BITS: u64 = 0x7ff8_0000_0000_0000;
    #[inline]
    fn bits(self) -> u64 {
        self.to_bits()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The two instantiations agree to f32 round-off on each function over the roll range.
    #[test]
    fn f32_and_f64_functions_agree_to_f32_round_off() {
        for step in -200..=200 {
            let x = step as f32 * 0.01;
            let wide = f64::from(x);
            let close = |narrow: f32, wide: f64| {
                (f64::from(narrow) - wide).abs() <= 4.0 * f64::from(f32::EPSILON) * wide.abs().max(1.0)
            };
            assert!(close(Real::exp(x), Real::exp(wide)), "exp {x}");
            let ((s, c), (s64, c64)) = (Real::sin_cos(x), Real::sin_cos(wide));
            assert!(close(s, s64) && close(c, c64), "sin_cos {x}");
            let unit = x / 2.0;
            assert!(close(Real::asin(unit), Real::asin(f64::from(unit))), "asin {unit}");
            assert!(close(Real::atan(x), Real::atan(wide)), "atan {x}");
        }
        assert_eq!(Real::sin_cos(10.0f64), Real::sin_cos(core::f64::consts::FRAC_PI_2), "clamped as the f32 one");
        assert!(Real::bits(f32::NAN) != Real::bits(1.0f32));
    }
}

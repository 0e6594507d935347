//! The scalar types a tensor can hold: `f32` for learning, `f64` for gradient checks.

use std::fmt::{Debug, Display};
use std::iter::Sum;
use std::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// A real floating-point element type (`f32` or `f64`).
///
/// Everything a kernel needs is here, so kernels are written once for both precisions.
/// The `faer` bound lets matrix products go through faer.
pub trait Float:
    Copy
    + Send
    + Sync
    + Debug
    + Display
    + Default
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + DivAssign
    + Sum
    + faer::traits::ComplexField
    + faer::traits::RealField
    + 'static
{
    /// Additive identity.
    const ZERO: Self;
    /// Multiplicative identity.
    const ONE: Self;
    /// Name of the type, for messages.
    const NAME: &'static str;
    /// Converts from `f64` (rounding for `f32`).
    fn from_f64(v: f64) -> Self;
    /// Converts to `f64` (exact).
    fn to_f64(self) -> f64;
    /// e^self.
    fn exp(self) -> Self;
    /// Natural logarithm.
    fn ln(self) -> Self;
    /// ln(1 + self), accurate near 0.
    fn ln_1p(self) -> Self;
    /// Hyperbolic tangent.
    fn tanh(self) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
    /// self^p.
    fn powf(self, p: Self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// The larger of the two (NaN-propagating through comparison order is not guaranteed).
    fn max(self, other: Self) -> Self;
    /// The smaller of the two.
    fn min(self, other: Self) -> Self;
    /// Whether the value is neither infinite nor NaN.
    fn is_finite(self) -> bool;
    /// Negative infinity (identity of `max`).
    fn neg_infinity() -> Self;
    /// The pool of recycled buffers of this type.
    fn pool() -> &'static crate::pool::BufferPool<Self>;
    /// The values as `f32` if this is `f32` (what a GPU buffer holds), else `None`.
    fn as_f32_slice(values: &[Self]) -> Option<&[f32]>;
    /// Values read back from a GPU buffer, as this type.
    fn from_f32_vec(values: Vec<f32>) -> Vec<Self>;
}

macro_rules! impl_float {
    ($t:ty, $name:expr, $as_f32:expr, $from_f32:expr) => {
        impl Float for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const NAME: &'static str = $name;
            #[inline(always)]
            fn from_f64(v: f64) -> Self {
                v as $t
            }
            #[inline(always)]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline(always)]
            fn exp(self) -> Self {
                <$t>::exp(self)
            }
            #[inline(always)]
            fn ln(self) -> Self {
                <$t>::ln(self)
            }
            #[inline(always)]
            fn ln_1p(self) -> Self {
                <$t>::ln_1p(self)
            }
            #[inline(always)]
            fn tanh(self) -> Self {
                <$t>::tanh(self)
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline(always)]
            fn powf(self, p: Self) -> Self {
                <$t>::powf(self, p)
            }
            #[inline(always)]
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            #[inline(always)]
            fn max(self, other: Self) -> Self {
                if self >= other { self } else { other }
            }
            #[inline(always)]
            fn min(self, other: Self) -> Self {
                if self <= other { self } else { other }
            }
            #[inline(always)]
            fn is_finite(self) -> bool {
                <$t>::is_finite(self)
            }
            #[inline(always)]
            fn neg_infinity() -> Self {
                <$t>::NEG_INFINITY
            }
            fn pool() -> &'static crate::pool::BufferPool<Self> {
                static POOL: crate::pool::BufferPool<$t> = crate::pool::BufferPool::new();
                &POOL
            }
            fn as_f32_slice(values: &[Self]) -> Option<&[f32]> {
                $as_f32(values)
            }
            fn from_f32_vec(values: Vec<f32>) -> Vec<Self> {
                $from_f32(values)
            }
        }
    };
}

fn some_f32(v: &[f32]) -> Option<&[f32]> {
    Some(v)
}
fn no_f32(_: &[f64]) -> Option<&[f32]> {
    None
}
impl_float!(f32, "f32", some_f32, |v: Vec<f32>| v);
impl_float!(f64, "f64", no_f32, |v: Vec<f32>| v.into_iter().map(f64::from).collect());

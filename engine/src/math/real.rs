use std::fmt::Debug;
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// A floating-point scalar: implemented for `f32` and `f64`.
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialOrd
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
{
    const ZERO: Self;
    const ONE: Self;
    const TWO: Self;
    const HALF: Self;
    const INFINITY: Self;
    /// The largest finite value.
    const MAX: Self;
    /// Machine epsilon of the type.
    const EPSILON: Self;

    fn from_f32(x: f32) -> Self;
    fn from_f64(x: f64) -> Self;
    fn to_f64(self) -> f64;
    fn sqrt(self) -> Self;
    fn abs(self) -> Self;
    fn is_finite(self) -> bool;
    /// The smallest number greater than `self`.
    fn next_up(self) -> Self;

    /// What a value of this precision needs beside it to give back the
    /// `f64` it was made from (see [`Real::unround`]): nothing for `f64`,
    /// the `f64` itself for `f32`. It lets the breadth-first tracer's ray
    /// slots hold a ray once, in its tests' precision, when that is `f64`,
    /// and the `f64` ray beside it only when it is not.
    type Kept: Copy + Debug + Default + Send + Sync + 'static;
    /// What to keep of `x` beside `Self::from_f64(x)`.
    fn keep(x: f64) -> Self::Kept;
    /// The `f64` `x` this value was made from (as `Self::from_f64(x)`),
    /// given `kept`, which gives what [`Real::keep`] kept of `x` (and is
    /// called only where something was kept).
    fn unround(self, kept: impl FnOnce() -> Self::Kept) -> f64;

    #[inline]
    fn max(self, o: Self) -> Self {
        if self > o { self } else { o }
    }
    #[inline]
    fn min(self, o: Self) -> Self {
        if self < o { self } else { o }
    }
}

macro_rules! impl_real {
    ($t:ty, $kept:ty, |$x:ident| $keep:expr, |$s:ident, $k:ident| $unround:expr) => {
        impl Real for $t {
            type Kept = $kept;
            #[inline(always)]
            fn keep($x: f64) -> Self::Kept {
                $keep
            }
            #[inline(always)]
            fn unround(self, $k: impl FnOnce() -> Self::Kept) -> f64 {
                let $s = self;
                $unround
            }
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const TWO: Self = 2.0;
            const HALF: Self = 0.5;
            const INFINITY: Self = <$t>::INFINITY;
            const MAX: Self = <$t>::MAX;
            const EPSILON: Self = <$t>::EPSILON;
            #[inline(always)]
            fn from_f32(x: f32) -> Self {
                x as $t
            }
            #[inline(always)]
            fn from_f64(x: f64) -> Self {
                x as $t
            }
            #[inline(always)]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline(always)]
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            #[inline(always)]
            fn is_finite(self) -> bool {
                <$t>::is_finite(self)
            }
            #[inline(always)]
            fn next_up(self) -> Self {
                <$t>::next_up(self)
            }
        }
    };
}

// An `f32` loses the `f64` it was made from, which is kept beside it.
impl_real!(f32, f64, |x| x, |_s, kept| kept());
// An `f64` is the `f64` it was made from: nothing is kept.
impl_real!(f64, (), |_x| (), |s, _kept| s);

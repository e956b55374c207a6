//! What a vector of lanes offers the kernels: the arithmetic of the
//! scalar code, lane by lane, and masks.

use crate::math::Real;
use std::ops::{Add, Div, Mul, Neg, Sub};

/// A set of lanes of one vector (one bit or one all-ones lane each).
pub trait Mask: Copy {
    /// The lanes whose bit is set in the low bits of `bits`.
    fn from_bits(bits: u64) -> Self;
    /// Bit `i` set for lane `i`.
    fn bits(self) -> u64;
    fn and(self, o: Self) -> Self;
    fn or(self, o: Self) -> Self;
    /// The lanes of `self` not in `o`.
    fn and_not(self, o: Self) -> Self;
    fn not(self) -> Self;

    #[inline(always)]
    fn any(self) -> bool {
        self.bits() != 0
    }
}

/// A vector of `N` lanes of `f32` or `f64`. Every operation is the scalar
/// one on each lane, correctly rounded; comparisons are false where
/// either side is NaN, as Rust's are.
pub trait Float:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    type Elem: Real;
    type Mask: Mask;
    /// Lanes.
    const N: usize;

    fn splat(x: Self::Elem) -> Self;
    /// The first `N` elements of `src` (which must hold that many).
    fn load(src: &[Self::Elem]) -> Self;
    /// Writes the lanes to the first `N` elements of `dst`.
    fn store(self, dst: &mut [Self::Elem]);
    fn sqrt(self) -> Self;
    fn abs(self) -> Self;
    fn lt(self, o: Self) -> Self::Mask;
    fn le(self, o: Self) -> Self::Mask;
    fn gt(self, o: Self) -> Self::Mask;
    fn ge(self, o: Self) -> Self::Mask;
    fn eq(self, o: Self) -> Self::Mask;
    /// `a` in the lanes of `m`, `b` elsewhere.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;

    /// `self` where it is less than `o`, else `o` (as [`Real::min`]).
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        Self::select(self.lt(o), self, o)
    }

    /// `self` where it is greater than `o`, else `o` (as [`Real::max`]).
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        Self::select(self.gt(o), self, o)
    }
}

/// The vectors of one instruction set.
pub trait Lanes {
    type F32: Float<Elem = f32>;
    type F64: Float<Elem = f64>;
}

/// A scalar the kernels run in: `f32` or `f64`, with its vector for
/// each instruction set.
pub trait Elem: Real {
    type V<L: Lanes>: Float<Elem = Self>;
}

impl Elem for f32 {
    type V<L: Lanes> = L::F32;
}

impl Elem for f64 {
    type V<L: Lanes> = L::F64;
}

/// Work written once for every instruction set (see
/// [`super::Isa::run`]). `run` is inlined into a function compiled with
/// the instruction set's features, so it should be `#[inline(always)]`
/// and call only `#[inline(always)]` code in its loops.
pub trait Job {
    type Out;
    fn run<L: Lanes>(self) -> Self::Out;
}

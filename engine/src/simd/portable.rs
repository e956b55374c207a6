//! The portable lanes: plain Rust arrays, one scalar operation per lane.
//! Any CPU runs them; they are the reference the other widths match.

use super::lanes::{Float, Lanes, Mask};
use crate::math::Real;
use std::ops::{Add, Div, Mul, Neg, Sub};

pub struct Portable;

impl Lanes for Portable {
    type F32 = P<f32, 4>;
    type F64 = P<f64, 2>;
}

#[derive(Clone, Copy, Debug)]
pub struct P<T, const N: usize>([T; N]);

#[derive(Clone, Copy, Debug)]
pub struct PMask<const N: usize>([bool; N]);

impl<const N: usize> Mask for PMask<N> {
    #[inline(always)]
    fn from_bits(bits: u64) -> Self {
        PMask(std::array::from_fn(|i| bits >> i & 1 != 0))
    }
    #[inline(always)]
    fn bits(self) -> u64 {
        let mut b = 0;
        for (i, &x) in self.0.iter().enumerate() {
            b |= (x as u64) << i;
        }
        b
    }
    #[inline(always)]
    fn and(self, o: Self) -> Self {
        PMask(std::array::from_fn(|i| self.0[i] & o.0[i]))
    }
    #[inline(always)]
    fn or(self, o: Self) -> Self {
        PMask(std::array::from_fn(|i| self.0[i] | o.0[i]))
    }
    #[inline(always)]
    fn and_not(self, o: Self) -> Self {
        PMask(std::array::from_fn(|i| self.0[i] & !o.0[i]))
    }
    #[inline(always)]
    fn not(self) -> Self {
        PMask(self.0.map(|x| !x))
    }
}

macro_rules! binary {
    ($Op:ident, $op:ident) => {
        impl<T: Real, const N: usize> $Op for P<T, N> {
            type Output = Self;
            #[inline(always)]
            fn $op(self, o: Self) -> Self {
                P(std::array::from_fn(|i| self.0[i].$op(o.0[i])))
            }
        }
    };
}

binary!(Add, add);
binary!(Sub, sub);
binary!(Mul, mul);
binary!(Div, div);

impl<T: Real, const N: usize> Neg for P<T, N> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        P(self.0.map(|x| -x))
    }
}

macro_rules! compare {
    ($name:ident, $op:tt) => {
        #[inline(always)]
        fn $name(self, o: Self) -> Self::Mask {
            PMask(std::array::from_fn(|i| self.0[i] $op o.0[i]))
        }
    };
}

macro_rules! float {
    ($T:ty, $N:literal) => {
        impl Float for P<$T, $N> {
            type Elem = $T;
            type Mask = PMask<$N>;
            const N: usize = $N;

            #[inline(always)]
            fn splat(x: $T) -> Self {
                P([x; $N])
            }
            #[inline(always)]
            fn load(src: &[$T]) -> Self {
                let s: &[$T; $N] = src[..$N].try_into().expect("N elements");
                P(*s)
            }
            #[inline(always)]
            fn store(self, dst: &mut [$T]) {
                dst[..$N].copy_from_slice(&self.0);
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                P(self.0.map(|x| x.sqrt()))
            }
            #[inline(always)]
            fn abs(self) -> Self {
                P(self.0.map(|x| x.abs()))
            }
            compare!(lt, <);
            compare!(le, <=);
            compare!(gt, >);
            compare!(ge, >=);
            compare!(eq, ==);
            #[inline(always)]
            fn select(m: PMask<$N>, a: Self, b: Self) -> Self {
                P(std::array::from_fn(|i| if m.0[i] { a.0[i] } else { b.0[i] }))
            }
        }
    };
}

float!(f32, 4);
float!(f64, 2);

//! The AArch64 lanes: NEON, part of every AArch64 CPU (four `f32` or
//! two `f64` lanes).
//!
//! **Why the `unsafe` blocks here are sound.** NEON is in the AArch64
//! baseline, so its arithmetic intrinsics need no run-time check. Loads
//! and stores read and write exactly `N` elements of a slice whose length
//! was checked by indexing it first (`&src[..N]`).
//!
//! NEON's own `vminq`/`vmaxq` treat NaN unlike the x86 instructions, so,
//! as everywhere, `min` and `max` are a comparison and a select
//! ([`Float::min`]).

use super::lanes::{Float, Lanes, Mask};
use std::arch::aarch64::*;
use std::ops::{Add, Div, Mul, Neg, Sub};

pub struct Neon;

impl Lanes for Neon {
    type F32 = F32x4;
    type F64 = F64x2;
}

macro_rules! neon {
    ($V:ident, $M:ident, $raw:ty, $mraw:ty, $T:ty, $N:literal, $U:ty,
     add: $add:ident, sub: $sub:ident, mul: $mul:ident, div: $div:ident, neg: $neg:ident,
     abs: $abs:ident, sqrt: $sqrt:ident, dup: $dup:ident, ld: $ld:ident, st: $st:ident,
     lt: $lt:ident, le: $le:ident, gt: $gt:ident, ge: $ge:ident, eq: $eq:ident,
     bsl: $bsl:ident, and: $and:ident, or: $or:ident, bic: $bic:ident, mvn: $mvn:expr,
     udup: $udup:ident, uld: $uld:ident, tst: $tst:ident, ust: $ust:ident) => {
        #[derive(Clone, Copy)]
        pub struct $V($raw);

        #[derive(Clone, Copy)]
        pub struct $M($mraw);

        impl Mask for $M {
            #[inline(always)]
            fn from_bits(bits: u64) -> $M {
                let lane: [$U; $N] = std::array::from_fn(|i| 1 << i);
                // SAFETY: see the module's documentation.
                $M(unsafe { $tst($udup(bits as $U), $uld(lane.as_ptr())) })
            }
            #[inline(always)]
            fn bits(self) -> u64 {
                let mut lanes = [0 as $U; $N];
                // SAFETY: `lanes` holds N elements.
                unsafe { $ust(lanes.as_mut_ptr(), self.0) };
                let mut b = 0;
                for (i, &x) in lanes.iter().enumerate() {
                    b |= ((x != 0) as u64) << i;
                }
                b
            }
            #[inline(always)]
            fn and(self, o: $M) -> $M {
                // SAFETY: see the module's documentation.
                $M(unsafe { $and(self.0, o.0) })
            }
            #[inline(always)]
            fn or(self, o: $M) -> $M {
                // SAFETY: see the module's documentation.
                $M(unsafe { $or(self.0, o.0) })
            }
            #[inline(always)]
            fn and_not(self, o: $M) -> $M {
                // SAFETY: see the module's documentation.
                $M(unsafe { $bic(self.0, o.0) })
            }
            #[inline(always)]
            fn not(self) -> $M {
                let f: fn($mraw) -> $mraw = $mvn;
                $M(f(self.0))
            }
        }

        impl Add for $V {
            type Output = $V;
            #[inline(always)]
            fn add(self, o: $V) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $add(self.0, o.0) })
            }
        }
        impl Sub for $V {
            type Output = $V;
            #[inline(always)]
            fn sub(self, o: $V) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $sub(self.0, o.0) })
            }
        }
        impl Mul for $V {
            type Output = $V;
            #[inline(always)]
            fn mul(self, o: $V) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $mul(self.0, o.0) })
            }
        }
        impl Div for $V {
            type Output = $V;
            #[inline(always)]
            fn div(self, o: $V) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $div(self.0, o.0) })
            }
        }
        impl Neg for $V {
            type Output = $V;
            #[inline(always)]
            fn neg(self) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $neg(self.0) })
            }
        }

        impl Float for $V {
            type Elem = $T;
            type Mask = $M;
            const N: usize = $N;

            #[inline(always)]
            fn splat(x: $T) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $dup(x) })
            }
            #[inline(always)]
            fn load(src: &[$T]) -> $V {
                let s = &src[..$N];
                // SAFETY: `s` holds N elements.
                $V(unsafe { $ld(s.as_ptr()) })
            }
            #[inline(always)]
            fn store(self, dst: &mut [$T]) {
                let d = &mut dst[..$N];
                // SAFETY: `d` holds N elements.
                unsafe { $st(d.as_mut_ptr(), self.0) }
            }
            #[inline(always)]
            fn sqrt(self) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $sqrt(self.0) })
            }
            #[inline(always)]
            fn abs(self) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $abs(self.0) })
            }
            #[inline(always)]
            fn lt(self, o: $V) -> $M {
                // SAFETY: see the module's documentation.
                $M(unsafe { $lt(self.0, o.0) })
            }
            #[inline(always)]
            fn le(self, o: $V) -> $M {
                // SAFETY: see the module's documentation.
                $M(unsafe { $le(self.0, o.0) })
            }
            #[inline(always)]
            fn gt(self, o: $V) -> $M {
                // SAFETY: see the module's documentation.
                $M(unsafe { $gt(self.0, o.0) })
            }
            #[inline(always)]
            fn ge(self, o: $V) -> $M {
                // SAFETY: see the module's documentation.
                $M(unsafe { $ge(self.0, o.0) })
            }
            #[inline(always)]
            fn eq(self, o: $V) -> $M {
                // SAFETY: see the module's documentation.
                $M(unsafe { $eq(self.0, o.0) })
            }
            #[inline(always)]
            fn select(m: $M, a: $V, b: $V) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $bsl(m.0, a.0, b.0) })
            }
        }
    };
}

neon!(F32x4, M32x4, float32x4_t, uint32x4_t, f32, 4, u32,
    add: vaddq_f32, sub: vsubq_f32, mul: vmulq_f32, div: vdivq_f32, neg: vnegq_f32,
    abs: vabsq_f32, sqrt: vsqrtq_f32, dup: vdupq_n_f32, ld: vld1q_f32, st: vst1q_f32,
    lt: vcltq_f32, le: vcleq_f32, gt: vcgtq_f32, ge: vcgeq_f32, eq: vceqq_f32,
    bsl: vbslq_f32, and: vandq_u32, or: vorrq_u32, bic: vbicq_u32,
    // SAFETY: see the module's documentation.
    mvn: |m| unsafe { vmvnq_u32(m) },
    udup: vdupq_n_u32, uld: vld1q_u32, tst: vtstq_u32, ust: vst1q_u32
);

neon!(F64x2, M64x2, float64x2_t, uint64x2_t, f64, 2, u64,
    add: vaddq_f64, sub: vsubq_f64, mul: vmulq_f64, div: vdivq_f64, neg: vnegq_f64,
    abs: vabsq_f64, sqrt: vsqrtq_f64, dup: vdupq_n_f64, ld: vld1q_f64, st: vst1q_f64,
    lt: vcltq_f64, le: vcleq_f64, gt: vcgtq_f64, ge: vcgeq_f64, eq: vceqq_f64,
    bsl: vbslq_f64, and: vandq_u64, or: vorrq_u64, bic: vbicq_u64,
    // No 64-bit NOT: flip the bits as 32-bit lanes.
    // SAFETY: see the module's documentation.
    mvn: |m| unsafe { vreinterpretq_u64_u32(vmvnq_u32(vreinterpretq_u32_u64(m))) },
    udup: vdupq_n_u64, uld: vld1q_u64, tst: vtstq_u64, ust: vst1q_u64
);

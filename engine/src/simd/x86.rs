//! The x86-64 lanes: SSE2 (every x86-64 CPU), AVX2 and AVX-512F.
//!
//! **Why the `unsafe` blocks here are sound.** The AVX2 and AVX-512
//! intrinsics may only run on a CPU that has those features. The types of
//! this module are private to [`super`], and the only code that
//! instantiates kernels with [`Avx2`] or [`Avx512`] is [`run_avx2`] and
//! [`run_avx512`], which [`super::Isa::run`] calls only after
//! `is_x86_feature_detected!` said the CPU has the features they are
//! compiled with ([`has_avx2`], and AVX-512F). Loads and
//! stores read and write exactly `N` elements of a slice whose length was
//! checked by indexing it first (`&src[..N]`). SSE2 is part of the
//! x86-64 baseline, so its intrinsics need no such argument.

use super::lanes::{Float, Job, Lanes, Mask};
use std::arch::x86_64::*;
use std::ops::{Add, Div, Mul, Neg, Sub};

pub struct Sse;
pub struct Avx2;
pub struct Avx512;

impl Lanes for Sse {
    type F32 = F32x4;
    type F64 = F64x2;
}

impl Lanes for Avx2 {
    type F32 = F32x8;
    type F64 = F64x4;
}

impl Lanes for Avx512 {
    type F32 = F32x16;
    type F64 = F64x8;
}

/// Whether the CPU has AVX2 and the bit instructions that come with every
/// AVX2 CPU (x86-64-v3): population count, and BMI1/BMI2/LZCNT. The
/// kernels count and find lanes in masks, which without `popcnt` costs
/// twenty instructions a count.
pub fn has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("popcnt")
        && std::arch::is_x86_feature_detected!("bmi1")
        && std::arch::is_x86_feature_detected!("bmi2")
        && std::arch::is_x86_feature_detected!("lzcnt")
}

/// Runs `job` with AVX2 lanes.
///
/// # Safety
/// The CPU must have what [`has_avx2`] checks.
#[target_feature(enable = "avx2,popcnt,bmi1,bmi2,lzcnt")]
pub unsafe fn run_avx2<J: Job>(job: J) -> J::Out {
    job.run::<Avx2>()
}

/// Runs `job` with AVX-512 lanes.
///
/// # Safety
/// The CPU must have AVX-512F and what [`has_avx2`] checks.
#[target_feature(enable = "avx512f,avx2,popcnt,bmi1,bmi2,lzcnt")]
pub unsafe fn run_avx512<J: Job>(job: J) -> J::Out {
    job.run::<Avx512>()
}

/// The arithmetic operators of a vector type, from its intrinsics.
macro_rules! operators {
    ($V:ident, $add:ident, $sub:ident, $mul:ident, $div:ident) => {
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
    };
}

// ---- SSE2 and AVX2: masks are vectors of all-ones or all-zeros lanes.

/// A mask held as a vector whose lanes are all ones or all zeros.
macro_rules! vector_mask {
    ($M:ident, $raw:ty, $and:ident, $or:ident, $andnot:ident, $xor:ident, $movemask:ident,
     $from_bits:expr, $ones:expr) => {
        #[derive(Clone, Copy)]
        pub struct $M($raw);

        impl Mask for $M {
            #[inline(always)]
            fn from_bits(bits: u64) -> $M {
                let f: fn(u64) -> $raw = $from_bits;
                $M(f(bits))
            }
            #[inline(always)]
            fn bits(self) -> u64 {
                // SAFETY: see the module's documentation.
                unsafe { $movemask(self.0) as u32 as u64 }
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
                $M(unsafe { $andnot(o.0, self.0) })
            }
            #[inline(always)]
            fn not(self) -> $M {
                let f: fn() -> $raw = $ones;
                // SAFETY: see the module's documentation.
                $M(unsafe { $xor(self.0, f()) })
            }
        }
    };
}

vector_mask!(
    M32x4,
    __m128,
    _mm_and_ps,
    _mm_or_ps,
    _mm_andnot_ps,
    _mm_xor_ps,
    _mm_movemask_ps,
    |b| {
        // SAFETY: see the module's documentation.
        unsafe {
            let lane = _mm_setr_epi32(1, 2, 4, 8);
            let set = _mm_and_si128(_mm_set1_epi32(b as i32), lane);
            _mm_castsi128_ps(_mm_cmpeq_epi32(set, lane))
        }
    },
    || {
        // SAFETY: see the module's documentation.
        unsafe {
            let z = _mm_setzero_si128();
            _mm_castsi128_ps(_mm_cmpeq_epi32(z, z))
        }
    }
);

vector_mask!(
    M64x2,
    __m128d,
    _mm_and_pd,
    _mm_or_pd,
    _mm_andnot_pd,
    _mm_xor_pd,
    _mm_movemask_pd,
    |b| {
        // Each 64-bit lane as two equal 32-bit halves.
        // SAFETY: see the module's documentation.
        unsafe {
            let lane = _mm_setr_epi32(1, 1, 2, 2);
            let set = _mm_and_si128(_mm_set1_epi32(b as i32), lane);
            _mm_castsi128_pd(_mm_cmpeq_epi32(set, lane))
        }
    },
    || {
        // SAFETY: see the module's documentation.
        unsafe {
            let z = _mm_setzero_si128();
            _mm_castsi128_pd(_mm_cmpeq_epi32(z, z))
        }
    }
);

vector_mask!(
    M32x8,
    __m256,
    _mm256_and_ps,
    _mm256_or_ps,
    _mm256_andnot_ps,
    _mm256_xor_ps,
    _mm256_movemask_ps,
    |b| {
        // SAFETY: see the module's documentation.
        unsafe {
            let lane = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            let set = _mm256_and_si256(_mm256_set1_epi32(b as i32), lane);
            _mm256_castsi256_ps(_mm256_cmpeq_epi32(set, lane))
        }
    },
    || {
        // SAFETY: see the module's documentation.
        unsafe {
            let z = _mm256_setzero_si256();
            _mm256_castsi256_ps(_mm256_cmpeq_epi32(z, z))
        }
    }
);

vector_mask!(
    M64x4,
    __m256d,
    _mm256_and_pd,
    _mm256_or_pd,
    _mm256_andnot_pd,
    _mm256_xor_pd,
    _mm256_movemask_pd,
    |b| {
        // SAFETY: see the module's documentation.
        unsafe {
            let lane = _mm256_setr_epi64x(1, 2, 4, 8);
            let set = _mm256_and_si256(_mm256_set1_epi64x(b as i64), lane);
            _mm256_castsi256_pd(_mm256_cmpeq_epi64(set, lane))
        }
    },
    || {
        // SAFETY: see the module's documentation.
        unsafe {
            let z = _mm256_setzero_si256();
            _mm256_castsi256_pd(_mm256_cmpeq_epi64(z, z))
        }
    }
);

/// A vector type whose masks are vectors.
macro_rules! vector_float {
    ($V:ident, $M:ident, $raw:ty, $T:ty, $N:literal,
     add: $add:ident, sub: $sub:ident, mul: $mul:ident, div: $div:ident,
     set1: $set1:ident, loadu: $loadu:ident, storeu: $storeu:ident, sqrt: $sqrt:ident,
     xor: $xor:ident, andnot: $andnot:ident, and: $and:ident, or: $or:ident,
     min: $min:ident, max: $max:ident,
     lt: $lt:expr, le: $le:expr, gt: $gt:expr, ge: $ge:expr, eq: $eq:expr,
     select: $select:expr) => {
        #[derive(Clone, Copy)]
        pub struct $V($raw);

        operators!($V, $add, $sub, $mul, $div);

        impl Neg for $V {
            type Output = $V;
            #[inline(always)]
            fn neg(self) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $xor(self.0, $set1(-0.0)) })
            }
        }

        impl Float for $V {
            type Elem = $T;
            type Mask = $M;
            const N: usize = $N;

            #[inline(always)]
            fn splat(x: $T) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $set1(x) })
            }
            #[inline(always)]
            fn load(src: &[$T]) -> $V {
                let s = &src[..$N];
                // SAFETY: `s` holds N elements; unaligned loads.
                $V(unsafe { $loadu(s.as_ptr()) })
            }
            #[inline(always)]
            fn store(self, dst: &mut [$T]) {
                let d = &mut dst[..$N];
                // SAFETY: `d` holds N elements; unaligned stores.
                unsafe { $storeu(d.as_mut_ptr(), self.0) }
            }
            #[inline(always)]
            fn sqrt(self) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $sqrt(self.0) })
            }
            #[inline(always)]
            fn abs(self) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $andnot($set1(-0.0), self.0) })
            }
            #[inline(always)]
            fn lt(self, o: $V) -> $M {
                let f: fn($raw, $raw) -> $raw = $lt;
                $M(f(self.0, o.0))
            }
            #[inline(always)]
            fn le(self, o: $V) -> $M {
                let f: fn($raw, $raw) -> $raw = $le;
                $M(f(self.0, o.0))
            }
            #[inline(always)]
            fn gt(self, o: $V) -> $M {
                let f: fn($raw, $raw) -> $raw = $gt;
                $M(f(self.0, o.0))
            }
            #[inline(always)]
            fn ge(self, o: $V) -> $M {
                let f: fn($raw, $raw) -> $raw = $ge;
                $M(f(self.0, o.0))
            }
            #[inline(always)]
            fn eq(self, o: $V) -> $M {
                let f: fn($raw, $raw) -> $raw = $eq;
                $M(f(self.0, o.0))
            }
            #[inline(always)]
            fn select(m: $M, a: $V, b: $V) -> $V {
                let f: fn($raw, $raw, $raw) -> $raw = $select;
                $V(f(m.0, a.0, b.0))
            }
            /// MINPS(a, b) is `a < b ? a : b`, NaN and signed zeros
            /// included: exactly [`Float::min`].
            #[inline(always)]
            fn min(self, o: $V) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $min(self.0, o.0) })
            }
            /// MAXPS(a, b) is `a > b ? a : b`: exactly [`Float::max`].
            #[inline(always)]
            fn max(self, o: $V) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $max(self.0, o.0) })
            }
        }
    };
}

// SAFETY (each closure below): see the module's documentation.
vector_float!(F32x4, M32x4, __m128, f32, 4,
    add: _mm_add_ps, sub: _mm_sub_ps, mul: _mm_mul_ps, div: _mm_div_ps,
    set1: _mm_set1_ps, loadu: _mm_loadu_ps, storeu: _mm_storeu_ps, sqrt: _mm_sqrt_ps,
    xor: _mm_xor_ps, andnot: _mm_andnot_ps, and: _mm_and_ps, or: _mm_or_ps,
    min: _mm_min_ps, max: _mm_max_ps,
    lt: |a, b| unsafe { _mm_cmplt_ps(a, b) }, le: |a, b| unsafe { _mm_cmple_ps(a, b) },
    gt: |a, b| unsafe { _mm_cmpgt_ps(a, b) }, ge: |a, b| unsafe { _mm_cmpge_ps(a, b) },
    eq: |a, b| unsafe { _mm_cmpeq_ps(a, b) },
    // SSE2 has no blend: (m & a) | (!m & b).
    select: |m, a, b| unsafe { _mm_or_ps(_mm_and_ps(m, a), _mm_andnot_ps(m, b)) }
);

// SAFETY (each closure below): see the module's documentation.
vector_float!(F64x2, M64x2, __m128d, f64, 2,
    add: _mm_add_pd, sub: _mm_sub_pd, mul: _mm_mul_pd, div: _mm_div_pd,
    set1: _mm_set1_pd, loadu: _mm_loadu_pd, storeu: _mm_storeu_pd, sqrt: _mm_sqrt_pd,
    xor: _mm_xor_pd, andnot: _mm_andnot_pd, and: _mm_and_pd, or: _mm_or_pd,
    min: _mm_min_pd, max: _mm_max_pd,
    lt: |a, b| unsafe { _mm_cmplt_pd(a, b) }, le: |a, b| unsafe { _mm_cmple_pd(a, b) },
    gt: |a, b| unsafe { _mm_cmpgt_pd(a, b) }, ge: |a, b| unsafe { _mm_cmpge_pd(a, b) },
    eq: |a, b| unsafe { _mm_cmpeq_pd(a, b) },
    select: |m, a, b| unsafe { _mm_or_pd(_mm_and_pd(m, a), _mm_andnot_pd(m, b)) }
);

vector_float!(F32x8, M32x8, __m256, f32, 8,
    add: _mm256_add_ps, sub: _mm256_sub_ps, mul: _mm256_mul_ps, div: _mm256_div_ps,
    set1: _mm256_set1_ps, loadu: _mm256_loadu_ps, storeu: _mm256_storeu_ps,
    sqrt: _mm256_sqrt_ps,
    xor: _mm256_xor_ps, andnot: _mm256_andnot_ps, and: _mm256_and_ps, or: _mm256_or_ps,
    min: _mm256_min_ps, max: _mm256_max_ps,
    // SAFETY (each closure below): see the module's documentation.
    lt: |a, b| unsafe { _mm256_cmp_ps::<_CMP_LT_OQ>(a, b) },
    le: |a, b| unsafe { _mm256_cmp_ps::<_CMP_LE_OQ>(a, b) },
    gt: |a, b| unsafe { _mm256_cmp_ps::<_CMP_GT_OQ>(a, b) },
    ge: |a, b| unsafe { _mm256_cmp_ps::<_CMP_GE_OQ>(a, b) },
    eq: |a, b| unsafe { _mm256_cmp_ps::<_CMP_EQ_OQ>(a, b) },
    select: |m, a, b| unsafe { _mm256_blendv_ps(b, a, m) }
);

vector_float!(F64x4, M64x4, __m256d, f64, 4,
    add: _mm256_add_pd, sub: _mm256_sub_pd, mul: _mm256_mul_pd, div: _mm256_div_pd,
    set1: _mm256_set1_pd, loadu: _mm256_loadu_pd, storeu: _mm256_storeu_pd,
    sqrt: _mm256_sqrt_pd,
    xor: _mm256_xor_pd, andnot: _mm256_andnot_pd, and: _mm256_and_pd, or: _mm256_or_pd,
    min: _mm256_min_pd, max: _mm256_max_pd,
    // SAFETY (each closure below): see the module's documentation.
    lt: |a, b| unsafe { _mm256_cmp_pd::<_CMP_LT_OQ>(a, b) },
    le: |a, b| unsafe { _mm256_cmp_pd::<_CMP_LE_OQ>(a, b) },
    gt: |a, b| unsafe { _mm256_cmp_pd::<_CMP_GT_OQ>(a, b) },
    ge: |a, b| unsafe { _mm256_cmp_pd::<_CMP_GE_OQ>(a, b) },
    eq: |a, b| unsafe { _mm256_cmp_pd::<_CMP_EQ_OQ>(a, b) },
    select: |m, a, b| unsafe { _mm256_blendv_pd(b, a, m) }
);

// ---- AVX-512: masks are bit masks (k registers).

macro_rules! bit_mask {
    ($M:ident, $raw:ty, $N:literal) => {
        #[derive(Clone, Copy)]
        pub struct $M($raw);

        impl Mask for $M {
            #[inline(always)]
            fn from_bits(bits: u64) -> $M {
                $M(bits as $raw)
            }
            #[inline(always)]
            fn bits(self) -> u64 {
                self.0 as u64
            }
            #[inline(always)]
            fn and(self, o: $M) -> $M {
                $M(self.0 & o.0)
            }
            #[inline(always)]
            fn or(self, o: $M) -> $M {
                $M(self.0 | o.0)
            }
            #[inline(always)]
            fn and_not(self, o: $M) -> $M {
                $M(self.0 & !o.0)
            }
            #[inline(always)]
            fn not(self) -> $M {
                $M(!self.0)
            }
        }
    };
}

bit_mask!(K16, __mmask16, 16);
bit_mask!(K8, __mmask8, 8);

macro_rules! avx512_float {
    ($V:ident, $M:ident, $raw:ty, $T:ty, $N:literal, $suffix:ident,
     add: $add:ident, sub: $sub:ident, mul: $mul:ident, div: $div:ident,
     set1: $set1:ident, loadu: $loadu:ident, storeu: $storeu:ident, sqrt: $sqrt:ident,
     abs: $abs:ident, cmp: $cmp:ident, blend: $blend:ident, min: $min:ident, max: $max:ident,
     neg: $neg:expr) => {
        #[derive(Clone, Copy)]
        pub struct $V($raw);

        operators!($V, $add, $sub, $mul, $div);

        impl Neg for $V {
            type Output = $V;
            #[inline(always)]
            fn neg(self) -> $V {
                let f: fn($raw) -> $raw = $neg;
                $V(f(self.0))
            }
        }

        impl Float for $V {
            type Elem = $T;
            type Mask = $M;
            const N: usize = $N;

            #[inline(always)]
            fn splat(x: $T) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $set1(x) })
            }
            #[inline(always)]
            fn load(src: &[$T]) -> $V {
                let s = &src[..$N];
                // SAFETY: `s` holds N elements; unaligned loads.
                $V(unsafe { $loadu(s.as_ptr()) })
            }
            #[inline(always)]
            fn store(self, dst: &mut [$T]) {
                let d = &mut dst[..$N];
                // SAFETY: `d` holds N elements; unaligned stores.
                unsafe { $storeu(d.as_mut_ptr(), self.0) }
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
                $M(unsafe { $cmp::<_CMP_LT_OQ>(self.0, o.0) })
            }
            #[inline(always)]
            fn le(self, o: $V) -> $M {
                // SAFETY: see the module's documentation.
                $M(unsafe { $cmp::<_CMP_LE_OQ>(self.0, o.0) })
            }
            #[inline(always)]
            fn gt(self, o: $V) -> $M {
                // SAFETY: see the module's documentation.
                $M(unsafe { $cmp::<_CMP_GT_OQ>(self.0, o.0) })
            }
            #[inline(always)]
            fn ge(self, o: $V) -> $M {
                // SAFETY: see the module's documentation.
                $M(unsafe { $cmp::<_CMP_GE_OQ>(self.0, o.0) })
            }
            #[inline(always)]
            fn eq(self, o: $V) -> $M {
                // SAFETY: see the module's documentation.
                $M(unsafe { $cmp::<_CMP_EQ_OQ>(self.0, o.0) })
            }
            #[inline(always)]
            fn select(m: $M, a: $V, b: $V) -> $V {
                // `blend` takes its second operand where the mask is set.
                // SAFETY: see the module's documentation.
                $V(unsafe { $blend(m.0, b.0, a.0) })
            }
            /// VMINPS(a, b) is `a < b ? a : b`: exactly [`Float::min`].
            #[inline(always)]
            fn min(self, o: $V) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $min(self.0, o.0) })
            }
            /// VMAXPS(a, b) is `a > b ? a : b`: exactly [`Float::max`].
            #[inline(always)]
            fn max(self, o: $V) -> $V {
                // SAFETY: see the module's documentation.
                $V(unsafe { $max(self.0, o.0) })
            }
        }
    };
}

avx512_float!(F32x16, K16, __m512, f32, 16, ps,
    add: _mm512_add_ps, sub: _mm512_sub_ps, mul: _mm512_mul_ps, div: _mm512_div_ps,
    set1: _mm512_set1_ps, loadu: _mm512_loadu_ps, storeu: _mm512_storeu_ps,
    sqrt: _mm512_sqrt_ps, abs: _mm512_abs_ps, cmp: _mm512_cmp_ps_mask,
    blend: _mm512_mask_blend_ps, min: _mm512_min_ps, max: _mm512_max_ps,
    // AVX-512F has no float xor: flip the sign bit as an integer.
    // SAFETY: see the module's documentation.
    neg: |a| unsafe {
        _mm512_castsi512_ps(_mm512_xor_si512(
            _mm512_castps_si512(a),
            _mm512_set1_epi32(i32::MIN),
        ))
    }
);

avx512_float!(F64x8, K8, __m512d, f64, 8, pd,
    add: _mm512_add_pd, sub: _mm512_sub_pd, mul: _mm512_mul_pd, div: _mm512_div_pd,
    set1: _mm512_set1_pd, loadu: _mm512_loadu_pd, storeu: _mm512_storeu_pd,
    sqrt: _mm512_sqrt_pd, abs: _mm512_abs_pd, cmp: _mm512_cmp_pd_mask,
    blend: _mm512_mask_blend_pd, min: _mm512_min_pd, max: _mm512_max_pd,
    // SAFETY: see the module's documentation.
    neg: |a| unsafe {
        _mm512_castsi512_pd(_mm512_xor_si512(
            _mm512_castpd_si512(a),
            _mm512_set1_epi64(i64::MIN),
        ))
    }
);

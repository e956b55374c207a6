//! Every operation, on every instruction set this machine has, against
//! the scalar operation lane by lane: the same bits, NaN, infinities,
//! signed zeros and subnormals included.

use super::*;
use crate::math::Real;

/// Values where instruction sets are known to disagree if one is careless.
fn awkward<R: Real>() -> Vec<R> {
    let mut v: Vec<R> = [
        0.0,
        -0.0,
        1.0,
        -1.0,
        0.1,
        -2.5,
        3.0e38,
        -3.0e38,
        1e-40,
        -1e-40,
        1e-310,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
        7.0,
        1e-7,
    ]
    .into_iter()
    .map(R::from_f64)
    .collect();
    // A few ordinary numbers, so every lane position sees every value.
    let mut x = 0.3f64;
    for _ in 0..48 {
        x = (x * 7.919 + 0.123).fract();
        v.push(R::from_f64((x - 0.5) * 100.0));
    }
    v
}

/// Applies each operation to `a` and `b` lane by lane through the vector
/// type of an instruction set: one row of results per operation, and the
/// comparisons and mask operations as bits.
struct Ops<'a, R> {
    a: &'a [R],
    b: &'a [R],
}

impl<R: Elem> Job for Ops<'_, R> {
    type Out = (Vec<Vec<u64>>, Vec<Vec<bool>>);

    #[inline(always)]
    fn run<L: Lanes>(self) -> Self::Out {
        run_ops::<R, R::V<L>>(self.a, self.b)
    }
}

/// Results as bits, one row per operation; masks as one row of lanes per
/// operation. Panics if a mask made from bits does not give them back.
#[inline(always)]
fn run_ops<R: Elem, V: Float<Elem = R>>(a: &[R], b: &[R]) -> (Vec<Vec<u64>>, Vec<Vec<bool>>) {
    let n = a.len();
    let mut rows = vec![vec![0u64; n]; 11];
    let mut masks = vec![vec![false; n]; 9];
    let mut out = vec![R::ZERO; V::N];
    let all = (1u64 << V::N) - 1;
    for c in (0..n).step_by(V::N) {
        let (x, y) = (V::load(&a[c..]), V::load(&b[c..]));
        let results = [
            x + y,
            x - y,
            x * y,
            x / y,
            x.sqrt(),
            x.abs(),
            -x,
            x.min(y),
            x.max(y),
            V::select(x.lt(y), x, y),
            x * y + y,
        ];
        for (row, v) in rows.iter_mut().zip(results) {
            v.store(&mut out);
            for k in 0..V::N {
                row[c + k] = out[k].to_f64().to_bits();
            }
        }
        let z = V::splat(R::ZERO);
        let got = [
            x.lt(y),
            x.le(y),
            x.gt(y),
            x.ge(y),
            x.eq(y),
            x.lt(y).and(x.gt(z)),
            x.lt(y).or(x.eq(y)),
            x.lt(y).and_not(x.ge(V::splat(R::ONE))),
            x.lt(y).not(),
        ];
        for (row, mk) in masks.iter_mut().zip(got) {
            for k in 0..V::N {
                row[c + k] = mk.bits() >> k & 1 != 0;
            }
        }
        for bits in [0, all, 0b1011_0110_1001_0111 & all, 1, 1 << (V::N - 1)] {
            assert_eq!(V::Mask::from_bits(bits).bits(), bits, "mask of {bits:b}");
        }
    }
    (rows, masks)
}

fn every_operation_matches<R: Elem>() {
    let v = awkward::<R>();
    // Every pair of awkward values, in lanes of every position.
    let mut a = Vec::new();
    let mut b = Vec::new();
    for &x in &v {
        for &y in &v {
            a.push(x);
            b.push(y);
        }
    }
    while a.len() % 16 != 0 {
        a.push(R::ONE);
        b.push(R::ONE);
    }
    let reference = Isa::Portable.run(Ops { a: &a, b: &b });
    // The portable lanes against plain scalar arithmetic.
    for i in 0..a.len() {
        let (x, y) = (a[i], b[i]);
        let want = [
            x + y,
            x - y,
            x * y,
            x / y,
            x.sqrt(),
            x.abs(),
            -x,
            x.min(y),
            x.max(y),
        ];
        for (r, w) in want.iter().enumerate() {
            assert_eq!(
                reference.0[r][i],
                w.to_f64().to_bits(),
                "op {r} on {x:?}, {y:?}"
            );
        }
        let cmp = [x < y, x <= y, x > y, x >= y, x == y];
        for (r, w) in cmp.iter().enumerate() {
            assert_eq!(reference.1[r][i], *w, "comparison {r} on {x:?}, {y:?}");
        }
    }
    for isa in Isa::available_here() {
        let got = isa.run(Ops { a: &a, b: &b });
        for (r, (g, w)) in got.0.iter().zip(&reference.0).enumerate() {
            for i in 0..a.len() {
                assert_eq!(g[i], w[i], "{isa}: op {r} on {:?}, {:?}", a[i], b[i]);
            }
        }
        for (r, (g, w)) in got.1.iter().zip(&reference.1).enumerate() {
            for i in 0..a.len() {
                assert_eq!(g[i], w[i], "{isa}: mask op {r} on {:?}, {:?}", a[i], b[i]);
            }
        }
    }
}

#[test]
fn every_operation_matches_scalar_arithmetic_in_f32() {
    every_operation_matches::<f32>();
}

#[test]
fn every_operation_matches_scalar_arithmetic_in_f64() {
    every_operation_matches::<f64>();
}

#[test]
fn the_choice_can_be_forced_and_is_checked() {
    assert_eq!("avx2".parse::<Isa>(), Ok(Isa::Avx2));
    assert!("avx1024".parse::<Isa>().is_err());
    assert_eq!(Isa::choose(Some(Isa::Portable)).unwrap(), Isa::Portable);
    for isa in Isa::ALL {
        assert_eq!(Isa::choose(Some(isa)).is_ok(), isa.available(), "{isa}");
    }
    assert!(Isa::detect().available());
    assert!(Isa::available_here().contains(&Isa::Portable));
}

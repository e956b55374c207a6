//! One sphere against many rays: the test of
//! [`crate::shapes::SphereKind`], lane by lane, with the same operations
//! in the same order.

use super::rays::{LANES, Lanes, RayLanes};
use super::{dot3, for_chunks, lane_mask, ld, ld3, of_f32, splat3, sub_scaled3, sub3};
use crate::shapes::Sphere;
use crate::simd::{Elem, Float, Job, Lanes as Simd, Mask};

/// The lanes of `m` whose rays meet the sphere at some `t` with
/// `t_min < t < limit`, with their nearest such `t` in `t_out`.
pub struct SphereLanes<'a, R> {
    pub s: &'a Sphere,
    pub rays: &'a RayLanes<R>,
    pub m: Lanes,
    pub limit: &'a [R; LANES],
    pub t_out: &'a mut [R; LANES],
}

impl<R: Elem> Job for SphereLanes<'_, R> {
    type Out = Lanes;

    #[inline(always)]
    fn run<L: Simd>(self) -> Lanes {
        let r = R::from_f32(self.s.radius);
        if !(r > R::ZERO) {
            return 0;
        }
        let mut hits = 0;
        for_chunks!(R::V<L>, self.m, |c, bits| {
            let h = chunk::<R, R::V<L>>(self.s, r, self.rays, c, bits, self.limit, self.t_out);
            hits |= (h & bits) << c;
        });
        hits
    }
}

#[inline(always)]
fn chunk<R: Elem, V: Float<Elem = R>>(
    s: &Sphere,
    r: R,
    rays: &RayLanes<R>,
    c: usize,
    bits: u64,
    limit: &[R; LANES],
    t_out: &mut [R; LANES],
) -> u64 {
    let oc = sub3(&ld3::<V>(&rays.o, c), &splat3(of_f32(s.center)));
    let d = ld3::<V>(&rays.d, c);
    let z = V::splat(R::ZERO);
    let b = dot3(&oc, &d);
    let r2 = V::splat(r * r);
    let cc = dot3(&oc, &oc) - r2;
    // Outside, and the sphere behind the ray.
    let behind = cc.gt(z).and(b.gt(z));
    let (a, inv_a): (V, V) = (ld(&rays.a, c), ld(&rays.inv_a, c));
    let f = sub_scaled3(&oc, &d, b * inv_a);
    let disc = a * (r2 - dot3(&f, &f));
    // Most tests end here, before the square root and the division:
    // every lane asked for misses the sphere or has it behind. (A lane
    // that hits passes both, so the hits are the same.)
    if disc.lt(z).or(behind).not().bits() & bits == 0 {
        return 0;
    }
    let sq = disc.sqrt();
    let q = V::select(b.ge(z), -(b + sq), sq - b);
    let q0 = q.eq(z);
    let t0 = V::select(q0, z, q * inv_a);
    let t1 = V::select(q0, z, cc / q);
    let swap = t0.gt(t1);
    let (t0, t1) = (V::select(swap, t1, t0), V::select(swap, t0, t1));
    let (lo, hi): (V, V) = (ld(&rays.t_min, c), ld(limit, c));
    let in0 = t0.gt(lo).and(t0.lt(hi));
    let in1 = t1.gt(lo).and(t1.lt(hi));
    V::select(in0, t0, t1).store(&mut t_out[c..c + V::N]);
    let ok = in0.or(in1).and_not(behind).and_not(disc.lt(z));
    ok.bits() & lane_mask::<V>()
}

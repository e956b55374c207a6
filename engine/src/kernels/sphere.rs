//! One sphere against many rays: the test of
//! [`crate::shapes::SphereKind`], lane by lane, with the same operations
//! in the same order.

use super::rays::{LANES, Lanes, RayLanes};
use super::{chunks, lane_mask};
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
        for (c, bits) in chunks::<R::V<L>>(self.m) {
            let h = chunk::<R, R::V<L>>(self.s, r, self.rays, c, self.limit, self.t_out);
            hits |= (h & bits) << c;
        }
        hits
    }
}

#[inline(always)]
fn chunk<R: Elem, V: Float<Elem = R>>(
    s: &Sphere,
    r: R,
    rays: &RayLanes<R>,
    c: usize,
    limit: &[R; LANES],
    t_out: &mut [R; LANES],
) -> u64 {
    let ld = |a: &[R; LANES]| V::load(&a[c..]);
    let oc = [0, 1, 2].map(|i| ld(&rays.o[i]) - V::splat(R::from_f32(s.center[i])));
    let d = [ld(&rays.d[0]), ld(&rays.d[1]), ld(&rays.d[2])];
    let dot = |p: &[V; 3], q: &[V; 3]| p[0] * q[0] + p[1] * q[1] + p[2] * q[2];
    let z = V::splat(R::ZERO);
    let b = dot(&oc, &d);
    let r2 = V::splat(r * r);
    let cc = dot(&oc, &oc) - r2;
    // Outside, and the sphere behind the ray.
    let behind = cc.gt(z).and(b.gt(z));
    let (a, inv_a) = (ld(&rays.a), ld(&rays.inv_a));
    let k = b * inv_a;
    let f = [oc[0] - d[0] * k, oc[1] - d[1] * k, oc[2] - d[2] * k];
    let disc = a * (r2 - dot(&f, &f));
    let sq = disc.sqrt();
    let q = V::select(b.ge(z), -(b + sq), sq - b);
    let q0 = q.eq(z);
    let t0 = V::select(q0, z, q * inv_a);
    let t1 = V::select(q0, z, cc / q);
    let swap = t0.gt(t1);
    let (t0, t1) = (V::select(swap, t1, t0), V::select(swap, t0, t1));
    let (lo, hi) = (ld(&rays.t_min), ld(limit));
    let in0 = t0.gt(lo).and(t0.lt(hi));
    let in1 = t1.gt(lo).and(t1.lt(hi));
    V::select(in0, t0, t1).store(&mut t_out[c..]);
    let ok = in0.or(in1).and_not(behind).and_not(disc.lt(z));
    ok.bits() & lane_mask::<V>()
}

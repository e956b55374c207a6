//! One cone (or cylinder) against many rays: the test of
//! [`crate::shapes::ConeKind`] (box pre-test, then the quadric in the
//! cone's frame), lane by lane, with the same operations in the same
//! order.

use super::boxes::may_hit_box;
use super::rays::{LANES, Lanes, RayLanes};
use super::{chunks, lane_mask};
use crate::scene::Aabb;
use crate::shapes::ConeFrame;
use crate::simd::{Elem, Float, Job, Lanes as Simd, Mask};

/// The lanes of `m` whose rays meet the cone (frame `frame`, box `bbox`)
/// at some `t` with `t_min < t < limit`, with their nearest such `t` in
/// `t_out`.
pub struct ConeLanes<'a, R> {
    pub frame: &'a ConeFrame<f64>,
    pub bbox: &'a Aabb,
    pub rays: &'a RayLanes<R>,
    pub m: Lanes,
    pub limit: &'a [R; LANES],
    pub t_out: &'a mut [R; LANES],
}

impl<R: Elem> Job for ConeLanes<'_, R> {
    type Out = Lanes;

    #[inline(always)]
    fn run<L: Simd>(self) -> Lanes {
        let mut out = 0;
        for (c, bits) in chunks::<R::V<L>>(self.m) {
            let mut h = may_hit_box::<R, R::V<L>>(self.bbox, self.rays, c, self.limit);
            if h & bits != 0 {
                h &= chunk::<R, R::V<L>>(self.frame, self.rays, c, self.limit, self.t_out);
            }
            out |= (h & bits) << c;
        }
        out
    }
}

#[inline(always)]
fn chunk<R: Elem, V: Float<Elem = R>>(
    f: &ConeFrame<f64>,
    rays: &RayLanes<R>,
    c: usize,
    limit: &[R; LANES],
    t_out: &mut [R; LANES],
) -> u64 {
    let ld = |a: &[R; LANES]| V::load(&a[c..]);
    let s = |x: f64| V::splat(R::from_f64(x));
    let (base, axis) = (f.base.to_array().map(s), f.axis.to_array().map(s));
    let (len, r0, k) = (s(f.len), s(f.r0), s(f.slope));
    let dot = |p: &[V; 3], q: &[V; 3]| p[0] * q[0] + p[1] * q[1] + p[2] * q[2];
    let o = [ld(&rays.o[0]), ld(&rays.o[1]), ld(&rays.o[2])];
    let d = [ld(&rays.d[0]), ld(&rays.d[1]), ld(&rays.d[2])];
    let w = [o[0] - base[0], o[1] - base[1], o[2] - base[2]];
    let wa = dot(&w, &axis);
    let da = dot(&d, &axis);
    let wp = [0, 1, 2].map(|i| w[i] - axis[i] * wa);
    let dp = [0, 1, 2].map(|i| d[i] - axis[i] * da);
    let rr = r0 + k * wa;
    let z = V::splat(R::ZERO);
    let a = dot(&dp, &dp) - k * k * da * da;
    let b = dot(&wp, &dp) - k * rr * da;
    let cc = dot(&wp, &wp) - rr * rr;
    // A linear equation where a = 0 (no root where b = 0 too).
    let flat = a.eq(z);
    let linear = -cc / (V::splat(R::TWO) * b);
    let disc = b * b - a * cc;
    let sq = disc.sqrt();
    let q = V::select(b.ge(z), -(b + sq), sq - b);
    let q0 = q.eq(z);
    let (r0q, r1q) = (
        V::select(q0, z, q / a),
        V::select(q0, V::splat(R::INFINITY), cc / q),
    );
    let swap = r0q.gt(r1q);
    let (qa, qb) = (V::select(swap, r1q, r0q), V::select(swap, r0q, r1q));
    let inf = V::splat(R::INFINITY);
    let root0 = V::select(flat, linear, qa);
    let root1 = V::select(flat, inf, qb);
    let none = flat.and(b.eq(z)).or(disc.lt(z).and_not(flat));
    let (lo, hi) = (ld(&rays.t_min), ld(limit));
    let on = |t: V| {
        let h = wa + t * da;
        t.gt(lo)
            .and(t.lt(hi))
            .and(h.ge(z))
            .and(h.le(len))
            .and((r0 + k * h).ge(z))
    };
    let (ok0, ok1) = (on(root0), on(root1));
    V::select(ok0, root0, root1).store(&mut t_out[c..]);
    ok0.or(ok1).and_not(none).bits() & lane_mask::<V>()
}

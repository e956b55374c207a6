//! One cone (or cylinder) against many rays: the test of
//! [`crate::shapes::ConeKind`] (box pre-test, then the quadric in the
//! cone's frame), lane by lane, with the same operations in the same
//! order.

use super::boxes::may_hit_box;
use super::rays::{LANES, Lanes, RayLanes};
use super::{dot3, for_chunks, lane_mask, ld, ld3, of_f64, splat3, sub_scaled3, sub3};
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
        for_chunks!(R::V<L>, self.m, |c, bits| {
            let mut h = may_hit_box::<R, R::V<L>>(self.bbox, self.rays, c, self.limit);
            if h & bits != 0 {
                h &=
                    chunk::<R, R::V<L>>(self.frame, self.rays, c, h & bits, self.limit, self.t_out);
            }
            out |= (h & bits) << c;
        });
        out
    }
}

#[inline(always)]
fn chunk<R: Elem, V: Float<Elem = R>>(
    f: &ConeFrame<f64>,
    rays: &RayLanes<R>,
    c: usize,
    bits: u64,
    limit: &[R; LANES],
    t_out: &mut [R; LANES],
) -> u64 {
    let base = splat3::<V>(of_f64(f.base.to_array()));
    let axis = splat3::<V>(of_f64(f.axis.to_array()));
    let (len, r0, k) = (
        V::splat(R::from_f64(f.len)),
        V::splat(R::from_f64(f.r0)),
        V::splat(R::from_f64(f.slope)),
    );
    let o = ld3::<V>(&rays.o, c);
    let d = ld3::<V>(&rays.d, c);
    let w = sub3(&o, &base);
    let wa = dot3(&w, &axis);
    let da = dot3(&d, &axis);
    let wp = sub_scaled3(&w, &axis, wa);
    let dp = sub_scaled3(&d, &axis, da);
    let rr = r0 + k * wa;
    let z = V::splat(R::ZERO);
    let a = dot3(&dp, &dp) - k * k * da * da;
    let b = dot3(&wp, &dp) - k * rr * da;
    let cc = dot3(&wp, &wp) - rr * rr;
    // A linear equation where a = 0 (no root where b = 0 too).
    let flat = a.eq(z);
    let disc = b * b - a * cc;
    let none = flat.and(b.eq(z)).or(disc.lt(z).and_not(flat));
    // Most tests that pass the box end here, before the square root and
    // the divisions: no lane asked for has a root. (The lanes with a root
    // are the same either way, so are the hits.)
    if none.not().bits() & bits == 0 {
        return 0;
    }
    let linear = -cc / (V::splat(R::TWO) * b);
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
    let (lo, hi): (V, V) = (ld(&rays.t_min, c), ld(limit, c));
    let (ok0, ok1) = (
        on_surface(root0, lo, hi, wa, da, len, r0, k),
        on_surface(root1, lo, hi, wa, da, len, r0, k),
    );
    V::select(ok0, root0, root1).store(&mut t_out[c..c + V::N]);
    ok0.or(ok1).and_not(none).bits() & lane_mask::<V>()
}

/// Whether a root `t` counts: in `(lo, hi)`, between the cone's ends, and
/// on its real sheet (a non-negative radius).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn on_surface<V: Float>(t: V, lo: V, hi: V, wa: V, da: V, len: V, r0: V, k: V) -> V::Mask {
    let z = V::splat(<V::Elem as crate::math::Real>::ZERO);
    let h = wa + t * da;
    t.gt(lo)
        .and(t.lt(hi))
        .and(h.ge(z))
        .and(h.le(len))
        .and((r0 + k * h).ge(z))
}

//! One polygon of four or more vertices against many rays: the test of
//! [`crate::shapes::PolygonKind`] (box pre-test for more than four
//! vertices, the plane, then the crossings test in the plane's
//! projection), lane by lane, with the same operations in the same order.
//!
//! [`PlaneLanes`] finds each lane's hit on the plane and the point's two
//! projected coordinates; [`Crossings`] counts the edges that straddle
//! them. A caller with few lanes left after the plane (or a polygon of
//! many vertices, whose edges the depth-first tracer bins) may count the
//! crossings lane by lane instead: the arithmetic per edge is the same.

use super::boxes::may_hit_box;
use super::rays::{LANES, Lanes, RayLanes};
use super::{dot3, for_chunks, lane_mask, ld, ld3, of_f32, of_f64, splat3, sub3};
use crate::scene::Aabb;
use crate::shapes::PolygonPlane;
use crate::simd::{Elem, Float, Job, Lanes as Simd, Mask};

/// Each lane's hit on the polygon's plane: the lanes of `m` whose plane
/// hit `t` lies in `(t_min, limit)` (and that pass the box pre-test of a
/// polygon of more than four vertices), with `t` and the hit point's
/// projected coordinates `pu`, `pv` written for them.
pub struct PlaneLanes<'a, R> {
    pub v: &'a [[f32; 3]],
    pub plane: &'a PolygonPlane,
    pub bbox: &'a Aabb,
    pub rays: &'a RayLanes<R>,
    pub m: Lanes,
    pub limit: &'a [R; LANES],
    pub t_out: &'a mut [R; LANES],
    pub pu: &'a mut [R; LANES],
    pub pv: &'a mut [R; LANES],
}

impl<R: Elem> Job for PlaneLanes<'_, R> {
    type Out = Lanes;

    #[inline(always)]
    fn run<L: Simd>(self) -> Lanes {
        let PlaneLanes {
            v,
            plane,
            bbox,
            rays,
            m,
            limit,
            t_out,
            pu,
            pv,
        } = self;
        let mut out = 0;
        for_chunks!(R::V<L>, m, |c, bits| {
            let mut h = plane_chunk::<R, R::V<L>>(v, plane, rays, c, limit, t_out, pu, pv);
            if v.len() > 4 {
                h &= may_hit_box::<R, R::V<L>>(bbox, rays, c, limit);
            }
            out |= (h & bits) << c;
        });
        out
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn plane_chunk<R: Elem, V: Float<Elem = R>>(
    v: &[[f32; 3]],
    pl: &PolygonPlane,
    rays: &RayLanes<R>,
    c: usize,
    limit: &[R; LANES],
    t_out: &mut [R; LANES],
    pu: &mut [R; LANES],
    pv: &mut [R; LANES],
) -> u64 {
    let n = splat3::<V>(of_f64(pl.n));
    let o = ld3::<V>(&rays.o, c);
    let d = ld3::<V>(&rays.d, c);
    let z = V::splat(R::ZERO);
    let denom = dot3(&n, &d);
    let w = sub3(&splat3(of_f32(v[0])), &o);
    let t = dot3(&n, &w) / denom;
    let ok = denom
        .eq(z)
        .not()
        .and(t.gt(ld(&rays.t_min, c)))
        .and(t.lt(ld(limit, c)));
    let (iu, iv) = (pl.iu as usize, pl.iv as usize);
    (o[iu] + d[iu] * t).store(&mut pu[c..c + V::N]);
    (o[iv] + d[iv] * t).store(&mut pv[c..c + V::N]);
    t.store(&mut t_out[c..c + V::N]);
    ok.bits() & lane_mask::<V>()
}

/// The lanes of `m` whose point (`pu`, `pv`) lies inside the polygon
/// `v` projected on the plane's axes: an odd number of straddling edges
/// pass to its right.
pub struct Crossings<'a, R> {
    pub v: &'a [[f32; 3]],
    pub plane: &'a PolygonPlane,
    pub m: Lanes,
    pub pu: &'a [R; LANES],
    pub pv: &'a [R; LANES],
}

impl<R: Elem> Job for Crossings<'_, R> {
    type Out = Lanes;

    #[inline(always)]
    fn run<L: Simd>(self) -> Lanes {
        let mut out = 0;
        for_chunks!(R::V<L>, self.m, |c, bits| {
            let h = crossings::<R, R::V<L>>(self.v, self.plane, c, self.pu, self.pv);
            out |= (h & bits) << c;
        });
        out
    }
}

#[inline(always)]
fn crossings<R: Elem, V: Float<Elem = R>>(
    v: &[[f32; 3]],
    pl: &PolygonPlane,
    c: usize,
    pu: &[R; LANES],
    pv: &[R; LANES],
) -> u64 {
    let (iu, iv) = (pl.iu as usize, pl.iv as usize);
    let (pu, pv) = (ld::<V>(pu, c), ld::<V>(pv, c));
    let mut inside = pu.lt(pu);
    let last = v[v.len() - 1];
    let (mut au, mut av) = (R::from_f32(last[iu]), R::from_f32(last[iv]));
    let mut a_above = V::splat(av).gt(pv);
    for b in v {
        let (bu, bv) = (R::from_f32(b[iu]), R::from_f32(b[iv]));
        let b_above = V::splat(bv).gt(pv);
        let straddles = a_above.and_not(b_above).or(b_above.and_not(a_above));
        if straddles.any() {
            let x = V::splat(au) + (pv - V::splat(av)) * V::splat(bu - au) / V::splat(bv - av);
            let flip = straddles.and(pu.lt(x));
            inside = inside.and_not(flip).or(flip.and_not(inside));
        }
        (au, av, a_above) = (bu, bv, b_above);
    }
    inside.bits() & lane_mask::<V>()
}

//! One triangle against many rays: the watertight test of
//! [`crate::intersect::triangle::intersect`], lane by lane, with the same
//! operations in the same order.

use super::rays::{LANES, Lanes, RayLanes};
use super::{for_chunks, lane_mask, ld, ld3, of_f32, splat3, sub3};
use crate::simd::{Elem, Float, Job, Lanes as Simd, Mask};

/// The lanes of `m` whose rays meet the triangle `v` at some `t` with
/// `t_min < t < limit` (each lane its own), with their `t` written to
/// `t_out` (other lanes of `t_out` are left as they were or overwritten
/// with meaningless values).
pub struct Triangle<'a, R> {
    pub v: &'a [[f32; 3]; 3],
    pub rays: &'a RayLanes<R>,
    pub m: Lanes,
    pub limit: &'a [R; LANES],
    pub t_out: &'a mut [R; LANES],
}

impl<R: Elem> Job for Triangle<'_, R> {
    type Out = Lanes;

    #[inline(always)]
    fn run<L: Simd>(self) -> Lanes {
        let mut hits = 0;
        let rays = self.rays;
        if rays.same_axes {
            // Every ray permutes the axes alike: the corners' coordinates
            // in the rays' axes, splat once for every vector of lanes.
            let k = rays.axes[0].map(|k| usize::from(k).min(2));
            let corners = [
                permuted::<R, R::V<L>>(&self.v[0], k),
                permuted::<R, R::V<L>>(&self.v[1], k),
                permuted::<R, R::V<L>>(&self.v[2], k),
            ];
            for_chunks!(R::V<L>, self.m, |c, bits| {
                let o = [
                    ld::<R::V<L>>(&rays.o[k[0]], c),
                    ld::<R::V<L>>(&rays.o[k[1]], c),
                    ld::<R::V<L>>(&rays.o[k[2]], c),
                ];
                let rel = [
                    sub3(&corners[0], &o),
                    sub3(&corners[1], &o),
                    sub3(&corners[2], &o),
                ];
                let h = finish::<R, R::V<L>>(&rel, rays, c, bits, self.limit, self.t_out);
                hits |= (h & bits) << c;
            });
        } else {
            for_chunks!(R::V<L>, self.m, |c, bits| {
                let rel = relative::<R, R::V<L>>(self.v, rays, c);
                let h = finish::<R, R::V<L>>(&rel, rays, c, bits, self.limit, self.t_out);
                hits |= (h & bits) << c;
            });
        }
        hits
    }
}

/// A corner's coordinates in the axes `k`, each in every lane.
#[inline(always)]
fn permuted<R: Elem, V: Float<Elem = R>>(p: &[f32; 3], k: [usize; 3]) -> [V; 3] {
    [
        V::splat(R::from_f32(p[k[0]])),
        V::splat(R::from_f32(p[k[1]])),
        V::splat(R::from_f32(p[k[2]])),
    ]
}

/// The corners relative to the origins of the lanes from `c`, in each
/// ray's own axes (picked lane by lane).
#[inline(always)]
fn relative<R: Elem, V: Float<Elem = R>>(
    v: &[[f32; 3]; 3],
    rays: &RayLanes<R>,
    c: usize,
) -> [[V; 3]; 3] {
    let o = ld3::<V>(&rays.o, c);
    let (zero, one) = (V::splat(R::ZERO), V::splat(R::ONE));
    let (kx, ky, kz) = (
        ld::<V>(&rays.kx, c),
        ld::<V>(&rays.ky, c),
        ld::<V>(&rays.kz, c),
    );
    let is0 = [kx.eq(zero), ky.eq(zero), kz.eq(zero)];
    let is1 = [kx.eq(one), ky.eq(one), kz.eq(one)];
    let mut out = [[zero; 3]; 3];
    for (p, corner) in out.iter_mut().zip(v) {
        let w = sub3(&splat3(of_f32(*corner)), &o);
        for j in 0..3 {
            p[j] = V::select(is0[j], w[0], V::select(is1[j], w[1], w[2]));
        }
    }
    out
}

/// The watertight test proper, for the lanes from `c` (of which `bits`
/// are asked for), given the corners relative to each origin in each
/// ray's axes: the mask of hits (relative to `c`).
#[inline(always)]
fn finish<R: Elem, V: Float<Elem = R>>(
    rel: &[[V; 3]; 3],
    rays: &RayLanes<R>,
    c: usize,
    bits: u64,
    limit: &[R; LANES],
    t_out: &mut [R; LANES],
) -> u64 {
    let shear = [
        ld::<V>(&rays.sx, c),
        ld::<V>(&rays.sy, c),
        ld::<V>(&rays.sz, c),
    ];
    let range = (ld::<V>(&rays.t_min, c), ld::<V>(limit, c));
    match watertight(rel, shear, range, bits) {
        Some((ok, t)) => {
            t.store(&mut t_out[c..c + V::N]);
            ok
        }
        None => 0,
    }
}

/// The watertight test's arithmetic (Woop, Benthin and Wald), shared by
/// the kernels of many rays and of many triangles: corners `rel` relative
/// to the ray's origin in its axes, its shear `sx, sy, sz`, and the open
/// interval `range` of distances that count. The lanes that hit and their
/// distances; `None` when no lane of `bits` is inside, before the
/// division (where most tests end).
#[inline(always)]
pub(super) fn watertight<R: Elem, V: Float<Elem = R>>(
    rel: &[[V; 3]; 3],
    [sx, sy, sz]: [V; 3],
    (t_min, limit): (V, V),
    bits: u64,
) -> Option<(u64, V)> {
    let [a, b, cc] = rel;
    let ax = a[0] - sx * a[2];
    let ay = a[1] - sy * a[2];
    let bx = b[0] - sx * b[2];
    let by = b[1] - sy * b[2];
    let cx = cc[0] - sx * cc[2];
    let cy = cc[1] - sy * cc[2];
    let u = cx * by - cy * bx;
    let vv = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    let z = V::splat(R::ZERO);
    let neg = u.lt(z).or(vv.lt(z)).or(w.lt(z));
    let pos = u.gt(z).or(vv.gt(z)).or(w.gt(z));
    let det = u + vv + w;
    // Inside (all edge functions of one sign) and not edge-on.
    let inside = neg.and(pos).not().and_not(det.eq(z));
    if inside.bits() & bits == 0 {
        return None;
    }
    let (az, bz, cz) = (sz * a[2], sz * b[2], sz * cc[2]);
    let t = (u * az + vv * bz + w * cz) / det;
    let ok = inside.and(t.gt(t_min)).and(t.lt(limit));
    Some((ok.bits() & lane_mask::<V>(), t))
}

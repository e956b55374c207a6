//! One triangle against many rays: the watertight test of
//! [`crate::intersect::triangle::intersect`], lane by lane, with the same
//! operations in the same order.

use super::rays::{LANES, Lanes, RayLanes};
use super::{for_chunks, lane_mask, ld};
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
        for_chunks!(R::V<L>, self.m, |c, bits| {
            let h = chunk::<R, R::V<L>>(self.v, self.rays, c, bits, self.limit, self.t_out);
            hits |= (h & bits) << c;
        });
        hits
    }
}

/// One vector of lanes from lane `c`, of which `bits` are asked for: the
/// mask of hits (relative to `c`).
#[inline(always)]
fn chunk<R: Elem, V: Float<Elem = R>>(
    v: &[[f32; 3]; 3],
    rays: &RayLanes<R>,
    c: usize,
    bits: u64,
    limit: &[R; LANES],
    t_out: &mut [R; LANES],
) -> u64 {
    // Each corner relative to the origin, in the ray's axes (x, y, z after
    // the permutation): read by index when every ray has the same axes,
    // else picked lane by lane. (Written out: a closure or `array::map`
    // here might not be inlined into the function compiled for the
    // instruction set, and its vector operations would become calls.)
    let (a, b, cc): ([V; 3], [V; 3], [V; 3]);
    if rays.same_axes {
        let [kx, ky, kz] = rays.axes[0];
        let (kx, ky, kz) = (kx as usize, ky as usize, kz as usize);
        let (ox, oy, oz) = (
            ld::<V>(&rays.o[kx], c),
            ld::<V>(&rays.o[ky], c),
            ld::<V>(&rays.o[kz], c),
        );
        let f = R::from_f32;
        a = [
            V::splat(f(v[0][kx])) - ox,
            V::splat(f(v[0][ky])) - oy,
            V::splat(f(v[0][kz])) - oz,
        ];
        b = [
            V::splat(f(v[1][kx])) - ox,
            V::splat(f(v[1][ky])) - oy,
            V::splat(f(v[1][kz])) - oz,
        ];
        cc = [
            V::splat(f(v[2][kx])) - ox,
            V::splat(f(v[2][ky])) - oy,
            V::splat(f(v[2][kz])) - oz,
        ];
    } else {
        let o = [
            ld::<V>(&rays.o[0], c),
            ld::<V>(&rays.o[1], c),
            ld::<V>(&rays.o[2], c),
        ];
        let (zero, one) = (V::splat(R::ZERO), V::splat(R::ONE));
        let (kx, ky, kz) = (
            ld::<V>(&rays.kx, c),
            ld::<V>(&rays.ky, c),
            ld::<V>(&rays.kz, c),
        );
        let is0 = [kx.eq(zero), ky.eq(zero), kz.eq(zero)];
        let is1 = [kx.eq(one), ky.eq(one), kz.eq(one)];
        let mut out = [[V::splat(R::ZERO); 3]; 3];
        for (p, corner) in out.iter_mut().zip(v) {
            let w = [
                V::splat(R::from_f32(corner[0])) - o[0],
                V::splat(R::from_f32(corner[1])) - o[1],
                V::splat(R::from_f32(corner[2])) - o[2],
            ];
            for j in 0..3 {
                p[j] = V::select(is0[j], w[0], V::select(is1[j], w[1], w[2]));
            }
        }
        [a, b, cc] = out;
    }
    let (sx, sy, sz) = (
        ld::<V>(&rays.sx, c),
        ld::<V>(&rays.sy, c),
        ld::<V>(&rays.sz, c),
    );
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
        return 0; // most tests end here, before the division
    }
    let (az, bz, cz) = (sz * a[2], sz * b[2], sz * cc[2]);
    let t = (u * az + vv * bz + w * cz) / det;
    let ok = inside
        .and(t.gt(ld::<V>(&rays.t_min, c)))
        .and(t.lt(ld::<V>(limit, c)));
    t.store(&mut t_out[c..c + V::N]);
    ok.bits() & lane_mask::<V>()
}

//! One triangle against many rays: the watertight test of
//! [`crate::intersect::triangle::intersect`], lane by lane, with the same
//! operations in the same order.

use super::rays::{LANES, Lanes, RayLanes};
use super::{chunks, lane_mask};
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
        for (c, bits) in chunks::<R::V<L>>(self.m) {
            let h = chunk::<R, R::V<L>>(self.v, self.rays, c, self.limit, self.t_out);
            hits |= (h & bits) << c;
        }
        hits
    }
}

/// One vector of lanes from lane `c`: the mask of hits (relative to `c`).
#[inline(always)]
fn chunk<R: Elem, V: Float<Elem = R>>(
    v: &[[f32; 3]; 3],
    rays: &RayLanes<R>,
    c: usize,
    limit: &[R; LANES],
    t_out: &mut [R; LANES],
) -> u64 {
    let o = [
        V::load(&rays.o[0][c..]),
        V::load(&rays.o[1][c..]),
        V::load(&rays.o[2][c..]),
    ];
    // Each corner relative to the origin, in the world's axes.
    let rel = |p: [f32; 3]| -> [V; 3] {
        [
            V::splat(R::from_f32(p[0])) - o[0],
            V::splat(R::from_f32(p[1])) - o[1],
            V::splat(R::from_f32(p[2])) - o[2],
        ]
    };
    let (a, b, cc) = (rel(v[0]), rel(v[1]), rel(v[2]));
    // The same coordinates in the ray's axes: picked by index when every
    // ray has the same axes, else lane by lane.
    let pick: [[V; 3]; 3] = if rays.same_axes {
        let [kx, ky, kz] = rays.axes[0].map(usize::from);
        [a, b, cc].map(|p| [p[kx], p[ky], p[kz]])
    } else {
        let (zero, one) = (V::splat(R::ZERO), V::splat(R::ONE));
        let k = [
            V::load(&rays.kx[c..]),
            V::load(&rays.ky[c..]),
            V::load(&rays.kz[c..]),
        ];
        let is0 = k.map(|k| k.eq(zero));
        let is1 = k.map(|k| k.eq(one));
        let sel = |p: &[V; 3], j: usize| V::select(is0[j], p[0], V::select(is1[j], p[1], p[2]));
        [a, b, cc].map(|p| [sel(&p, 0), sel(&p, 1), sel(&p, 2)])
    };
    let [a, b, cc] = pick;
    let (sx, sy, sz) = (
        V::load(&rays.sx[c..]),
        V::load(&rays.sy[c..]),
        V::load(&rays.sz[c..]),
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
    let (az, bz, cz) = (sz * a[2], sz * b[2], sz * cc[2]);
    let t = (u * az + vv * bz + w * cz) / det;
    let inside = neg.and(pos).not().and_not(det.eq(z));
    let ok = inside
        .and(t.gt(V::load(&rays.t_min[c..])))
        .and(t.lt(V::load(&limit[c..])));
    t.store(&mut t_out[c..]);
    ok.bits() & lane_mask::<V>()
}

//! One candidate object tested against the lanes of a group of rays, with
//! the kernels of [`crate::kernels`]: each lane's result is the scalar
//! test's of the object's kind, bit for bit.

use super::{Candidate, DfScene};
use crate::intersect::Ray;
pub use crate::kernels::Found;
use crate::kernels::{
    Crossings, LANES, Lanes, RayLanes, Triangle, each_lane, on_plane, shape_lanes,
};
use crate::render::KindCounts;
use crate::shapes::{Prepared, Shape};
use crate::simd::{Elem, Job, Lanes as Simd};

/// Whether a test looks for the nearest hit or for any hit at all.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Want {
    Nearest,
    Any,
}

/// The lanes of `m` whose rays meet candidate `c` (object `id`) at some
/// `t` with `t_min < t < limit` (each lane its own), with their `t` (and
/// for an instance, the model's triangle) in `out`. Counts one test of
/// the candidate's kind per lane of `m`, whatever the width of the
/// vectors, so that counts are the same on every machine.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn test<R: Elem, L: Simd>(
    s: &DfScene,
    c: Candidate,
    rays: &RayLanes<R>,
    m: Lanes,
    limit: &[R; LANES],
    want: Want,
    out: &mut Found<R>,
    tests: &mut KindCounts,
) -> Lanes {
    tests.add_n(c.kind(), m.count_ones() as u64);
    match c {
        Candidate::Face { v, .. } => Triangle {
            v: &v,
            rays,
            m,
            limit,
            t_out: &mut out.t,
        }
        .run::<L>(),
        Candidate::Instance(_, pl) => {
            let mut hits = 0;
            for i in each_lane(m) {
                let (q, hi) = (rays.ray(i), limit[i]);
                let ray = Ray {
                    q: &q,
                    o: rays.o(i),
                    d: rays.d(i),
                    t_min: rays.t_min[i],
                    t_max: hi,
                };
                match want {
                    Want::Nearest => {
                        if let Some((t, p)) = s.models.nearest(pl, ray, tests) {
                            out.t[i] = t;
                            out.prim[i] = p;
                            hits |= 1 << i;
                        }
                    }
                    Want::Any => {
                        if s.models.blocks(pl, ray, tests) {
                            out.t[i] = hi;
                            hits |= 1 << i;
                        }
                    }
                }
            }
            hits
        }
        Candidate::Record(h) => match (&h.shape, s.prep(h), s.bins(h)) {
            // A polygon whose edges are binned: few lanes left, or many
            // edges, take the binned crossings lane by lane.
            (Shape::Polygon(p), Some(Prepared::Polygon(plane)), Some(bins))
                if p.vertices.len() > 3 =>
            {
                let on = on_plane::<R, L>(p.vertices, plane, &h.bbox, rays, m, limit, out);
                if on.count_ones() <= 4 || p.vertices.len() > 32 {
                    let mut inside = 0;
                    for i in each_lane(on) {
                        if bins.inside(p.vertices, out.pu[i], out.pv[i]) {
                            inside |= 1 << i;
                        }
                    }
                    inside
                } else {
                    Crossings {
                        v: p.vertices,
                        plane,
                        m: on,
                        pu: &out.pu,
                        pv: &out.pv,
                    }
                    .run::<L>()
                }
            }
            (shape, prep, _) => {
                match shape_lanes::<R, L>(shape, prep, &h.bbox, rays, m, limit, out) {
                    Some(hits) => hits,
                    // A kind with no kernel: the scalar test, lane by
                    // lane.
                    None => {
                        let mut hits = 0;
                        for i in each_lane(m) {
                            if let Some(t) = c.intersect(s, &rays.ray(i), rays.t_min[i], limit[i]) {
                                out.t[i] = t;
                                hits |= 1 << i;
                            }
                        }
                        hits
                    }
                }
            }
        },
    }
}

//! One candidate object tested against the lanes of a group of rays, with
//! the kernels of [`crate::kernels`]: each lane's result is the scalar
//! test's of the object's kind, bit for bit.

use super::{Candidate, DfScene};
use crate::kernels::{
    ConeLanes, Crossings, LANES, Lanes, PlaneLanes, RayLanes, SphereLanes, Triangle, each_lane,
};
use crate::math::Real;
use crate::render::KindCounts;
use crate::shapes::{Prepared, Shape};
use crate::simd::{Elem, Job, Lanes as Simd};

/// What a test of one candidate leaves for its hit lanes: the distance
/// and, for a placed model, the model's triangle hit. Kept per thread so
/// that tests allocate nothing.
pub struct Found<R> {
    pub t: [R; LANES],
    /// A placed model's triangle per lane (only for instances).
    pub prim: [u32; LANES],
    pu: [R; LANES],
    pv: [R; LANES],
    limit: [R; LANES],
}

impl<R: Real> Found<R> {
    pub fn new() -> Box<Found<R>> {
        Box::new(Found {
            t: [R::ZERO; LANES],
            prim: [0; LANES],
            pu: [R::ZERO; LANES],
            pv: [R::ZERO; LANES],
            limit: [R::ZERO; LANES],
        })
    }
}

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
                let (q, lo, hi) = (rays.ray(i), rays.t_min[i], limit[i]);
                let (o, d) = (rays.o(i), rays.d(i));
                match want {
                    Want::Nearest => {
                        if let Some((t, p)) = s.models.nearest(pl, &q, o, d, lo, hi, tests) {
                            out.t[i] = t;
                            out.prim[i] = p;
                            hits |= 1 << i;
                        }
                    }
                    Want::Any => {
                        if s.models.blocks(pl, &q, o, d, lo, hi, tests) {
                            out.t[i] = hi;
                            hits |= 1 << i;
                        }
                    }
                }
            }
            hits
        }
        Candidate::Record(h) => match (&h.shape, s.prep(h)) {
            (Shape::Sphere(sp), _) => SphereLanes {
                s: sp,
                rays,
                m,
                limit,
                t_out: &mut out.t,
            }
            .run::<L>(),
            (Shape::Polygon(p), _) if p.vertices.len() == 3 => {
                let v = [p.vertices[0], p.vertices[1], p.vertices[2]];
                Triangle {
                    v: &v,
                    rays,
                    m,
                    limit,
                    t_out: &mut out.t,
                }
                .run::<L>()
            }
            (Shape::Polygon(p), Some(Prepared::Polygon(plane))) => {
                let on = PlaneLanes {
                    v: p.vertices,
                    plane,
                    bbox: &h.bbox,
                    rays,
                    m,
                    limit,
                    t_out: &mut out.t,
                    pu: &mut out.pu,
                    pv: &mut out.pv,
                }
                .run::<L>();
                match s.bins(h) {
                    // Few lanes left, or many edges: the binned crossings,
                    // lane by lane.
                    Some(bins) if on.count_ones() <= 4 || p.vertices.len() > 32 => {
                        let mut inside = 0;
                        for i in each_lane(on) {
                            if bins.inside(p.vertices, out.pu[i], out.pv[i]) {
                                inside |= 1 << i;
                            }
                        }
                        inside
                    }
                    _ => Crossings {
                        v: p.vertices,
                        plane,
                        m: on,
                        pu: &out.pu,
                        pv: &out.pv,
                    }
                    .run::<L>(),
                }
            }
            (Shape::Patch(p), _) => {
                // A fan of triangles about the first vertex, each lane's
                // nearest: as the patch kind's own loop.
                out.limit = *limit;
                let v = p.vertices;
                let mut hits = 0;
                for k in 1..v.len() - 1 {
                    let tri = [v[0], v[k], v[k + 1]];
                    let mut t = [R::ZERO; LANES];
                    let h = Triangle {
                        v: &tri,
                        rays,
                        m,
                        limit: &out.limit,
                        t_out: &mut t,
                    }
                    .run::<L>();
                    for i in each_lane(h) {
                        out.limit[i] = t[i];
                        out.t[i] = t[i];
                    }
                    hits |= h;
                }
                hits
            }
            (Shape::Cone(_), Some(Prepared::Cone(frame))) => ConeLanes {
                frame,
                bbox: &h.bbox,
                rays,
                m,
                limit,
                t_out: &mut out.t,
            }
            .run::<L>(),
            // A cone of no length, or a kind with no lanes of its own:
            // the scalar test, lane by lane.
            _ => {
                let mut hits = 0;
                for i in each_lane(m) {
                    if let Some(t) = c.intersect(s, &rays.ray(i), rays.t_min[i], limit[i]) {
                        out.t[i] = t;
                        hits |= 1 << i;
                    }
                }
                hits
            }
        },
    }
}

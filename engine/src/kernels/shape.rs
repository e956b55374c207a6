//! One object of any kind tested against the lanes of a group of rays:
//! the kernel of its kind, as both tracers use it (a depth-first packet's
//! candidate, a breadth-first voxel's object against the rays registered
//! there). Each lane's result is the scalar test's of the kind
//! ([`crate::shapes::Shape::intersect`]), bit for bit.

use super::{
    ConeLanes, Crossings, LANES, Lanes, PlaneLanes, RayLanes, SphereLanes, Triangle, each_lane,
};
use crate::math::Real;
use crate::scene::Aabb;
use crate::shapes::{PolygonPlane, Prepared, Shape};
use crate::simd::{Elem, Job, Lanes as Simd};

/// What a test of one object leaves for its hit lanes: the distance and,
/// for a placed model, the model's triangle hit; and the kernels' scratch.
/// Kept per thread so that tests allocate nothing.
pub struct Found<R> {
    pub t: [R; LANES],
    /// A placed model's triangle per lane (only for instances).
    pub prim: [u32; LANES],
    /// Where each lane meets a polygon's plane, in the plane's axes.
    pub(crate) pu: [R; LANES],
    pub(crate) pv: [R; LANES],
    /// Each lane's bound while a patch's triangles are tested.
    pub(crate) limit: [R; LANES],
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

/// The lanes of `m` whose rays meet `shape` (with its prepared data
/// `prep` and box `bbox`) at some `t` with `t_min < t < limit`, each lane
/// its own, with their `t` in `out.t`; `None` for a kind without a kernel
/// (textured objects, instances, cones of no length), which the caller
/// tests lane by lane with the scalar test.
///
/// Polygons go through [`PlaneLanes`] and then [`Crossings`]; a tracer
/// that bins a polygon's edges tests those itself first.
#[inline(always)]
pub fn shape_lanes<R: Elem, L: Simd>(
    shape: &Shape<'_>,
    prep: Option<&Prepared>,
    bbox: &Aabb,
    rays: &RayLanes<R>,
    m: Lanes,
    limit: &[R; LANES],
    out: &mut Found<R>,
) -> Option<Lanes> {
    Some(match (shape, prep) {
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
            let on = on_plane::<R, L>(p.vertices, plane, bbox, rays, m, limit, out);
            Crossings {
                v: p.vertices,
                plane,
                m: on,
                pu: &out.pu,
                pv: &out.pv,
            }
            .run::<L>()
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
            bbox,
            rays,
            m,
            limit,
            t_out: &mut out.t,
        }
        .run::<L>(),
        _ => return None,
    })
}

/// The lanes of `m` that meet the plane of polygon `v` inside its box
/// before `limit`, with their distances in `out.t` and where they meet it
/// in `out.pu`, `out.pv`: the first half of a polygon's test, whose
/// second asks whether that point is inside ([`Crossings`], or a
/// tracer's binned edges).
#[inline(always)]
pub(crate) fn on_plane<R: Elem, L: Simd>(
    v: &[[f32; 3]],
    plane: &PolygonPlane,
    bbox: &Aabb,
    rays: &RayLanes<R>,
    m: Lanes,
    limit: &[R; LANES],
    out: &mut Found<R>,
) -> Lanes {
    PlaneLanes {
        v,
        plane,
        bbox,
        rays,
        m,
        limit,
        t_out: &mut out.t,
        pu: &mut out.pu,
        pv: &mut out.pv,
    }
    .run::<L>()
}

/// [`shape_lanes`] as a job for [`crate::simd::Isa::run`].
pub struct ShapeLanes<'a, 's, R> {
    pub shape: &'a Shape<'s>,
    pub prep: Option<&'a Prepared>,
    pub bbox: &'a Aabb,
    pub rays: &'a RayLanes<R>,
    pub m: Lanes,
    pub limit: &'a [R; LANES],
    pub out: &'a mut Found<R>,
}

impl<R: Elem> Job for ShapeLanes<'_, '_, R> {
    type Out = Option<Lanes>;

    #[inline(always)]
    fn run<L: Simd>(self) -> Option<Lanes> {
        shape_lanes::<R, L>(
            self.shape, self.prep, self.bbox, self.rays, self.m, self.limit, self.out,
        )
    }
}

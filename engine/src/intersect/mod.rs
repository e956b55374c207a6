//! Ray/primitive intersection, one file per kind.
//!
//! Every routine reads the primitive's `f32` data as stored in the object
//! database and computes in the precision `R` of the ray. Both the
//! depth-first and the breadth-first tracer call exactly these functions on
//! exactly the same data, so they find exactly the same hits.
//!
//! Conventions: a hit counts when `t_min < t < t_max`; a degenerate
//! primitive (zero-area polygon, zero-length cone, zero-radius sphere) is
//! never hit; a ray lying in a polygon's plane does not hit it.

mod cone;
mod polygon;
mod ray;
mod sphere;
mod surface;
mod triangle;

pub use ray::RayQ;
pub use surface::{Surface, surface_at};

use crate::math::Real;
use crate::scene::{Aabb, Shape};

/// What an intersection test can compute once per object and reuse for
/// every ray: the plane of a many-sided polygon, the frame of a cone. One
/// function computes it, so a tracer that keeps it and one that recomputes
/// it per pass test alike, bit for bit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Prepared {
    /// Nothing worth keeping (spheres, triangles, patches).
    Plain,
    Polygon(polygon::PolygonPlane),
    Cone(cone::ConeFrame<f64>),
    /// A degenerate primitive (zero-length cone): never hit.
    Never,
}

pub use cone::ConeFrame;
pub use polygon::PolygonPlane;

/// The reusable part of `shape`'s intersection test.
pub fn prepare(shape: &Shape<'_>) -> Prepared {
    match *shape {
        Shape::Polygon { vertices } if vertices.len() > 3 => {
            Prepared::Polygon(polygon::plane(vertices))
        }
        Shape::Cone {
            base,
            base_radius,
            apex,
            apex_radius,
        } => match cone::frame::<f64>(base, base_radius, apex, apex_radius) {
            Some(f) => Prepared::Cone(f),
            None => Prepared::Never,
        },
        _ => Prepared::Plain,
    }
}

/// Nearest `t` in `(t_min, t_max)` at which `ray` meets `shape`, whose
/// bounding box is `bbox`.
#[inline]
pub fn intersect<R: Real>(
    shape: &Shape<'_>,
    bbox: &Aabb,
    ray: &RayQ<R>,
    t_min: R,
    t_max: R,
) -> Option<R> {
    intersect_prepared(shape, &prepare(shape), bbox, ray, t_min, t_max)
}

/// As [`intersect`], with `prep = prepare(shape)` computed beforehand.
/// Costly kinds (cones, many-sided polygons) are first culled against the
/// box.
#[inline(always)]
pub fn intersect_prepared<R: Real>(
    shape: &Shape<'_>,
    prep: &Prepared,
    bbox: &Aabb,
    ray: &RayQ<R>,
    t_min: R,
    t_max: R,
) -> Option<R> {
    match shape {
        Shape::Sphere { center, radius } => sphere::intersect(*center, *radius, ray, t_min, t_max),
        Shape::Polygon { vertices } => match prep {
            Prepared::Polygon(pl) => {
                if vertices.len() > 4 && !ray.may_hit_box(bbox, t_min, t_max) {
                    return None;
                }
                polygon::intersect(vertices, pl, ray, t_min, t_max)
            }
            _ => triangle::intersect(vertices[0], vertices[1], vertices[2], ray, t_min, t_max),
        },
        Shape::Patch { vertices, .. } => triangle::intersect_fan(vertices, ray, t_min, t_max),
        Shape::Cone { .. } => match prep {
            Prepared::Cone(f) => {
                if !ray.may_hit_box(bbox, t_min, t_max) {
                    return None;
                }
                cone::intersect(f, ray, t_min, t_max)
            }
            _ => None,
        },
    }
}

#[cfg(test)]
mod tests;

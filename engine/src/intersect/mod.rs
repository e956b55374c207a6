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
use crate::scene::Shape;

/// Nearest `t` in `(t_min, t_max)` at which `ray` meets `shape`.
#[inline]
pub fn intersect<R: Real>(shape: &Shape<'_>, ray: &RayQ<R>, t_min: R, t_max: R) -> Option<R> {
    match *shape {
        Shape::Sphere { center, radius } => sphere::intersect(center, radius, ray, t_min, t_max),
        Shape::Polygon { vertices } => {
            if vertices.len() == 3 {
                triangle::intersect(vertices[0], vertices[1], vertices[2], ray, t_min, t_max)
            } else {
                polygon::intersect(vertices, ray, t_min, t_max)
            }
        }
        Shape::Patch { vertices, .. } => triangle::intersect_fan(vertices, ray, t_min, t_max),
        Shape::Cone {
            base,
            base_radius,
            apex,
            apex_radius,
        } => cone::intersect(base, base_radius, apex, apex_radius, ray, t_min, t_max),
    }
}

#[cfg(test)]
mod tests;

use super::RayQ;
use crate::math::{Real, V3};

/// Nearest root in range of |o + t d - c|^2 = r^2.
///
/// The discriminant is formed from the part of `o - c` perpendicular to the
/// ray (Haines et al., "Precision Improvements for Ray/Sphere
/// Intersection", Ray Tracing Gems, 2019) so that a small sphere far away
/// keeps its precision, and the roots are taken without cancellation, so a
/// ray leaving the surface finds the other side and not itself.
#[inline(always)]
pub fn intersect<R: Real>(
    center: [f32; 3],
    radius: f32,
    ray: &RayQ<R>,
    t_min: R,
    t_max: R,
) -> Option<R> {
    let c = V3::<R>::from_f32(center);
    let r = R::from_f32(radius);
    if !(r > R::ZERO) {
        return None;
    }
    let oc = ray.o - c;
    let d = ray.d;
    let b = oc.dot(d); // half of the linear coefficient
    let r2 = r * r;
    let cc = oc.dot(oc) - r2;
    if cc > R::ZERO && b > R::ZERO {
        return None; // outside, and the sphere lies behind the ray
    }
    let f = oc - d * (b * ray.inv_a); // from the centre to the ray's closest point
    let disc = ray.a * (r2 - f.dot(f));
    if disc < R::ZERO {
        return None;
    }
    let sq = disc.sqrt();
    let q = if b >= R::ZERO { -(b + sq) } else { sq - b };
    let (mut t0, mut t1) = if q == R::ZERO {
        (R::ZERO, R::ZERO)
    } else {
        (q * ray.inv_a, cc / q)
    };
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    if t0 > t_min && t0 < t_max {
        Some(t0)
    } else if t1 > t_min && t1 < t_max {
        Some(t1)
    } else {
        None
    }
}

//! Spheres: centre and radius.

use super::{GeometryMap, Kind};
use crate::intersect::{Attrs, RayQ, Surface};
use crate::math::{Real, V3, Vec3, Vec3Ext};
use crate::math::Aabb;
use crate::math::{f32_down, f32_up};

/// A sphere. A zero radius is never hit; a negative one (NFF's
/// "inside-visible") is refused by validation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    pub center: [f32; 3],
    pub radius: f32,
}

pub struct SphereKind;

impl Kind for SphereKind {
    type Shape<'a> = Sphere;
    type Prep = ();
    const NAME: &'static str = "sphere";

    fn payload_words(count: u32) -> Option<usize> {
        (count == 0).then_some(4)
    }

    fn count(_: &Sphere) -> u32 {
        0
    }

    #[inline(always)]
    fn decode(g: &[f32], _: u32) -> Sphere {
        Sphere {
            center: [g[0], g[1], g[2]],
            radius: g[3],
        }
    }

    fn encode(s: &Sphere, out: &mut Vec<u32>) {
        super::push_points(out, &[s.center]);
        out.push(s.radius.to_bits());
    }

    fn validate(s: &Sphere) -> Result<(), String> {
        if !s.center.iter().all(|c| c.is_finite()) || !s.radius.is_finite() {
            return Err("sphere has a non-finite number".into());
        }
        if s.radius < 0.0 {
            return Err(format!(
                "sphere radius {} is negative (inside-visible spheres are not supported)",
                s.radius
            ));
        }
        Ok(())
    }

    fn bounds(s: &Sphere) -> Aabb {
        let r = s.radius as f64;
        let mut b = Aabb::EMPTY;
        for i in 0..3 {
            b.min[i] = f32_down(s.center[i] as f64 - r);
            b.max[i] = f32_up(s.center[i] as f64 + r);
        }
        b
    }

    fn prepare(_: &Sphere) -> Option<()> {
        None
    }

    /// Nearest root in range of |o + t d - c|^2 = r^2.
    ///
    /// The discriminant is formed from the part of `o - c` perpendicular to
    /// the ray (Haines et al., "Precision Improvements for Ray/Sphere
    /// Intersection", Ray Tracing Gems, 2019) so that a small sphere far
    /// away keeps its precision, and the roots are taken without
    /// cancellation, so a ray leaving the surface finds the other side and
    /// not itself.
    #[inline(always)]
    fn intersect<R: Real>(
        s: &Sphere,
        _: Option<&()>,
        _: &Aabb,
        ray: &RayQ<R>,
        t_min: R,
        t_max: R,
    ) -> Option<R> {
        let c = V3::<R>::from_f32(s.center);
        let r = R::from_f32(s.radius);
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

    /// The outward normal.
    fn surface(s: &Sphere, ray: &RayQ<f64>, t: f64) -> Surface {
        let p: Vec3 = ray.at(t).into();
        let ng = Surface::unit_or_facing(p - Vec3::from_f32(s.center), ray);
        Surface {
            p,
            ng,
            ns: ng,
            attrs: Attrs::NONE,
        }
    }

    fn map(s: &Sphere, m: &GeometryMap<'_>, out: &mut Vec<u32>) {
        let mapped = Sphere {
            center: (m.point)(s.center),
            radius: (m.length)(s.radius),
        };
        Self::encode(&mapped, out);
    }

    fn triangles(_: &Sphere) -> u64 {
        0
    }
}

//! Open cones and cylinders between two discs, without end caps.

use super::{GeometryMap, Kind, push_points};
use crate::intersect::{RayQ, Surface};
use crate::math::{Real, V3};
use crate::math::Aabb;
use crate::math::{f32_down, f32_up};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cone {
    pub base: [f32; 3],
    pub base_radius: f32,
    pub apex: [f32; 3],
    pub apex_radius: f32,
}

/// The frame of an open cone: base point, unit axis, length, base radius
/// and the radius's change per unit length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConeFrame<R> {
    pub base: V3<R>,
    pub axis: V3<R>,
    pub len: R,
    pub r0: R,
    pub slope: R,
}

pub struct ConeKind;

impl Kind for ConeKind {
    type Shape<'a> = Cone;
    /// The frame, in double precision.
    type Prep = ConeFrame<f64>;
    const NAME: &'static str = "cone";

    fn payload_words(count: u32) -> Option<usize> {
        (count == 0).then_some(8)
    }

    fn count(_: &Cone) -> u32 {
        0
    }

    #[inline(always)]
    fn decode(g: &[f32], _: u32) -> Cone {
        Cone {
            base: [g[0], g[1], g[2]],
            base_radius: g[3],
            apex: [g[4], g[5], g[6]],
            apex_radius: g[7],
        }
    }

    fn encode(s: &Cone, out: &mut Vec<u32>) {
        push_points(out, &[s.base]);
        out.push(s.base_radius.to_bits());
        push_points(out, &[s.apex]);
        out.push(s.apex_radius.to_bits());
    }

    fn validate(s: &Cone) -> Result<(), String> {
        let finite = |p: &[f32; 3]| p.iter().all(|c| c.is_finite());
        if !finite(&s.base)
            || !finite(&s.apex)
            || !s.base_radius.is_finite()
            || !s.apex_radius.is_finite()
        {
            return Err("cone has a non-finite number".into());
        }
        if s.base_radius < 0.0 || s.apex_radius < 0.0 {
            return Err("cone radius is negative (inside-visible cones are not supported)".into());
        }
        Ok(())
    }

    /// The union of the bounds of its two end discs.
    fn bounds(s: &Cone) -> Aabb {
        let b = s.base.map(|c| c as f64);
        let a = s.apex.map(|c| c as f64);
        let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let (br, ar) = (s.base_radius as f64, s.apex_radius as f64);
        let mut out = Aabb::EMPTY;
        for i in 0..3 {
            // A disc of radius r with unit normal n spans r*sqrt(1 - n_i^2)
            // along axis i. A zero-length cone gets the full radius on
            // every axis.
            let s = if len > 0.0 {
                let n = d[i] / len;
                (1.0 - n * n).max(0.0).sqrt()
            } else {
                1.0
            };
            let lo = (b[i] - br * s).min(a[i] - ar * s);
            let hi = (b[i] + br * s).max(a[i] + ar * s);
            out.min[i] = f32_down(lo);
            out.max[i] = f32_up(hi);
        }
        out
    }

    /// `None` for a zero-length cone, which has no surface.
    fn prepare(s: &Cone) -> Option<ConeFrame<f64>> {
        frame(s)
    }

    /// Points whose distance from the axis is r0 + slope * s at height s
    /// in [0, len]. The frame is computed once per cone, in double
    /// precision; costly, so the box is tried first.
    #[inline(always)]
    fn intersect<R: Real>(
        s: &Cone,
        prep: Option<&ConeFrame<f64>>,
        bbox: &Aabb,
        ray: &RayQ<R>,
        t_min: R,
        t_max: R,
    ) -> Option<R> {
        let computed;
        let f64frame = match prep {
            Some(f) => f,
            None => {
                computed = frame(s)?;
                &computed
            }
        };
        if !ray.may_hit_box(bbox, t_min, t_max) {
            return None;
        }
        intersect_frame(f64frame, ray, t_min, t_max)
    }

    fn surface(s: &Cone, ray: &RayQ<f64>, t: f64) -> Surface {
        let p = ray.at(t);
        let g: V3<f64> = match frame(s) {
            Some(f) => {
                let rel = p - f.base;
                let s = rel.dot(f.axis);
                let radial = rel - f.axis * s;
                // Gradient of |radial|^2 - (r0 + slope s)^2.
                radial - f.axis * ((f.r0 + f.slope * s) * f.slope)
            }
            None => V3::zero(),
        };
        let ng = Surface::unit_or_facing(g.into(), ray);
        Surface {
            p: p.into(),
            ng,
            ns: ng,
            attrs: crate::intersect::Attrs::NONE,
        }
    }

    fn map(s: &Cone, m: &GeometryMap<'_>, out: &mut Vec<u32>) {
        let mapped = Cone {
            base: (m.point)(s.base),
            base_radius: (m.length)(s.base_radius),
            apex: (m.point)(s.apex),
            apex_radius: (m.length)(s.apex_radius),
        };
        Self::encode(&mapped, out);
    }

    fn triangles(_: &Cone) -> u64 {
        0
    }
}

/// The cone's frame, or `None` for a zero-length cone.
#[inline]
pub fn frame(s: &Cone) -> Option<ConeFrame<f64>> {
    let b = V3::<f64>::from_f32(s.base);
    let along = V3::<f64>::from_f32(s.apex) - b;
    let len = along.length();
    if !(len > 0.0) {
        return None; // zero-length cone: no surface
    }
    let (r0, r1) = (s.base_radius as f64, s.apex_radius as f64);
    Some(ConeFrame {
        base: b,
        axis: along * (1.0 / len),
        len,
        r0,
        slope: (r1 - r0) / len,
    })
}

#[inline(always)]
fn intersect_frame<R: Real>(
    f64frame: &ConeFrame<f64>,
    ray: &RayQ<R>,
    t_min: R,
    t_max: R,
) -> Option<R> {
    let f = ConeFrame::<R> {
        base: f64frame.base.cast(),
        axis: f64frame.axis.cast(),
        len: R::from_f64(f64frame.len),
        r0: R::from_f64(f64frame.r0),
        slope: R::from_f64(f64frame.slope),
    };
    let w = ray.o - f.base;
    let wa = w.dot(f.axis);
    let da = ray.d.dot(f.axis);
    let wp = w - f.axis * wa;
    let dp = ray.d - f.axis * da;
    let rr = f.r0 + f.slope * wa;
    let k = f.slope;
    let a = dp.dot(dp) - k * k * da * da;
    let b = wp.dot(dp) - k * rr * da; // half of the linear coefficient
    let c = wp.dot(wp) - rr * rr;
    let mut roots = [R::INFINITY; 2];
    if a == R::ZERO {
        if b == R::ZERO {
            return None;
        }
        roots[0] = -c / (R::TWO * b);
    } else {
        let disc = b * b - a * c;
        if disc < R::ZERO {
            return None;
        }
        let sq = disc.sqrt();
        let q = if b >= R::ZERO { -(b + sq) } else { sq - b };
        if q == R::ZERO {
            roots[0] = R::ZERO;
        } else {
            roots = [q / a, c / q];
        }
        if roots[0] > roots[1] {
            roots.swap(0, 1);
        }
    }
    for t in roots {
        if t > t_min && t < t_max {
            let s = wa + t * da;
            if s >= R::ZERO && s <= f.len && f.r0 + k * s >= R::ZERO {
                return Some(t);
            }
        }
    }
    None
}

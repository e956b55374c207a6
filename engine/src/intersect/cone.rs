use super::RayQ;
use crate::math::{Real, V3};

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

#[inline]
pub fn frame<R: Real>(base: [f32; 3], r0: f32, apex: [f32; 3], r1: f32) -> Option<ConeFrame<R>> {
    let b = V3::<R>::from_f32(base);
    let along = V3::<R>::from_f32(apex) - b;
    let len = along.length();
    if !(len > R::ZERO) {
        return None; // zero-length cone: no surface
    }
    let (r0, r1) = (R::from_f32(r0), R::from_f32(r1));
    Some(ConeFrame {
        base: b,
        axis: along * (R::ONE / len),
        len,
        r0,
        slope: (r1 - r0) / len,
    })
}

/// Open cone or cylinder between two discs, no caps: points whose distance
/// from the axis is r0 + slope * s at height s in [0, len]. The frame is
/// computed once per cone, in double precision.
#[inline(always)]
pub fn intersect<R: Real>(
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

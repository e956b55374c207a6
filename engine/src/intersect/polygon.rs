use super::RayQ;
use crate::math::{Real, V3};

/// The plane normal of a polygon: from its first three vertices, as NFF
/// defines it; if those are collinear, Newell's normal of the whole outline
/// (so a polygon whose first corner happens to be straight still works).
/// Zero for a polygon of no area.
#[inline]
pub fn normal<R: Real>(v: &[[f32; 3]]) -> V3<R> {
    let p0 = V3::<R>::from_f32(v[0]);
    let n = (V3::<R>::from_f32(v[1]) - p0).cross(V3::<R>::from_f32(v[2]) - p0);
    if n != V3::zero() {
        return n;
    }
    let mut m = V3::<R>::zero();
    for i in 0..v.len() {
        let a = V3::<R>::from_f32(v[i]);
        let b = V3::<R>::from_f32(v[(i + 1) % v.len()]);
        m.x += (a.y - b.y) * (a.z + b.z);
        m.y += (a.z - b.z) * (a.x + b.x);
        m.z += (a.x - b.x) * (a.y + b.y);
    }
    m
}

/// What a polygon test needs beyond the vertices: the plane normal and
/// the two axes of the projection that drops the normal's largest one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PolygonPlane {
    pub n: [f64; 3],
    pub iu: u8,
    pub iv: u8,
}

pub fn plane(v: &[[f32; 3]]) -> PolygonPlane {
    let n = normal::<f64>(v);
    let (iu, iv) = match n.max_axis() {
        0 => (1, 2),
        1 => (2, 0),
        _ => (0, 1),
    };
    PolygonPlane {
        n: n.to_array(),
        iu,
        iv,
    }
}

/// Planar polygon, convex or not: the plane hit, then the crossings test
/// (Haines, Graphics Gems IV) in the projection that drops the normal's
/// largest axis. Edges count half-open in the projected v direction, so a
/// point on a vertex is decided consistently.
#[inline(always)]
pub fn intersect<R: Real>(
    v: &[[f32; 3]],
    pl: &PolygonPlane,
    ray: &RayQ<R>,
    t_min: R,
    t_max: R,
) -> Option<R> {
    let n = V3::<R>::from_f64(pl.n);
    let denom = n.dot(ray.d);
    if denom == R::ZERO {
        return None; // parallel to the plane (or no area)
    }
    let p0 = V3::<R>::from_f32(v[0]);
    let t = n.dot(p0 - ray.o) / denom;
    if !(t > t_min && t < t_max) {
        return None;
    }
    let p = ray.at(t);
    let (iu, iv) = (pl.iu as usize, pl.iv as usize);
    let (pu, pv) = (p[iu], p[iv]);
    let mut inside = false;
    let last = v[v.len() - 1];
    let (mut au, mut av) = (R::from_f32(last[iu]), R::from_f32(last[iv]));
    for b in v {
        let (bu, bv) = (R::from_f32(b[iu]), R::from_f32(b[iv]));
        if (av > pv) != (bv > pv) {
            let x = au + (pv - av) * (bu - au) / (bv - av);
            if pu < x {
                inside = !inside;
            }
        }
        au = bu;
        av = bv;
    }
    inside.then_some(t)
}

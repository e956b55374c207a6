//! Planar polygons of 3 or more vertices, convex or not. The plane comes
//! from the first three vertices, as NFF defines it.

use super::{GeometryMap, Kind, check_vertex_count, push_points};
use crate::intersect::{Attrs, RayQ, Surface, triangle};
use crate::math::{Real, V3};
use crate::math::Aabb;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Polygon<'a> {
    pub vertices: &'a [[f32; 3]],
}

/// What a test of a polygon of more than three vertices keeps: the plane
/// normal and the two axes of the projection that drops the normal's
/// largest one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PolygonPlane {
    pub n: [f64; 3],
    pub iu: u8,
    pub iv: u8,
}

pub struct PolygonKind;

impl Kind for PolygonKind {
    type Shape<'a> = Polygon<'a>;
    type Prep = PolygonPlane;
    const NAME: &'static str = "polygon";

    fn payload_words(count: u32) -> Option<usize> {
        (3..=super::MAX_POLYGON_VERTICES)
            .contains(&(count as usize))
            .then_some(3 * count as usize)
    }

    fn count(s: &Polygon<'_>) -> u32 {
        s.vertices.len() as u32
    }

    #[inline(always)]
    fn decode(g: &[f32], count: u32) -> Polygon<'_> {
        Polygon {
            vertices: bytemuck::cast_slice(&g[..3 * count as usize]),
        }
    }

    fn encode(s: &Polygon<'_>, out: &mut Vec<u32>) {
        push_points(out, s.vertices);
    }

    fn validate(s: &Polygon<'_>) -> Result<(), String> {
        check_vertex_count(s.vertices.len(), "polygon")?;
        if !s.vertices.iter().flatten().all(|c| c.is_finite()) {
            return Err("polygon has a non-finite coordinate".into());
        }
        Ok(())
    }

    fn bounds(s: &Polygon<'_>) -> Aabb {
        let mut b = Aabb::EMPTY;
        for v in s.vertices {
            b.add_point(*v);
        }
        b
    }

    /// Triangles need nothing kept: the watertight test is as cheap as
    /// reading a plane.
    fn prepare(s: &Polygon<'_>) -> Option<PolygonPlane> {
        (s.vertices.len() > 3).then(|| plane(s.vertices))
    }

    #[inline(always)]
    fn intersect<R: Real>(
        s: &Polygon<'_>,
        prep: Option<&PolygonPlane>,
        bbox: &Aabb,
        ray: &RayQ<R>,
        t_min: R,
        t_max: R,
    ) -> Option<R> {
        let v = s.vertices;
        if v.len() == 3 {
            return triangle::intersect(v[0], v[1], v[2], ray, t_min, t_max);
        }
        // Many-sided polygons (the gears' faces) are first culled against
        // their box.
        if v.len() > 4 && !ray.may_hit_box(bbox, t_min, t_max) {
            return None;
        }
        match prep {
            Some(pl) => crossings(v, pl, ray, t_min, t_max),
            None => crossings(v, &plane(v), ray, t_min, t_max),
        }
    }

    fn surface(s: &Polygon<'_>, ray: &RayQ<f64>, t: f64) -> Surface {
        let p = ray.at(t).into();
        let ng = Surface::unit_or_facing(normal::<f64>(s.vertices).into(), ray);
        Surface {
            p,
            ng,
            ns: ng,
            attrs: Attrs::NONE,
        }
    }

    fn map(s: &Polygon<'_>, m: &GeometryMap<'_>, out: &mut Vec<u32>) {
        let v: Vec<[f32; 3]> = s.vertices.iter().map(|&p| (m.point)(p)).collect();
        push_points(out, &v);
    }

    fn triangles(s: &Polygon<'_>) -> u64 {
        s.vertices.len().saturating_sub(2) as u64
    }
}

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
fn crossings<R: Real>(
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

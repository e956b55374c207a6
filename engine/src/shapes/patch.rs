//! Polygonal patches: polygons with a normal per vertex, intersected as a
//! fan of triangles about the first vertex and shaded with interpolated
//! normals (the SPD writes only triangles; larger patches work the same).

use super::{GeometryMap, Kind, check_vertex_count, push_points};
use crate::intersect::{RayQ, Surface, triangle};
use crate::math::{Real, Vec3, Vec3Ext};
use crate::math::Aabb;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Patch<'a> {
    pub vertices: &'a [[f32; 3]],
    pub normals: &'a [[f32; 3]],
}

pub struct PatchKind;

impl Kind for PatchKind {
    type Shape<'a> = Patch<'a>;
    type Prep = ();
    const NAME: &'static str = "patch";

    fn payload_words(count: u32) -> Option<usize> {
        (3..=super::MAX_POLYGON_VERTICES)
            .contains(&(count as usize))
            .then_some(6 * count as usize)
    }

    fn count(s: &Patch<'_>) -> u32 {
        s.vertices.len() as u32
    }

    #[inline(always)]
    fn decode(g: &[f32], count: u32) -> Patch<'_> {
        let n = 3 * count as usize;
        Patch {
            vertices: bytemuck::cast_slice(&g[..n]),
            normals: bytemuck::cast_slice(&g[n..2 * n]),
        }
    }

    fn encode(s: &Patch<'_>, out: &mut Vec<u32>) {
        push_points(out, s.vertices);
        push_points(out, s.normals);
    }

    fn validate(s: &Patch<'_>) -> Result<(), String> {
        check_vertex_count(s.vertices.len(), "patch")?;
        if s.normals.len() != s.vertices.len() {
            return Err("patch has a different number of normals and vertices".into());
        }
        let finite = |v: &[[f32; 3]]| v.iter().flatten().all(|c| c.is_finite());
        if !finite(s.vertices) || !finite(s.normals) {
            return Err("patch has a non-finite coordinate".into());
        }
        Ok(())
    }

    fn bounds(s: &Patch<'_>) -> Aabb {
        let mut b = Aabb::EMPTY;
        for v in s.vertices {
            b.add_point(*v);
        }
        b
    }

    fn prepare(_: &Patch<'_>) -> Option<()> {
        None
    }

    #[inline(always)]
    fn intersect<R: Real>(
        s: &Patch<'_>,
        _: Option<&()>,
        _: &Aabb,
        ray: &RayQ<R>,
        t_min: R,
        mut t_max: R,
    ) -> Option<R> {
        let v = s.vertices;
        let mut best = None;
        for i in 1..v.len() - 1 {
            if let Some(t) = triangle::intersect(v[0], v[i], v[i + 1], ray, t_min, t_max) {
                t_max = t;
                best = Some(t);
            }
        }
        best
    }

    /// The geometric normal of the fan triangle that holds the point (the
    /// one whose smallest barycentric weight is largest), and the vertex
    /// normals interpolated there.
    fn surface(s: &Patch<'_>, ray: &RayQ<f64>, t: f64) -> Surface {
        let p = ray.at(t).into();
        let (vertices, normals) = (s.vertices, s.normals);
        let mut best = (f64::NEG_INFINITY, 1, [1.0 / 3.0; 3]);
        for i in 1..vertices.len() - 1 {
            let w = triangle::weights(vertices[0], vertices[i], vertices[i + 1], ray);
            let m = w[0].min(w[1]).min(w[2]);
            if m > best.0 {
                best = (m, i, w);
            }
        }
        let (_, i, w) = best;
        let ng = Surface::unit_or_facing(
            super::polygon::normal::<f64>(&[vertices[0], vertices[i], vertices[i + 1]]).into(),
            ray,
        );
        let ns = Vec3::from_f32(normals[0]) * w[0]
            + Vec3::from_f32(normals[i]) * w[1]
            + Vec3::from_f32(normals[i + 1]) * w[2];
        Surface {
            p,
            ng,
            ns: ns.try_normalize().unwrap_or(ng),
            attrs: crate::intersect::Attrs::NONE,
        }
    }

    fn map(s: &Patch<'_>, m: &GeometryMap<'_>, out: &mut Vec<u32>) {
        let v: Vec<[f32; 3]> = s.vertices.iter().map(|&p| (m.point)(p)).collect();
        let n: Vec<[f32; 3]> = s.normals.iter().map(|&p| (m.normal)(p)).collect();
        push_points(out, &v);
        push_points(out, &n);
    }

    fn triangles(s: &Patch<'_>) -> u64 {
        s.vertices.len().saturating_sub(2) as u64
    }
}

//! Triangles that carry attributes at their corners: texture coordinates,
//! colours and (optionally) normals, as glTF's `TEXCOORD_n` and `COLOR_0`,
//! OBJ's `vt` and PLY's `u v` give them.
//!
//! A mesh without such attributes is stored as polygons and patches, as
//! before, and costs nothing more; only a face with attributes becomes a
//! textured triangle. Intersection is the triangles' watertight test on
//! the three corners (the same function as a polygon of three vertices,
//! so a triangle hits the same rays textured or not); the surface
//! interpolates the attributes with the barycentric weights of the hit.
//!
//! The record's count field says which attributes follow the corners
//! ([`NORMALS`], [`UVS`], [`COLORS`]; at least one): normals as three
//! `f32` per corner, texture coordinates as two, colours as linear RGBA
//! quantised to 16 bits a channel, two words per corner (red and green in
//! the first, low half first; blue and alpha in the second).

use super::{GeometryMap, Kind, push_points};
use crate::intersect::{Attrs, RayQ, Surface, triangle};
use crate::math::Aabb;
use crate::math::{Real, Vec3, Vec3Ext};

/// Count-field bit: a normal per corner follows the corners.
pub const NORMALS: u32 = 1;
/// Count-field bit: texture coordinates per corner follow.
pub const UVS: u32 = 2;
/// Count-field bit: a colour per corner follows.
pub const COLORS: u32 = 4;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Textured<'a> {
    pub vertices: &'a [[f32; 3]],
    /// Three, or none.
    pub normals: &'a [[f32; 3]],
    /// Three, or none.
    pub uvs: &'a [[f32; 2]],
    /// Three packed colours ([`pack_color`]), or none.
    pub colors: &'a [[u32; 2]],
}

/// A linear RGBA colour in [0, 1] (clamped) as stored: 16 bits a channel.
pub fn pack_color(c: [f32; 4]) -> [u32; 2] {
    let q = |x: f32| (x.clamp(0.0, 1.0) * 65535.0).round() as u32;
    [q(c[0]) | q(c[1]) << 16, q(c[2]) | q(c[3]) << 16]
}

/// A stored colour as linear RGBA.
pub fn unpack_color(w: [u32; 2]) -> [f32; 4] {
    let f = |x: u32| (x & 0xffff) as f32 / 65535.0;
    [f(w[0]), f(w[0] >> 16), f(w[1]), f(w[1] >> 16)]
}

impl Textured<'_> {
    /// The count field for what this triangle carries.
    fn mask(&self) -> u32 {
        let bit = |has: bool, b: u32| if has { b } else { 0 };
        bit(!self.normals.is_empty(), NORMALS)
            | bit(!self.uvs.is_empty(), UVS)
            | bit(!self.colors.is_empty(), COLORS)
    }
}

pub struct TexturedKind;

impl Kind for TexturedKind {
    type Shape<'a> = Textured<'a>;
    type Prep = ();
    const NAME: &'static str = "textured";

    fn payload_words(count: u32) -> Option<usize> {
        (1..8).contains(&count).then(|| {
            9 + 9 * (count & NORMALS != 0) as usize
                + 6 * (count & UVS != 0) as usize
                + 6 * (count & COLORS != 0) as usize
        })
    }

    fn count(s: &Textured<'_>) -> u32 {
        s.mask()
    }

    #[inline(always)]
    fn decode(g: &[f32], count: u32) -> Textured<'_> {
        let (vertices, rest) = g.split_at(9);
        let (normals, rest) = rest.split_at(if count & NORMALS != 0 { 9 } else { 0 });
        let (uvs, rest) = rest.split_at(if count & UVS != 0 { 6 } else { 0 });
        let colors: &[u32] = bytemuck::cast_slice(&rest[..if count & COLORS != 0 { 6 } else { 0 }]);
        Textured {
            vertices: bytemuck::cast_slice(vertices),
            normals: bytemuck::cast_slice(normals),
            uvs: bytemuck::cast_slice(uvs),
            colors: bytemuck::cast_slice(colors),
        }
    }

    fn encode(s: &Textured<'_>, out: &mut Vec<u32>) {
        push_points(out, s.vertices);
        push_points(out, s.normals);
        out.extend(s.uvs.iter().flatten().map(|f| f.to_bits()));
        out.extend(s.colors.iter().flatten());
    }

    fn validate(s: &Textured<'_>) -> Result<(), String> {
        let three = |n: usize| n == 0 || n == 3;
        if s.vertices.len() != 3
            || !three(s.normals.len())
            || !three(s.uvs.len())
            || !three(s.colors.len())
        {
            return Err("textured triangle has other than 3 corners".into());
        }
        if s.mask() == 0 {
            return Err("textured triangle carries no attribute".into());
        }
        let finite = s.vertices.iter().flatten().all(|c| c.is_finite())
            && s.normals.iter().flatten().all(|c| c.is_finite())
            && s.uvs.iter().flatten().all(|c| c.is_finite());
        if !finite {
            return Err("textured triangle has a non-finite number".into());
        }
        Ok(())
    }

    fn bounds(s: &Textured<'_>) -> Aabb {
        let mut b = Aabb::EMPTY;
        for v in s.vertices {
            b.add_point(*v);
        }
        b
    }

    fn prepare(_: &Textured<'_>) -> Option<()> {
        None
    }

    #[inline(always)]
    fn intersect<R: Real>(
        s: &Textured<'_>,
        _: Option<&()>,
        _: &Aabb,
        ray: &RayQ<R>,
        t_min: R,
        t_max: R,
    ) -> Option<R> {
        let v = s.vertices;
        triangle::intersect(v[0], v[1], v[2], ray, t_min, t_max)
    }

    /// The geometric normal (by the vertex order, as a polygon's), the
    /// corner normals interpolated (or the geometric one), and the
    /// attributes interpolated.
    fn surface(s: &Textured<'_>, ray: &RayQ<f64>, t: f64) -> Surface {
        let p = ray.at(t).into();
        let v = s.vertices;
        let w = triangle::weights(v[0], v[1], v[2], ray);
        let ng = Surface::unit_or_facing(super::polygon::normal::<f64>(v).into(), ray);
        let ns = match s.normals {
            [a, b, c] => (Vec3::from_f32(*a) * w[0]
                + Vec3::from_f32(*b) * w[1]
                + Vec3::from_f32(*c) * w[2])
                .try_normalize()
                .unwrap_or(ng),
            _ => ng,
        };
        let mix = |a: f32, b: f32, c: f32| (a as f64 * w[0] + b as f64 * w[1] + c as f64 * w[2]) as f32;
        let (uv, uv_per_length, tangent) = match s.uvs {
            [a, b, c] => {
                let (du1, dv1) = (b[0] as f64 - a[0] as f64, b[1] as f64 - a[1] as f64);
                let (du2, dv2) = (c[0] as f64 - a[0] as f64, c[1] as f64 - a[1] as f64);
                let det = du1 * dv2 - du2 * dv1;
                let (p0, p1, p2) = (
                    Vec3::from_f32(v[0]),
                    Vec3::from_f32(v[1]),
                    Vec3::from_f32(v[2]),
                );
                let (e1, e2) = (p1 - p0, p2 - p0);
                let area = e1.cross(e2).length();
                let ratio = if area > 0.0 {
                    (det.abs() / area).sqrt()
                } else {
                    0.0
                };
                // dp/du from the edges and their texture coordinates.
                let tangent = if det != 0.0 {
                    ((e1 * dv2 - e2 * dv1) * (1.0 / det)).to_array().map(|x| x as f32)
                } else {
                    [0.0; 3]
                };
                (
                    Some([mix(a[0], b[0], c[0]), mix(a[1], b[1], c[1])]),
                    ratio as f32,
                    tangent,
                )
            }
            _ => (None, 0.0, [0.0; 3]),
        };
        let color = match s.colors {
            [a, b, c] => {
                let (a, b, c) = (unpack_color(*a), unpack_color(*b), unpack_color(*c));
                Some(std::array::from_fn(|k| mix(a[k], b[k], c[k])))
            }
            _ => None,
        };
        Surface {
            p,
            ng,
            ns,
            attrs: Attrs {
                uv,
                color,
                uv_per_length,
                tangent,
            },
        }
    }

    fn map(s: &Textured<'_>, m: &GeometryMap<'_>, out: &mut Vec<u32>) {
        let v: Vec<[f32; 3]> = s.vertices.iter().map(|&p| (m.point)(p)).collect();
        let n: Vec<[f32; 3]> = s.normals.iter().map(|&p| (m.normal)(p)).collect();
        push_points(out, &v);
        push_points(out, &n);
        out.extend(s.uvs.iter().flatten().map(|f| f.to_bits()));
        out.extend(s.colors.iter().flatten());
    }

    fn triangles(_: &Textured<'_>) -> u64 {
        1
    }
}

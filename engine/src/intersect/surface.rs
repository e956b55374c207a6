use super::RayQ;
use crate::math::Vec3;

/// What shading needs at a hit: the point, the geometric normal (outward
/// for spheres and cones; by the vertex order for polygons and patches) and
/// the shading normal (interpolated for patches), both unit length. Neither
/// is turned toward the ray here. `attrs` holds what a triangle carries
/// at its corners, interpolated at the point (none for every other kind).
#[derive(Clone, Copy, Debug)]
pub struct Surface {
    pub p: Vec3,
    pub ng: Vec3,
    pub ns: Vec3,
    pub attrs: Attrs,
}

/// Attributes interpolated at a hit from a triangle's corners: texture
/// coordinates and a linear RGBA colour (glTF's `TEXCOORD_n`, `COLOR_0`;
/// OBJ's `vt`; PLY's `u v`), when the triangle has them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Attrs {
    pub uv: Option<[f32; 2]>,
    pub color: Option<[f32; 4]>,
    /// How fast the texture coordinates change across the surface: the
    /// square root of the triangle's area in texture coordinates over its
    /// area in space (zero without coordinates). Shading turns it into a
    /// footprint in texels to pick a mip level.
    pub uv_per_length: f32,
    /// How the point moves as `u` grows (dp/du, not unit length; zero
    /// without texture coordinates): with the normal, the tangent frame a
    /// normal map is read in.
    pub tangent: [f32; 3],
}

impl Attrs {
    pub const NONE: Attrs = Attrs {
        uv: None,
        color: None,
        uv_per_length: 0.0,
        tangent: [0.0; 3],
    };
}

impl Surface {
    /// `v` made unit length; where it has none (a degenerate primitive),
    /// the direction back toward the ray's origin, so shading still has a
    /// normal.
    #[inline]
    pub fn unit_or_facing(v: Vec3, ray: &RayQ<f64>) -> Vec3 {
        v.try_normalize().unwrap_or_else(|| {
            -Vec3::from(ray.d)
                .try_normalize()
                .unwrap_or(Vec3::new(0.0, 0.0, 1.0))
        })
    }
}

use super::RayQ;
use crate::math::Vec3;

/// What shading needs at a hit: the point, the geometric normal (outward
/// for spheres and cones; by the vertex order for polygons and patches) and
/// the shading normal (interpolated for patches), both unit length. Neither
/// is turned toward the ray here.
#[derive(Clone, Copy, Debug)]
pub struct Surface {
    pub p: Vec3,
    pub ng: Vec3,
    pub ns: Vec3,
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

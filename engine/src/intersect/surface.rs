use super::RayQ;
use super::cone::frame;
use super::polygon::normal;
use super::triangle::weights;
use crate::math::Vec3;
use crate::scene::Shape;

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

/// The surface of `shape` where `ray` meets it at `t`. Always `f64`, so
/// that shading is the same whatever precision found the hit.
pub fn surface_at(shape: &Shape<'_>, ray: &RayQ<f64>, t: f64) -> Surface {
    let p = ray.at(t);
    let fallback = -ray.d.try_normalize().unwrap_or(Vec3::new(0.0, 0.0, 1.0));
    let unit = |v: Vec3| v.try_normalize().unwrap_or(fallback);
    let ng = match *shape {
        Shape::Sphere { center, .. } => unit(p - Vec3::from_f32(center)),
        Shape::Polygon { vertices } => unit(normal::<f64>(vertices)),
        Shape::Patch { vertices, normals } => {
            // The fan triangle that holds the point: the one whose smallest
            // barycentric weight is largest.
            let mut best = (f64::NEG_INFINITY, 1, [1.0 / 3.0; 3]);
            for i in 1..vertices.len() - 1 {
                let w = weights(vertices[0], vertices[i], vertices[i + 1], ray);
                let m = w[0].min(w[1]).min(w[2]);
                if m > best.0 {
                    best = (m, i, w);
                }
            }
            let (_, i, w) = best;
            let ng = unit(normal::<f64>(&[vertices[0], vertices[i], vertices[i + 1]]));
            let ns = Vec3::from_f32(normals[0]) * w[0]
                + Vec3::from_f32(normals[i]) * w[1]
                + Vec3::from_f32(normals[i + 1]) * w[2];
            return Surface {
                p,
                ng,
                ns: ns.try_normalize().unwrap_or(ng),
            };
        }
        Shape::Cone {
            base,
            base_radius,
            apex,
            apex_radius,
        } => match frame::<f64>(base, base_radius, apex, apex_radius) {
            Some(f) => {
                let rel = p - f.base;
                let s = rel.dot(f.axis);
                let radial = rel - f.axis * s;
                // Gradient of |radial|^2 - (r0 + slope s)^2.
                let g = radial - f.axis * ((f.r0 + f.slope * s) * f.slope);
                unit(g)
            }
            None => fallback,
        },
    };
    Surface { p, ng, ns: ng }
}

use super::aabb::{Aabb, f32_down, f32_up};
use serde::Serialize;

/// Largest vertex count accepted for a polygon or patch. Real scenes stay far
/// below it (the gears' faces have 144); it bounds the memory any one object
/// may claim.
pub const MAX_POLYGON_VERTICES: usize = 16_384;

/// The four primitive kinds of NFF.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
#[repr(u8)]
pub enum ShapeKind {
    Sphere = 0,
    Polygon = 1,
    Patch = 2,
    Cone = 3,
}

impl ShapeKind {
    pub const ALL: [ShapeKind; 4] = [
        ShapeKind::Sphere,
        ShapeKind::Polygon,
        ShapeKind::Patch,
        ShapeKind::Cone,
    ];

    pub fn from_u8(v: u8) -> Option<ShapeKind> {
        match v {
            0 => Some(ShapeKind::Sphere),
            1 => Some(ShapeKind::Polygon),
            2 => Some(ShapeKind::Patch),
            3 => Some(ShapeKind::Cone),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            ShapeKind::Sphere => "sphere",
            ShapeKind::Polygon => "polygon",
            ShapeKind::Patch => "patch",
            ShapeKind::Cone => "cone",
        }
    }
}

/// One primitive, borrowing its vertex lists. Coordinates are `f32`, the
/// precision of the object database.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape<'a> {
    Sphere {
        center: [f32; 3],
        radius: f32,
    },
    /// Planar polygon, possibly non-convex; the normal comes from the first
    /// three vertices.
    Polygon {
        vertices: &'a [[f32; 3]],
    },
    /// Polygon with a normal per vertex, shaded smoothly.
    Patch {
        vertices: &'a [[f32; 3]],
        normals: &'a [[f32; 3]],
    },
    /// Open surface of revolution between two discs, no end caps.
    Cone {
        base: [f32; 3],
        base_radius: f32,
        apex: [f32; 3],
        apex_radius: f32,
    },
}

impl Shape<'_> {
    pub fn kind(&self) -> ShapeKind {
        match self {
            Shape::Sphere { .. } => ShapeKind::Sphere,
            Shape::Polygon { .. } => ShapeKind::Polygon,
            Shape::Patch { .. } => ShapeKind::Patch,
            Shape::Cone { .. } => ShapeKind::Cone,
        }
    }

    /// A box that contains every point of the shape, rounded outward to
    /// `f32`.
    pub fn bounds(&self) -> Aabb {
        match *self {
            Shape::Sphere { center, radius } => {
                let r = radius as f64;
                let mut b = Aabb::EMPTY;
                for i in 0..3 {
                    b.min[i] = f32_down(center[i] as f64 - r);
                    b.max[i] = f32_up(center[i] as f64 + r);
                }
                b
            }
            Shape::Polygon { vertices } | Shape::Patch { vertices, .. } => {
                let mut b = Aabb::EMPTY;
                for v in vertices {
                    b.add_point(*v);
                }
                b
            }
            Shape::Cone {
                base,
                base_radius,
                apex,
                apex_radius,
            } => cone_bounds(base, base_radius, apex, apex_radius),
        }
    }

    /// Checks what a well-formed shape must satisfy; returns a description
    /// of the first problem.
    pub fn validate(&self) -> Result<(), String> {
        let finite = |p: &[f32; 3]| p.iter().all(|c| c.is_finite());
        match *self {
            Shape::Sphere { center, radius } => {
                if !finite(&center) || !radius.is_finite() {
                    return Err("sphere has a non-finite number".into());
                }
                if radius < 0.0 {
                    return Err(format!(
                        "sphere radius {radius} is negative (inside-visible spheres are not supported)"
                    ));
                }
            }
            Shape::Polygon { vertices } => {
                check_vertex_count(vertices.len(), "polygon")?;
                if !vertices.iter().all(finite) {
                    return Err("polygon has a non-finite coordinate".into());
                }
            }
            Shape::Patch { vertices, normals } => {
                check_vertex_count(vertices.len(), "patch")?;
                if normals.len() != vertices.len() {
                    return Err("patch has a different number of normals and vertices".into());
                }
                if !vertices.iter().all(finite) || !normals.iter().all(finite) {
                    return Err("patch has a non-finite coordinate".into());
                }
            }
            Shape::Cone {
                base,
                base_radius,
                apex,
                apex_radius,
            } => {
                if !finite(&base)
                    || !finite(&apex)
                    || !base_radius.is_finite()
                    || !apex_radius.is_finite()
                {
                    return Err("cone has a non-finite number".into());
                }
                if base_radius < 0.0 || apex_radius < 0.0 {
                    return Err(
                        "cone radius is negative (inside-visible cones are not supported)".into(),
                    );
                }
            }
        }
        Ok(())
    }
}

fn check_vertex_count(n: usize, what: &str) -> Result<(), String> {
    if n < 3 {
        Err(format!("{what} has {n} vertices; at least 3 are needed"))
    } else if n > MAX_POLYGON_VERTICES {
        Err(format!(
            "{what} has {n} vertices, more than the limit of {MAX_POLYGON_VERTICES}"
        ))
    } else {
        Ok(())
    }
}

/// Bounds of an open cone: the union of the bounds of its two end discs.
fn cone_bounds(base: [f32; 3], br: f32, apex: [f32; 3], ar: f32) -> Aabb {
    let b = [base[0] as f64, base[1] as f64, base[2] as f64];
    let a = [apex[0] as f64, apex[1] as f64, apex[2] as f64];
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let (br, ar) = (br as f64, ar as f64);
    let mut out = Aabb::EMPTY;
    for i in 0..3 {
        // A disc of radius r with unit normal n spans r*sqrt(1 - n_i^2)
        // along axis i. A zero-length cone gets the full radius on every axis.
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_bounds_contain_the_sphere() {
        let s = Shape::Sphere {
            center: [0.1, -0.2, 0.3],
            radius: 0.7,
        };
        let b = s.bounds();
        assert!((b.min[0] as f64) <= 0.1f32 as f64 - 0.7f32 as f64);
        assert!((b.max[2] as f64) >= 0.3f32 as f64 + 0.7f32 as f64);
    }

    #[test]
    fn axis_aligned_cylinder_bounds_are_tight() {
        let c = Shape::Cone {
            base: [0.0, 0.0, 0.0],
            base_radius: 1.0,
            apex: [0.0, 0.0, 2.0],
            apex_radius: 0.5,
        };
        let b = c.bounds();
        assert_eq!(b.min, [-1.0, -1.0, 0.0]);
        assert_eq!(b.max, [1.0, 1.0, 2.0]);
    }

    #[test]
    fn validation_messages() {
        let tri = [[0.0f32; 3]; 2];
        assert!(
            Shape::Polygon { vertices: &tri }
                .validate()
                .unwrap_err()
                .contains("at least 3")
        );
        let neg = Shape::Sphere {
            center: [0.0; 3],
            radius: -1.0,
        };
        assert!(neg.validate().unwrap_err().contains("negative"));
    }
}

//! Analytic checks of every intersection routine, including the cases that
//! break naive implementations.

use super::*;
use crate::intersect::{RayQ, triangle};
use crate::math::{V3, Vec3};

fn ray(o: [f64; 3], d: [f64; 3]) -> RayQ<f64> {
    RayQ::new(V3::from_f64(o), V3::from_f64(d))
}

fn hit(shape: &Shape<'_>, o: [f64; 3], d: [f64; 3]) -> Option<f64> {
    intersect(shape, &shape.bounds(), &ray(o, d), 1e-9, f64::INFINITY)
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * b.abs().max(1.0)
}

const UNIT_SPHERE: Shape<'static> = Shape::Sphere(Sphere {
    center: [0.0, 0.0, 0.0],
    radius: 1.0,
});

#[test]
fn sphere_along_each_axis() {
    for axis in 0..3 {
        for sign in [-1.0, 1.0] {
            let mut o = [0.0; 3];
            o[axis] = -5.0 * sign;
            let mut d = [0.0; 3];
            d[axis] = sign;
            assert!(
                close(hit(&UNIT_SPHERE, o, d).unwrap(), 4.0),
                "axis {axis} sign {sign}"
            );
        }
    }
}

#[test]
fn sphere_from_inside_hits_the_far_side() {
    assert!(close(
        hit(&UNIT_SPHERE, [0.0, 0.0, 0.5], [0.0, 0.0, 1.0]).unwrap(),
        0.5
    ));
    assert!(close(
        hit(&UNIT_SPHERE, [0.0, 0.0, 0.5], [0.0, 0.0, -1.0]).unwrap(),
        1.5
    ));
}

#[test]
fn sphere_leaving_its_own_surface_finds_the_other_side() {
    // From a point on the surface heading inward: the near root is ~0.
    let p = [0.6, 0.8, 0.0];
    let t = hit(&UNIT_SPHERE, p, [-0.6, -0.8, 0.0]).unwrap();
    assert!(close(t, 2.0), "{t}");
    // Heading outward: no hit at all.
    assert!(hit(&UNIT_SPHERE, p, [0.6, 0.8, 0.0]).is_none());
}

#[test]
fn sphere_grazing_silhouette() {
    // Tangent ray at x = 1: a double root at t = 5.
    let t = hit(&UNIT_SPHERE, [1.0, -5.0, 0.0], [0.0, 1.0, 0.0]).unwrap();
    assert!((t - 5.0).abs() < 1e-6, "{t}");
    // Just outside the silhouette: miss.
    assert!(hit(&UNIT_SPHERE, [1.0 + 1e-7, -5.0, 0.0], [0.0, 1.0, 0.0]).is_none());
    // Just inside: two roots either side of 5.
    let t = hit(&UNIT_SPHERE, [1.0 - 1e-6, -5.0, 0.0], [0.0, 1.0, 0.0]).unwrap();
    assert!(t < 5.0 && t > 4.99);
}

#[test]
fn small_sphere_far_away_keeps_precision() {
    let s = Shape::Sphere(Sphere {
        center: [0.0, 1e4, 0.0],
        radius: 1e-3,
    });
    let t = hit(&s, [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]).unwrap();
    assert!((t - (1e4 - 1e-3)).abs() < 1e-7, "{t}");
    // Single precision: the discriminant trick still finds it.
    let t32 = intersect(
        &s,
        &s.bounds(),
        &ray([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]).cast::<f32>(),
        0.0,
        f32::INFINITY,
    );
    assert!(t32.is_some());
}

#[test]
fn zero_radius_sphere_is_never_hit() {
    let s = Shape::Sphere(Sphere {
        center: [0.0; 3],
        radius: 0.0,
    });
    assert!(hit(&s, [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]).is_none());
}

#[test]
fn triangle_hits_and_barycentrics() {
    let v = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let r = ray([0.25, 0.25, 1.0], [0.0, 0.0, -1.0]);
    let t = triangle::intersect(v[0], v[1], v[2], &r, 0.0, f64::INFINITY).unwrap();
    assert!(close(t, 1.0));
    let w = triangle::weights(v[0], v[1], v[2], &r);
    assert!(close(w[0], 0.5) && close(w[1], 0.25) && close(w[2], 0.25));
    // From below and from the side of the back face: both sides count.
    assert!(
        hit(
            &Shape::Polygon(Polygon { vertices: &v }),
            [0.25, 0.25, -2.0],
            [0.0, 0.0, 1.0]
        )
        .is_some()
    );
    // Outside the triangle.
    assert!(
        hit(
            &Shape::Polygon(Polygon { vertices: &v }),
            [0.75, 0.75, 1.0],
            [0.0, 0.0, -1.0]
        )
        .is_none()
    );
}

#[test]
fn triangle_along_each_axis() {
    for axis in 0..3 {
        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
        let mut v = [[0.0f32; 3]; 3];
        v[1][a] = 2.0;
        v[2][b] = 2.0;
        let mut o = [0.5; 3];
        o[axis] = 3.0;
        let mut d = [0.0; 3];
        d[axis] = -1.0;
        assert!(close(
            hit(&Shape::Polygon(Polygon { vertices: &v }), o, d).unwrap(),
            3.0
        ));
    }
}

#[test]
fn ray_in_the_plane_misses() {
    let tri = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let quad = [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ];
    for v in [&tri[..], &quad[..]] {
        let s = Shape::Polygon(Polygon { vertices: v });
        assert!(hit(&s, [-1.0, 0.25, 0.0], [1.0, 0.0, 0.0]).is_none());
        assert!(hit(&s, [-1.0, -1.0, 0.0], [1.0, 1.0, 0.0]).is_none());
    }
}

#[test]
fn shared_edge_is_watertight() {
    // Two triangles sharing the diagonal of the unit square; rays exactly
    // through points of the diagonal must hit one of them.
    let a = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
    let b = [[0.0f32, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    for i in 0..=64 {
        let x = i as f64 / 64.0;
        let o = [x, x, 1.0];
        let d = [0.001 * (i as f64 - 32.0), 0.0007, -1.0];
        let ha = hit(&Shape::Polygon(Polygon { vertices: &a }), o, d);
        let hb = hit(&Shape::Polygon(Polygon { vertices: &b }), o, d);
        let inside = (0.0..=1.0).contains(&(x + d[0])) && (0.0..=1.0).contains(&(x + d[1]));
        if inside {
            assert!(ha.is_some() || hb.is_some(), "crack at {i}");
        }
    }
}

#[test]
fn degenerate_polygons_are_never_hit() {
    let line = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
    let point = [[1.0f32, 1.0, 1.0]; 4];
    for v in [&line[..], &point[..]] {
        let s = Shape::Polygon(Polygon { vertices: v });
        for d in [
            [0.0, 0.0, -1.0],
            [0.0, -1.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.3, -0.2, -1.0],
        ] {
            assert!(hit(&s, [1.0, 0.0, 1.0], d).is_none());
        }
    }
}

#[test]
fn concave_polygon() {
    // An L shape: the notch at (1.5, 1.5) is outside.
    let l = [
        [0.0f32, 0.0, 0.0],
        [2.0, 0.0, 0.0],
        [2.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
        [1.0, 2.0, 0.0],
        [0.0, 2.0, 0.0],
    ];
    let s = Shape::Polygon(Polygon { vertices: &l });
    assert!(hit(&s, [0.5, 1.5, 1.0], [0.0, 0.0, -1.0]).is_some());
    assert!(hit(&s, [1.5, 0.5, 1.0], [0.0, 0.0, -1.0]).is_some());
    assert!(hit(&s, [1.5, 1.5, 1.0], [0.0, 0.0, -1.0]).is_none());
    assert!(hit(&s, [2.5, 0.5, 1.0], [0.0, 0.0, -1.0]).is_none());
}

#[test]
fn polygon_with_collinear_first_corner_uses_newell_normal() {
    let q = [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [2.0, 0.0, 0.0],
        [2.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ];
    let s = Shape::Polygon(Polygon { vertices: &q });
    assert!(close(
        hit(&s, [0.5, 0.5, 2.0], [0.0, 0.0, -1.0]).unwrap(),
        2.0
    ));
}

#[test]
fn cylinder_and_cone() {
    let cyl = Shape::Cone(Cone {
        base: [0.0, 0.0, 0.0],
        base_radius: 1.0,
        apex: [0.0, 0.0, 2.0],
        apex_radius: 1.0,
    });
    assert!(close(
        hit(&cyl, [-5.0, 0.0, 1.0], [1.0, 0.0, 0.0]).unwrap(),
        4.0
    ));
    // Open: a ray down the axis passes through.
    assert!(hit(&cyl, [0.0, 0.0, 5.0], [0.0, 0.0, -1.0]).is_none());
    // Above the top: miss; from inside: the far wall.
    assert!(hit(&cyl, [-5.0, 0.0, 2.5], [1.0, 0.0, 0.0]).is_none());
    assert!(close(
        hit(&cyl, [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]).unwrap(),
        1.0
    ));
    // A true cone, radius 1 at z = 0 to 0 at z = 1: at z = 0.5 the radius
    // is 0.5.
    let cone = Shape::Cone(Cone {
        base: [0.0, 0.0, 0.0],
        base_radius: 1.0,
        apex: [0.0, 0.0, 1.0],
        apex_radius: 0.0,
    });
    assert!(close(
        hit(&cone, [-3.0, 0.0, 0.5], [1.0, 0.0, 0.0]).unwrap(),
        2.5
    ));
    // The cone's mirror nappe beyond the apex is not part of it.
    assert!(hit(&cone, [-3.0, 0.0, 1.5], [1.0, 0.0, 0.0]).is_none());
    // Along each axis.
    for axis in 0..3 {
        let mut apex = [0.0f32; 3];
        apex[axis] = 2.0;
        let c = Shape::Cone(Cone {
            base: [0.0; 3],
            base_radius: 0.5,
            apex,
            apex_radius: 0.5,
        });
        let mut o = [0.0; 3];
        o[axis] = 1.0;
        o[(axis + 1) % 3] = -4.0;
        let mut d = [0.0; 3];
        d[(axis + 1) % 3] = 1.0;
        assert!(close(hit(&c, o, d).unwrap(), 3.5), "axis {axis}");
    }
}

#[test]
fn zero_length_cone_is_never_hit() {
    let c = Shape::Cone(Cone {
        base: [0.0, 0.0, 0.0],
        base_radius: 1.0,
        apex: [0.0, 0.0, 0.0],
        apex_radius: 0.5,
    });
    for d in [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.3, 0.4, -0.5]] {
        assert!(hit(&c, [-2.0, 0.0, 1.0], d).is_none());
    }
}

#[test]
fn patch_interpolates_vertex_normals() {
    let v = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let n = [[0.0f32, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let s = Shape::Patch(Patch {
        vertices: &v,
        normals: &n,
    });
    let r = ray([0.25, 0.25, 1.0], [0.0, 0.0, -1.0]);
    let t = intersect(&s, &s.bounds(), &r, 0.0, f64::INFINITY).unwrap();
    let surf = s.surface(&r, t);
    let expect = Vec3::new(0.25, 0.25, 0.5).try_normalize().unwrap();
    assert!((surf.ns - expect).length() < 1e-9);
    assert!((surf.ng - Vec3::new(0.0, 0.0, 1.0)).length() < 1e-12);
}

#[test]
fn surface_normals() {
    let r = ray([0.0, 0.0, 5.0], [0.0, 0.0, -1.0]);
    let s = UNIT_SPHERE.surface(&r, 4.0);
    assert!((s.ng - Vec3::new(0.0, 0.0, 1.0)).length() < 1e-12);
    let cone = Shape::Cone(Cone {
        base: [0.0, 0.0, 0.0],
        base_radius: 1.0,
        apex: [0.0, 0.0, 1.0],
        apex_radius: 0.0,
    });
    let r = ray([-3.0, 0.0, 0.5], [1.0, 0.0, 0.0]);
    let s = cone.surface(&r, 2.5);
    let expect = Vec3::new(-1.0, 0.0, 1.0).try_normalize().unwrap();
    assert!((s.ng - expect).length() < 1e-9, "{:?}", s.ng);
}

#[test]
fn single_precision_agrees_on_easy_cases() {
    let quad = [
        [-1.0f32, -1.0, 0.0],
        [1.0, -1.0, 0.0],
        [1.0, 1.0, 0.0],
        [-1.0, 1.0, 0.0],
    ];
    let shapes = [
        UNIT_SPHERE,
        Shape::Polygon(Polygon { vertices: &quad }),
        Shape::Cone(Cone {
            base: [0.0, 0.0, -1.0],
            base_radius: 0.5,
            apex: [0.0, 0.0, 1.0],
            apex_radius: 0.25,
        }),
    ];
    for s in &shapes {
        let r = ray([0.1, 0.2, 4.0], [0.05, -0.02, -1.0]);
        let a = intersect(s, &s.bounds(), &r, 0.0, f64::INFINITY);
        let b = intersect(s, &s.bounds(), &r.cast::<f32>(), 0.0, f32::INFINITY);
        match (a, b) {
            (Some(a), Some(b)) => assert!((a - b as f64).abs() < 1e-5),
            (None, None) => {}
            other => panic!("{other:?}"),
        }
    }
}

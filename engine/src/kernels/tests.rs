//! Every kernel, on every instruction set this machine has and in both
//! precisions, against the scalar test of its kind: the same lanes hit,
//! at the same distances, bit for bit.

use super::*;
use crate::intersect::{RayQ, triangle};
use crate::math::{Real, Vec3, Vec3Ext};
use crate::scene::Aabb;
use crate::shapes::{Cone, ConeKind, Kind, Polygon, PolygonKind, Sphere, SphereKind, frame};
use crate::simd::{Elem, Isa};

/// Reproducible numbers in [0, 1).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }

    fn point(&mut self, s: f64) -> [f32; 3] {
        [0, 1, 2].map(|_| self.range(-s, s) as f32)
    }
}

/// A group of rays toward the unit cube from all around, with some of
/// the awkward ones: directions with zero components, rays through the
/// given points exactly, short intervals.
fn rays<R: Real>(rng: &mut Rng, targets: &[[f32; 3]]) -> RayLanes<R> {
    let mut g = unsealed::<R>(rng, targets, LANES);
    g.seal(Isa::detect());
    g
}

/// [`rays`]' first `n` rays, pushed and not sealed.
fn unsealed<R: Real>(rng: &mut Rng, targets: &[[f32; 3]], n: usize) -> RayLanes<R> {
    let mut g = RayLanes::<R>::new();
    for i in 0..n {
        let o = Vec3::new(
            rng.range(-3.0, 3.0),
            rng.range(-3.0, 3.0),
            rng.range(-3.0, 3.0),
        );
        let target = if i % 4 == 0 && !targets.is_empty() {
            let p = targets[i % targets.len()];
            Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64)
        } else {
            Vec3::new(
                rng.range(-1.2, 1.2),
                rng.range(-1.2, 1.2),
                rng.range(-1.2, 1.2),
            )
        };
        let mut d = target - o;
        if i % 9 == 0 {
            d.x = 0.0;
        }
        if i % 13 == 0 {
            d.y = -0.0;
        }
        if d == Vec3::ZERO {
            d = Vec3::X;
        }
        let (lo, hi) = match i % 5 {
            0 => (0.0, f64::INFINITY),
            1 => (rng.range(0.0, 0.5), rng.range(0.5, 2.0)),
            _ => (1e-6, f64::INFINITY),
        };
        g.push(o, d, lo, hi);
    }
    g
}

/// Every value [`RayLanes::seal`] derives for lane `i`, as bits.
fn derived<R: Real>(g: &RayLanes<R>, i: usize) -> Vec<u64> {
    let b = |x: R| x.to_f64().to_bits();
    let mut v = vec![];
    for a in 0..3 {
        v.extend([
            b(g.o[a][i]),
            b(g.d[a][i]),
            b(g.inv[a][i]),
            g.inv64[a][i].to_bits(),
        ]);
    }
    v.extend([g.t_min[i], g.t_max[i], g.kx[i], g.ky[i], g.kz[i]].map(b));
    v.extend([g.sx[i], g.sy[i], g.sz[i], g.a[i], g.inv_a[i]].map(b));
    v.extend(g.axes[i].map(u64::from));
    v
}

/// Sealing a group derives, on every instruction set, the values of the
/// scalar ray the tests take ([`RayQ::with_inverse`] of the ray rounded
/// to `R`, with `1 / d` computed in `f64`), for full groups and for
/// groups whose last vector is partly filled.
fn seals_as_the_scalar_ray<R: Real>() {
    for (seed, n) in [(3, LANES), (4, 37), (5, 1), (6, 16)] {
        let want: Vec<Vec<u64>> = {
            let g = unsealed::<R>(&mut Rng(seed), &[[0.5, 0.5, 0.5]], n);
            (0..n)
                .map(|i| {
                    let (o, d) = (g.o(i), g.d(i));
                    let inv = Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
                    let q = RayQ::<R>::with_inverse(o.cast(), d.cast(), inv.cast());
                    let b = |x: R| x.to_f64().to_bits();
                    let finite = |x: R| {
                        if x.is_finite() {
                            x
                        } else if x > R::ZERO {
                            R::MAX
                        } else {
                            -R::MAX
                        }
                    };
                    let mut v = vec![];
                    for a in 0..3 {
                        v.extend([b(q.o[a]), b(q.d[a]), b(finite(q.inv[a])), inv[a].to_bits()]);
                    }
                    let k = [q.kx, q.ky, q.kz].map(|k| R::from_f64(k as f64));
                    v.extend([
                        b(R::from_f64(g.t_min64[i])),
                        b(R::from_f64(g.t_max64[i])),
                        b(k[0]),
                        b(k[1]),
                        b(k[2]),
                    ]);
                    v.extend([q.sx, q.sy, q.sz(), q.a, q.inv_a].map(b));
                    v.extend([q.kx, q.ky, q.kz].map(u64::from));
                    v
                })
                .collect()
        };
        for isa in Isa::available_here() {
            let mut g = unsealed::<R>(&mut Rng(seed), &[[0.5, 0.5, 0.5]], n);
            assert!(!g.is_sealed());
            g.seal(isa);
            assert!(g.is_sealed());
            for i in 0..n {
                assert_eq!(derived(&g, i), want[i], "{isa}, {n} rays, lane {i}");
            }
            let same = (1..n).all(|i| want[i][want[i].len() - 3..] == want[0][want[0].len() - 3..]);
            assert_eq!(g.same_axes, same, "{isa}, {n} rays");
        }
    }
}

#[test]
fn sealing_derives_the_scalar_rays_on_every_width() {
    seals_as_the_scalar_ray::<f32>();
    seals_as_the_scalar_ray::<f64>();
}

fn limits<R: Real>(g: &RayLanes<R>) -> [R; LANES] {
    g.t_max
}

/// Runs `kernel` on every instruction set here and checks its lanes and
/// distances against `scalar`, lane by lane.
fn check<R: Elem>(
    what: &str,
    g: &RayLanes<R>,
    mut kernel: impl FnMut(Isa, Lanes, &mut [R; LANES]) -> Lanes,
    scalar: impl Fn(&RayQ<R>, R, R) -> Option<R>,
) -> usize {
    let mut hits = 0;
    let limit = limits(g);
    // Every lane, and a sparse mask.
    for m in [g.all(), 0x8421_0842_1084_2108 & g.all()] {
        let want: Vec<Option<R>> = (0..LANES)
            .map(|i| {
                (m >> i & 1 != 0)
                    .then(|| scalar(&g.ray(i), g.t_min[i], limit[i]))
                    .flatten()
            })
            .collect();
        for isa in Isa::available_here() {
            let mut t = [R::ZERO; LANES];
            let got = kernel(isa, m, &mut t);
            for i in 0..LANES {
                let g = (got >> i & 1 != 0).then_some(t[i]);
                assert_eq!(
                    want[i].map(|x| x.to_f64().to_bits()),
                    g.map(|x| x.to_f64().to_bits()),
                    "{what}, {isa}, lane {i}"
                );
            }
        }
        hits += want.iter().filter(|w| w.is_some()).count();
    }
    hits
}

fn triangles<R: Elem>(rng: &mut Rng) -> usize {
    let mut hits = 0;
    for _ in 0..300 {
        let v = [rng.point(1.0), rng.point(1.0), rng.point(1.0)];
        let g = rays::<R>(rng, &v);
        hits += check(
            "triangle",
            &g,
            |isa, m, t| {
                isa.run(Triangle {
                    v: &v,
                    rays: &g,
                    m,
                    limit: &g.t_max,
                    t_out: t,
                })
            },
            |q, lo, hi| triangle::intersect(v[0], v[1], v[2], q, lo, hi),
        );
    }
    hits
}

#[test]
fn triangles_match_the_scalar_test() {
    let mut rng = Rng(1);
    assert!(triangles::<f64>(&mut rng) > 1000);
    assert!(triangles::<f32>(&mut rng) > 1000);
}

/// Rays that all share their axes take the kernel's other path.
#[test]
fn triangles_match_with_rays_of_the_same_axes() {
    let mut rng = Rng(2);
    for _ in 0..100 {
        let v = [rng.point(1.0), rng.point(1.0), rng.point(1.0)];
        let mut g = RayLanes::<f32>::new();
        for _ in 0..LANES {
            let o = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), 4.0);
            let d = Vec3::new(rng.range(-0.3, 0.3), rng.range(-0.3, 0.3), -1.0);
            g.push(o, d, 0.0, f64::INFINITY);
        }
        g.seal(Isa::detect());
        assert!(g.same_axes);
        check(
            "triangle",
            &g,
            |isa, m, t| {
                isa.run(Triangle {
                    v: &v,
                    rays: &g,
                    m,
                    limit: &g.t_max,
                    t_out: t,
                })
            },
            |q, lo, hi| triangle::intersect(v[0], v[1], v[2], q, lo, hi),
        );
    }
}

fn spheres<R: Elem>(rng: &mut Rng) -> usize {
    let mut hits = 0;
    for k in 0..300 {
        let s = Sphere {
            center: rng.point(0.8),
            radius: if k % 50 == 0 {
                0.0
            } else {
                rng.range(0.01, 0.7) as f32
            },
        };
        let g = rays::<R>(rng, &[s.center]);
        let bbox = SphereKind::bounds(&s);
        hits += check(
            "sphere",
            &g,
            |isa, m, t| {
                isa.run(SphereLanes {
                    s: &s,
                    rays: &g,
                    m,
                    limit: &g.t_max,
                    t_out: t,
                })
            },
            |q, lo, hi| SphereKind::intersect(&s, None, &bbox, q, lo, hi),
        );
    }
    hits
}

#[test]
fn spheres_match_the_scalar_test() {
    let mut rng = Rng(3);
    assert!(spheres::<f64>(&mut rng) > 1000);
    assert!(spheres::<f32>(&mut rng) > 1000);
}

/// A planar polygon of `n` vertices, star-shaped (so not convex), in a
/// random plane.
fn polygon(rng: &mut Rng, n: usize) -> Vec<[f32; 3]> {
    let c = rng.point(0.3);
    let (a, b) = (rng.point(1.0), rng.point(1.0));
    (0..n)
        .map(|i| {
            let ang = i as f64 / n as f64 * std::f64::consts::TAU;
            let r = if i % 2 == 0 { 0.8 } else { 0.4 };
            let (x, y) = (r * ang.cos(), r * ang.sin());
            [0, 1, 2].map(|k| c[k] + (x * a[k] as f64 + y * b[k] as f64) as f32)
        })
        .collect()
}

fn polygons<R: Elem>(rng: &mut Rng) -> usize {
    let mut hits = 0;
    for k in 0..300 {
        let v = polygon(rng, [4, 5, 8, 24, 144][k % 5]);
        let shape = Polygon { vertices: &v };
        let plane = PolygonKind::prepare(&shape).expect("a polygon's plane");
        let bbox = PolygonKind::bounds(&shape);
        let g = rays::<R>(rng, &v);
        hits += check(
            "polygon",
            &g,
            |isa, m, t| {
                let (mut pu, mut pv) = ([R::ZERO; LANES], [R::ZERO; LANES]);
                let on = isa.run(PlaneLanes {
                    v: &v,
                    plane: &plane,
                    bbox: &bbox,
                    rays: &g,
                    m,
                    limit: &g.t_max,
                    t_out: t,
                    pu: &mut pu,
                    pv: &mut pv,
                });
                isa.run(Crossings {
                    v: &v,
                    plane: &plane,
                    m: on,
                    pu: &pu,
                    pv: &pv,
                })
            },
            |q, lo, hi| PolygonKind::intersect(&shape, Some(&plane), &bbox, q, lo, hi),
        );
    }
    hits
}

#[test]
fn polygons_match_the_scalar_test() {
    let mut rng = Rng(4);
    assert!(polygons::<f64>(&mut rng) > 500);
    assert!(polygons::<f32>(&mut rng) > 500);
}

fn cones<R: Elem>(rng: &mut Rng) -> usize {
    let mut hits = 0;
    for k in 0..300 {
        let c = Cone {
            base: rng.point(0.8),
            base_radius: rng.range(0.0, 0.5) as f32,
            apex: rng.point(0.8),
            apex_radius: if k % 3 == 0 {
                0.0
            } else {
                rng.range(0.0, 0.5) as f32
            },
        };
        let Some(f) = frame(&c) else { continue };
        let bbox = ConeKind::bounds(&c);
        let g = rays::<R>(rng, &[c.base, c.apex]);
        hits += check(
            "cone",
            &g,
            |isa, m, t| {
                isa.run(ConeLanes {
                    frame: &f,
                    bbox: &bbox,
                    rays: &g,
                    m,
                    limit: &g.t_max,
                    t_out: t,
                })
            },
            |q, lo, hi| ConeKind::intersect(&c, Some(&f), &bbox, q, lo, hi),
        );
    }
    hits
}

#[test]
fn cones_match_the_scalar_test() {
    let mut rng = Rng(5);
    assert!(cones::<f64>(&mut rng) > 500);
    assert!(cones::<f32>(&mut rng) > 500);
}

fn boxes<R: Elem>(rng: &mut Rng) {
    for k in 0..300 {
        let (p, q) = (rng.point(1.0), rng.point(1.0));
        let mut b = Aabb {
            min: [0, 1, 2].map(|i| p[i].min(q[i])),
            max: [0, 1, 2].map(|i| p[i].max(q[i])),
        };
        if k % 7 == 0 {
            b.max[1] = b.min[1]; // flat
        }
        let g = rays::<R>(rng, &[b.min, b.max]);
        // The exact pre-test, against the scalar one: on rays some of
        // whose directions have a zero component (in most vectors of
        // lanes, on every width), and on rays none of whose directions
        // have one (the kernel's shorter path in every vector).
        for h in [&g, &without_zero_components(&g)] {
            for isa in Isa::available_here() {
                let got = isa.run(MayHitBox {
                    b: &b,
                    rays: h,
                    m: h.all(),
                    limit: &h.t_max,
                });
                for i in 0..h.n {
                    let want = h.ray(i).may_hit_box(&b, h.t_min[i], h.t_max[i]);
                    assert_eq!(got >> i & 1 != 0, want, "may_hit_box, {isa}, lane {i}");
                }
            }
        }
        // The culling test: the same on every instruction set, and
        // never false where the scalar culling test is true.
        let lo = b.min.map(|x| R::from_f32(x));
        let hi = b.max.map(|x| R::from_f32(x));
        let runs: Vec<Lanes> = Isa::available_here()
            .into_iter()
            .map(|isa| {
                isa.run(BoxLanes {
                    lo,
                    hi,
                    rays: &g,
                    m: g.all(),
                    limit: &g.t_max,
                })
            })
            .collect();
        assert!(
            runs.windows(2).all(|w| w[0] == w[1]),
            "box lanes differ by width"
        );
        for i in 0..LANES {
            let meets =
                crate::df::ray_meets(g.o(i), g.inv(i), g.t_min64[i], g.t_max64[i], &b, 1e-9);
            let thick = (0..3).all(|a| b.max[a] - b.min[a] > 1e-3);
            if runs[0] >> i & 1 == 0 && meets && thick {
                // A lane ruled out in R but met in f64 with a pad: only
                // the rounding of R, within a hair of the box.
                let grown =
                    crate::df::ray_meets(g.o(i), g.inv(i), g.t_min64[i], g.t_max64[i], &b, -1e-4);
                assert!(!grown, "lane {i} misses a box it crosses");
            }
        }
    }
}

/// The rays of `g` whose directions have no zero component, sealed.
fn without_zero_components<R: Real>(g: &RayLanes<R>) -> RayLanes<R> {
    let mut h = RayLanes::new();
    for i in 0..g.n {
        let d = g.d(i);
        if d.x != 0.0 && d.y != 0.0 && d.z != 0.0 {
            h.push(g.o(i), d, g.t_min64[i], g.t_max64[i]);
        }
    }
    assert!(h.n > LANES / 2);
    h.seal(Isa::detect());
    h
}

#[test]
fn boxes_match_the_scalar_tests() {
    let mut rng = Rng(6);
    boxes::<f64>(&mut rng);
    boxes::<f32>(&mut rng);
}

/// A lane holds the ray as `RayQ` prepares it for the scalar tests.
#[test]
fn a_lane_is_the_ray_the_scalar_tests_take() {
    let mut rng = Rng(7);
    let g = rays::<f32>(&mut rng, &[]);
    for i in 0..LANES {
        let q = RayQ::<f32>::with_inverse(g.o(i).cast(), g.d(i).cast(), g.inv(i).cast());
        assert_eq!(g.axes[i], [q.kx, q.ky, q.kz], "lane {i}");
        assert_eq!(
            [g.sx[i], g.sy[i], g.sz[i]].map(f32::to_bits),
            [q.sx, q.sy, q.sz()].map(f32::to_bits),
            "lane {i}"
        );
        assert_eq!(g.kz[i], q.kz as f32);
        assert_eq!(g.inv_a[i].to_bits(), q.inv_a.to_bits());
    }
}

/// One ray against a batch of triangles gives each triangle the scalar
/// test's answer, on every instruction set.
#[test]
fn batches_of_triangles_match_the_scalar_test() {
    fn run<R: Elem>(rng: &mut Rng) -> usize {
        let mut hits = 0;
        for round in 0..40 {
            let tris: Vec<[[f32; 3]; 3]> = (0..BATCH - round % 7)
                .map(|_| [rng.point(1.0), rng.point(1.0), rng.point(1.0)])
                .collect();
            let mut batch = TriangleBatch::<R>::new();
            for t in &tris {
                batch.push(t);
            }
            let g = rays::<R>(rng, &tris.iter().map(|t| t[0]).collect::<Vec<_>>());
            for i in 0..LANES {
                let m = if i % 3 == 0 {
                    batch.all()
                } else {
                    batch.all() & 0x5555_5555_5555_5555
                };
                let want: Vec<Option<R>> = (0..BATCH)
                    .map(|j| {
                        (m >> j & 1 != 0)
                            .then(|| {
                                let t = &tris[j];
                                triangle::intersect(
                                    t[0],
                                    t[1],
                                    t[2],
                                    &g.ray(i),
                                    g.t_min[i],
                                    g.t_max[i],
                                )
                            })
                            .flatten()
                    })
                    .collect();
                for isa in Isa::available_here() {
                    let mut t = [R::ZERO; BATCH];
                    let got = isa.run(RayTriangles {
                        batch: &batch,
                        m,
                        rays: &g,
                        i,
                        limit: g.t_max[i],
                        t_out: &mut t,
                    });
                    for j in 0..BATCH {
                        assert_eq!(
                            want[j].map(|x| x.to_f64().to_bits()),
                            (got >> j & 1 != 0).then(|| t[j].to_f64().to_bits()),
                            "{isa}, ray {i}, triangle {j}"
                        );
                    }
                }
                hits += want.iter().filter(|w| w.is_some()).count();
            }
        }
        hits
    }
    let mut rng = Rng(8);
    assert!(run::<f64>(&mut rng) > 1000);
    assert!(run::<f32>(&mut rng) > 1000);
}

/// `rays`' lanes put one by one from each lane's scalar ray with
/// [`RayLanes::set_q`], as the breadth-first scan gathers its slots'
/// rays, with the values `need` asks for; the other values are garbage,
/// which a kernel that read them would show.
fn gathered<R: Real>(g: &RayLanes<R>, need: Need) -> RayLanes<R> {
    let mut h = RayLanes::<R>::new();
    for i in 0..LANES {
        for a in 0..3 {
            h.o[a][i] = R::from_f64(1e3);
            h.d[a][i] = R::from_f64(-7.0);
            h.inv[a][i] = R::from_f64(0.25);
        }
        (h.a[i], h.inv_a[i], h.sx[i], h.sy[i]) = (R::ONE, R::ONE, R::ONE, R::ONE);
    }
    for i in 0..g.n {
        h.set_q(i, &g.ray(i), g.t_min[i], g.t_max[i], need);
    }
    h.n = g.n;
    h
}

/// Every kind through [`shape_lanes`], on rays gathered from scalar rays
/// with only what each kind's kernel needs: the scalar test's bits.
fn gathered_shapes<R: Elem>(rng: &mut Rng) -> usize {
    let mut hits = 0;
    for k in 0..200 {
        let v = polygon(rng, 3 + k % 6);
        let normals = vec![[0.0, 0.0, 1.0]; v.len()];
        let sphere = Sphere {
            center: rng.point(0.8),
            radius: rng.range(0.05, 0.8) as f32,
        };
        let cone = Cone {
            base: rng.point(0.8),
            base_radius: rng.range(0.0, 0.5) as f32,
            apex: rng.point(0.8),
            apex_radius: rng.range(0.0, 0.5) as f32,
        };
        let shapes = [
            crate::shapes::Shape::Sphere(sphere),
            crate::shapes::Shape::Polygon(Polygon { vertices: &v }),
            crate::shapes::Shape::Patch(crate::shapes::Patch {
                vertices: &v,
                normals: &normals,
            }),
            crate::shapes::Shape::Cone(cone),
        ];
        for shape in &shapes {
            let prep = shape.prepare();
            let bbox = shape.bounds();
            let need = match shape {
                crate::shapes::Shape::Polygon(p) if p.vertices.len() == 3 => Need::Triangle,
                s => Need::of(s.kind()),
            };
            let g = rays::<R>(rng, &v);
            let lanes = gathered(&g, need);
            let mut out = Found::<R>::new();
            hits += check(
                "gathered",
                &g,
                |isa, m, t| {
                    let hit = isa
                        .run(ShapeLanes {
                            shape,
                            prep: prep.as_ref(),
                            bbox: &bbox,
                            rays: &lanes,
                            m,
                            limit: &lanes.t_max,
                            out: &mut out,
                        })
                        .expect("a kind with a kernel");
                    *t = out.t;
                    hit
                },
                |q, lo, hi| shape.intersect(prep.as_ref(), &bbox, q, lo, hi),
            );
        }
    }
    hits
}

#[test]
fn rays_gathered_from_scalar_rays_match_the_scalar_tests() {
    let mut rng = Rng(11);
    assert!(gathered_shapes::<f64>(&mut rng) > 1000);
    assert!(gathered_shapes::<f32>(&mut rng) > 1000);
}

//! The SIMD intersection kernels, each on every instruction set this CPU
//! has: one primitive against a group of 64 rays (about half of which hit
//! it), reported as rays per second per primitive kind. `cargo bench -p
//! sray-engine --bench kernels` (not run by CI: timings are benchmarks,
//! not tests).

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use sray_engine::kernels::{
    BATCH, BoxLanes, ConeLanes, Crossings, LANES, PlaneLanes, RayLanes, RayTriangles, SphereLanes,
    Triangle, TriangleBatch,
};
use sray_engine::math::Vec3;
use sray_engine::scene::Aabb;
use sray_engine::shapes::{Cone, ConeKind, Kind, Polygon, PolygonKind, Sphere, frame};
use sray_engine::simd::{Elem, Isa};
use std::hint::black_box;

/// Reproducible numbers in [0, 1).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// 64 rays from around (0, 0, 5) toward points of the square [-1.2, 1.2]²
/// at z = 0: a primitive filling the unit square is hit by about half.
fn rays<R: Elem>() -> RayLanes<R> {
    let mut rng = Rng(7);
    let mut g = RayLanes::<R>::new();
    for _ in 0..LANES {
        let o = Vec3::new(rng.next() * 0.2, rng.next() * 0.2, 5.0);
        let t = Vec3::new(rng.next() * 2.4 - 1.2, rng.next() * 2.4 - 1.2, 0.0);
        g.push(o, t - o, 1e-6, f64::INFINITY);
    }
    g.seal(Isa::detect());
    g
}

fn bench_kernels<R: Elem>(c: &mut Criterion, precision: &str) {
    let g = rays::<R>();
    let all = g.all();
    let mut t = [R::ZERO; LANES];
    let widths = Isa::available_here();

    let mut group = c.benchmark_group(format!("kernels_{precision}"));
    group.throughput(Throughput::Elements(LANES as u64));

    let tri = [[-1.0f32, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]];
    for &isa in &widths {
        group.bench_with_input(BenchmarkId::new("triangle", isa), &isa, |b, &isa| {
            b.iter(|| {
                isa.run(Triangle {
                    v: black_box(&tri),
                    rays: &g,
                    m: all,
                    limit: &g.t_max,
                    t_out: &mut t,
                })
            })
        });
    }

    let sphere = Sphere {
        center: [0.0, 0.0, 0.0],
        radius: 1.0,
    };
    for &isa in &widths {
        group.bench_with_input(BenchmarkId::new("sphere", isa), &isa, |b, &isa| {
            b.iter(|| {
                isa.run(SphereLanes {
                    s: black_box(&sphere),
                    rays: &g,
                    m: all,
                    limit: &g.t_max,
                    t_out: &mut t,
                })
            })
        });
    }

    // A gear-like polygon of 48 vertices.
    let gear: Vec<[f32; 3]> = (0..48)
        .map(|i| {
            let a = i as f32 / 48.0 * std::f32::consts::TAU;
            let r = if i % 2 == 0 { 1.0 } else { 0.8 };
            [r * a.cos(), r * a.sin(), 0.0]
        })
        .collect();
    let shape = Polygon { vertices: &gear };
    let plane = PolygonKind::prepare(&shape).expect("a plane");
    let pbox = PolygonKind::bounds(&shape);
    for &isa in &widths {
        group.bench_with_input(BenchmarkId::new("polygon48", isa), &isa, |b, &isa| {
            let (mut pu, mut pv) = ([R::ZERO; LANES], [R::ZERO; LANES]);
            b.iter(|| {
                let on = isa.run(PlaneLanes {
                    v: black_box(&gear),
                    plane: &plane,
                    bbox: &pbox,
                    rays: &g,
                    m: all,
                    limit: &g.t_max,
                    t_out: &mut t,
                    pu: &mut pu,
                    pv: &mut pv,
                });
                isa.run(Crossings {
                    v: &gear,
                    plane: &plane,
                    m: on,
                    pu: &pu,
                    pv: &pv,
                })
            })
        });
    }

    let cone = Cone {
        base: [0.0, 0.0, -1.0],
        base_radius: 1.0,
        apex: [0.0, 0.3, 1.0],
        apex_radius: 0.4,
    };
    let f = frame(&cone).expect("a cone's frame");
    let cbox = ConeKind::bounds(&cone);
    for &isa in &widths {
        group.bench_with_input(BenchmarkId::new("cone", isa), &isa, |b, &isa| {
            b.iter(|| {
                isa.run(ConeLanes {
                    frame: black_box(&f),
                    bbox: &cbox,
                    rays: &g,
                    m: all,
                    limit: &g.t_max,
                    t_out: &mut t,
                })
            })
        });
    }

    let bx = Aabb {
        min: [-1.0, -1.0, -0.5],
        max: [1.0, 1.0, 0.5],
    };
    let (lo, hi) = (bx.min.map(R::from_f32), bx.max.map(R::from_f32));
    for &isa in &widths {
        group.bench_with_input(BenchmarkId::new("box", isa), &isa, |b, &isa| {
            b.iter(|| {
                isa.run(BoxLanes {
                    lo: black_box(lo),
                    hi,
                    rays: &g,
                    m: all,
                    limit: &g.t_max,
                })
            })
        });
    }
    group.finish();

    // One ray against a batch of 64 small triangles tiling the square:
    // triangle tests per second.
    let mut group = c.benchmark_group(format!("batch_{precision}"));
    group.throughput(Throughput::Elements(BATCH as u64));
    let mut batch = TriangleBatch::<R>::new();
    for k in 0..BATCH {
        let (x, y) = ((k % 8) as f32 / 4.0 - 1.0, (k / 8) as f32 / 4.0 - 1.0);
        batch.push(&[[x, y, 0.0], [x + 0.25, y, 0.0], [x, y + 0.25, 0.0]]);
    }
    let mut bt = [R::ZERO; BATCH];
    for &isa in &widths {
        group.bench_with_input(BenchmarkId::new("ray_triangles", isa), &isa, |b, &isa| {
            b.iter(|| {
                isa.run(RayTriangles {
                    batch: black_box(&batch),
                    m: batch.all(),
                    rays: &g,
                    i: 3,
                    limit: g.t_max[3],
                    t_out: &mut bt,
                })
            })
        });
    }
    group.finish();
}

fn kernels(c: &mut Criterion) {
    bench_kernels::<f32>(c, "single");
    bench_kernels::<f64>(c, "double");
}

criterion_group!(benches, kernels);
criterion_main!(benches);

//! Micro-benchmarks of the hot loops both tracers share: each primitive's
//! intersection test, one step of the grid walk, and decoding a block of
//! the object database. A baseline for the speed work; `cargo bench -p
//! sray-engine` (not run by CI: timings belong in benchmarks, not tests).

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use sray_engine::grid::{Dda, GridSpec};
use sray_engine::intersect::RayQ;
use sray_engine::math::Vec3;
use sray_engine::progress::NoProgress;
use sray_engine::scene::Aabb;
use sray_engine::sdb::{Compression, Database, DbWriter};
use sray_engine::shapes::{Cone, Patch, Polygon, Shape, Sphere};
use sray_engine::source::SceneSource;
use sray_engine::spd::SpdScene;
use std::hint::black_box;

/// A ray from (0.1, 0.2, 5) toward -z, slightly tilted, and its inverse.
fn ray() -> (Vec3, Vec3) {
    let o = Vec3::new(0.1, 0.2, 5.0);
    let d = Vec3::new(0.01, -0.02, -1.0).normalize();
    (o, d)
}

fn intersection_tests(c: &mut Criterion) {
    let tri = [[-1.0f32, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]];
    let quad = [
        [-1.0f32, -1.0, 0.0],
        [1.0, -1.0, 0.0],
        [1.0, 1.0, 0.0],
        [-1.0, 1.0, 0.0],
    ];
    // A gear-like polygon of 48 vertices (many-sided, non-trivial crossings test).
    let gear: Vec<[f32; 3]> = (0..48)
        .map(|i| {
            let a = i as f32 / 48.0 * std::f32::consts::TAU;
            let r = if i % 2 == 0 { 1.0 } else { 0.8 };
            [r * a.cos(), r * a.sin(), 0.0]
        })
        .collect();
    let normals = [[0.0f32, 0.0, 1.0]; 3];
    let shapes: Vec<(&str, Shape<'_>)> = vec![
        (
            "sphere",
            Shape::Sphere(Sphere {
                center: [0.0, 0.0, 0.0],
                radius: 1.0,
            }),
        ),
        ("triangle", Shape::Polygon(Polygon { vertices: &tri })),
        ("quad", Shape::Polygon(Polygon { vertices: &quad })),
        ("polygon48", Shape::Polygon(Polygon { vertices: &gear })),
        (
            "patch",
            Shape::Patch(Patch {
                vertices: &tri,
                normals: &normals,
            }),
        ),
        (
            "cone",
            Shape::Cone(Cone {
                base: [0.0, 0.0, -1.0],
                base_radius: 1.0,
                apex: [0.0, 0.0, 1.0],
                apex_radius: 0.5,
            }),
        ),
    ];
    let (o, d) = ray();
    let q64 = RayQ::<f64>::from_vec3(o, d);
    let q32 = q64.cast::<f32>();
    let mut g = c.benchmark_group("intersect");
    for (name, s) in &shapes {
        let bbox = s.bounds();
        let prep = s.prepare();
        g.bench_with_input(BenchmarkId::new("double", name), s, |b, s| {
            b.iter(|| {
                black_box(s.intersect(prep.as_ref(), &bbox, black_box(&q64), 0.0, f64::INFINITY))
            })
        });
        g.bench_with_input(BenchmarkId::new("single", name), s, |b, s| {
            b.iter(|| {
                black_box(s.intersect(prep.as_ref(), &bbox, black_box(&q32), 0.0, f32::INFINITY))
            })
        });
    }
    g.finish();
}

fn dda_steps(c: &mut Criterion) {
    let spec = GridSpec::new(
        &Aabb {
            min: [-1.0; 3],
            max: [1.0; 3],
        },
        [64, 64, 64],
    );
    let o = Vec3::new(-1.5, -1.2, -1.3);
    let d = Vec3::new(1.0, 0.9, 0.8).normalize();
    let inv = Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
    let start = Dda::start(&spec, o, d, inv, 0.0, f64::INFINITY).expect("the ray meets the grid");
    let mut walk = start;
    let mut g = c.benchmark_group("dda");
    g.throughput(Throughput::Elements(1));
    g.bench_function("advance", |b| {
        b.iter(|| {
            if !walk.advance() {
                walk = start;
            }
            black_box(walk.index)
        })
    });
    g.bench_function("start", |b| {
        b.iter(|| black_box(Dda::start(&spec, black_box(o), d, inv, 0.0, f64::INFINITY)))
    });
    g.finish();
}

fn block_decoding(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("temporary directory");
    let mut g = c.benchmark_group("database");
    for (name, compression) in [("plain", Compression::None), ("zstd", Compression::Zstd(3))] {
        let path = dir.path().join(format!("tetra7-{name}.sdb"));
        let mut w = DbWriter::create(&path, compression).expect("create");
        SceneSource::Spd {
            scene: SpdScene::Tetra,
            size: 7,
        }
        .stream_into(&mut w, &NoProgress)
        .expect("generate");
        w.finish().expect("finish");
        let db = Database::open(&path).expect("open");
        g.throughput(Throughput::Elements(db.object_count()));
        g.bench_function(BenchmarkId::new("scan_objects", name), |b| {
            b.iter(|| {
                let mut scan = db.scan().expect("scan");
                let mut n = 0u64;
                while let Some(block) = scan.next_block().expect("block") {
                    for o in block.objects() {
                        n += o.bbox.min[0].to_bits() as u64 & 1;
                    }
                }
                black_box(n)
            })
        });
    }
    g.finish();
}

/// A frame's corners made pixels (the mean of four, in f64), as every
/// image is written: what a coordinator does per pixel at a job's end.
fn frame_to_pixels(c: &mut Criterion) {
    let mut frame = sray_engine::render::Frame::new(1024, 1024);
    for (i, s) in frame.slots.iter_mut().enumerate() {
        *s = sray_engine::render::to_fixed([(i % 1031) as f32 / 1031.0, 0.5, 0.25]);
    }
    let mut g = c.benchmark_group("frame");
    g.throughput(Throughput::Elements(1024 * 1024));
    let mut row = vec![[0.0; 3]; 1024];
    g.bench_function("corners to pixels, 1024x1024", |b| {
        b.iter(|| {
            for y in 0..1024 {
                frame.pixel_row(y, &mut row);
                black_box(&row);
            }
        })
    });
    g.finish();
}

criterion_group!(
    benches,
    intersection_tests,
    dda_steps,
    block_decoding,
    frame_to_pixels
);
criterion_main!(benches);

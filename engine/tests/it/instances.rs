//! Models stored once and placed by instances, against the same scene
//! written as copies: a model of smooth and flat triangles in two
//! materials, placed by rotations, non-uniform scales, a mirror, a shear
//! and twice at exactly the same place (ties), the whole scene far from
//! the origin (where placing a corner in `f32` rounds most), written as
//! instances and as the copies those instances stand for.

use crate::common::{bf_render, bf_render_with, df_render};
use glam::{DAffine3, DMat3, DQuat, DVec3};
use sray_engine::bf::{BfOptions, ModelHolding, Shading, StoreNumber};
use sray_engine::models::{place_normal, place_point};
use sray_engine::progress::NoProgress;
use sray_engine::render::{Precision, RenderOptions};
use sray_engine::scene::{Light, Material, SceneSink, View};
use sray_engine::sdb::{Compression, Database, DbWriter};
use sray_engine::shapes::{Patch, Polygon, Shape, Sphere};
use std::path::Path;

/// Far from the origin: a corner placed there rounds to 2^-12.
const FAR: f64 = 3000.0;

/// A model's triangles: corners, and normals for the smooth ones, with
/// their material (0 or 1).
struct Tri {
    v: [[f32; 3]; 3],
    n: Option<[[f32; 3]; 3]>,
    material: usize,
}

fn model() -> Vec<Tri> {
    let mut x: u64 = 11;
    let mut next = || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((x >> 11) as f64 / (1u64 << 53) as f64) as f32
    };
    let mut out = Vec::new();
    // A bumpy sheet of smooth triangles (shared edges), and loose flat
    // triangles above it.
    let h = |i: usize, j: usize| 0.15 * ((i as f32 * 0.9).sin() + (j as f32 * 1.3).cos());
    let n = 12;
    for i in 0..n {
        for j in 0..n {
            let p = |a: usize, b: usize| [a as f32 / n as f32, h(a, b), b as f32 / n as f32];
            let nrm = |a: usize, b: usize| [0.1 * a as f32 - 0.5, 1.0, 0.05 * b as f32];
            for (a, b, c) in [
                ((i, j), (i + 1, j), (i, j + 1)),
                ((i + 1, j), (i + 1, j + 1), (i, j + 1)),
            ] {
                out.push(Tri {
                    v: [p(a.0, a.1), p(b.0, b.1), p(c.0, c.1)],
                    n: Some([nrm(a.0, a.1), nrm(b.0, b.1), nrm(c.0, c.1)]),
                    material: 0,
                });
            }
        }
    }
    for _ in 0..150 {
        let c = [next(), 0.3 + 0.5 * next(), next()];
        let v = std::array::from_fn(|_| std::array::from_fn(|k| c[k] + 0.12 * (next() - 0.5)));
        out.push(Tri {
            v,
            n: None,
            material: 1,
        });
    }
    out
}

fn placements() -> Vec<DAffine3> {
    let at = |x: f64, z: f64| DVec3::new(FAR + x, 0.0, z);
    let mut p = vec![
        DAffine3::from_translation(at(0.0, 0.0)),
        DAffine3::from_scale_rotation_translation(
            DVec3::new(1.3, 0.7, 0.9),
            DQuat::from_rotation_y(0.7),
            at(1.6, 0.2),
        ),
        // A mirror.
        DAffine3::from_scale_rotation_translation(
            DVec3::new(-1.0, 1.0, 1.0),
            DQuat::from_rotation_y(-0.4),
            at(-0.4, 1.6),
        ),
        // A shear.
        DAffine3 {
            matrix3: DMat3::from_cols(
                DVec3::new(1.0, 0.0, 0.0),
                DVec3::new(0.4, 1.0, 0.0),
                DVec3::new(0.0, 0.3, 1.2),
            ),
            translation: at(1.5, 1.7),
        },
    ];
    // The same place twice: every hit on the two is a tie.
    p.push(p[1]);
    p
}

fn header(w: &mut dyn SceneSink) {
    w.view(&View {
        from: [FAR + 0.9, 2.6, 4.6],
        at: [FAR + 0.9, 0.2, 0.9],
        up: [0.0, 1.0, 0.0],
        angle: 45.0,
        hither: 0.01,
        resolution: [48, 48],
    })
    .unwrap();
    w.background([0.1, 0.1, 0.2]).unwrap();
    for position in [[FAR + 3.0, 6.0, 4.0], [FAR - 2.0, 4.0, 1.0]] {
        w.light(&Light {
            photometric: None,
            position,
            color: None,
        })
        .unwrap();
    }
}

const MATERIALS: [Material; 2] = [
    Material {
        pbr: None,
        texture: None,
        maps: sray_engine::scene::Maps::NONE,
        color: [0.8, 0.5, 0.3],
        kd: 0.7,
        ks: 0.3,
        shine: 20.0,
        t: 0.0,
        ior: 1.0,
    },
    Material {
        pbr: None,
        texture: None,
        maps: sray_engine::scene::Maps::NONE,
        color: [0.3, 0.6, 0.9],
        kd: 0.5,
        ks: 0.2,
        shine: 8.0,
        t: 0.3,
        ior: 1.3,
    },
];

/// Triangles of `tris` placed by `m` (the identity: as they are) into `w`.
fn emit(w: &mut dyn SceneSink, tris: &[Tri], m: Option<&DAffine3>) {
    let nm = m.map(|m| m.matrix3.inverse().transpose());
    let mut current = usize::MAX;
    for t in tris {
        if t.material != current {
            w.material(&MATERIALS[t.material]).unwrap();
            current = t.material;
        }
        let v = t.v.map(|p| m.map_or(p, |m| place_point(m, p)));
        match t.n {
            Some(n) => {
                let n = n.map(|x| nm.as_ref().map_or(x, |nm| place_normal(nm, x)));
                w.object(&Shape::Patch(Patch {
                    vertices: &v,
                    normals: &n,
                }))
                .unwrap()
            }
            None => w.object(&Shape::Polygon(Polygon { vertices: &v })).unwrap(),
        }
    }
}

/// The scene as instances (a ground sphere, then the model's placements)
/// or as copies.
fn write(path: &Path, instances: bool) -> Database {
    write_padded(path, instances, 0)
}

/// [`write`], with `pad` small spheres deep inside the floor's sphere (out
/// of every ray's reach) after each placement, so that the placements lie
/// in different blocks; with padding, each placement is made four times
/// (coincident instances: many per ray).
fn write_padded(path: &Path, instances: bool, pad: usize) -> Database {
    let tris = model();
    let mut w = DbWriter::create(path, Compression::None).unwrap();
    header(&mut w);
    let model = instances.then(|| {
        w.begin_model().unwrap();
        emit(&mut w, &tris, None);
        w.end_model().unwrap()
    });
    w.material(&MATERIALS[0]).unwrap();
    w.object(&Shape::Sphere(Sphere {
        center: [(FAR + 0.8) as f32, -100.0, 0.8],
        radius: 99.9,
    }))
    .unwrap();
    let times = if pad > 0 { 4 } else { 1 };
    for p in placements()
        .into_iter()
        .flat_map(|p| std::iter::repeat_n(p, times))
    {
        match &model {
            Some(m) => w.instance(m.index, &p).unwrap(),
            None => emit(&mut w, &tris, Some(&p)),
        }
        for k in 0..pad {
            w.object(&Shape::Sphere(Sphere {
                center: [
                    (FAR + 0.8) as f32 + (k % 50) as f32,
                    -150.0,
                    (k / 50) as f32,
                ],
                radius: 0.1,
            }))
            .unwrap();
        }
    }
    w.finish().unwrap();
    Database::open(path).unwrap()
}

#[test]
fn instances_render_as_the_copies_they_stand_for() {
    let dir = tempfile::tempdir().unwrap();
    let inst = write(&dir.path().join("inst.sdb"), true);
    let copies = write(&dir.path().join("copies.sdb"), false);
    assert_eq!(inst.version(), 5);
    assert_eq!(inst.models().len(), 1);
    assert_eq!(inst.object_count(), 1 + placements().len() as u64);
    assert_eq!(
        copies.object_count(),
        1 + (placements().len() * model().len()) as u64
    );
    for precision in [Precision::Double, Precision::Single] {
        let o = RenderOptions {
            width: 48,
            height: 48,
            max_depth: 3,
            precision,
            ..Default::default()
        };
        let (a, sa) = df_render(&inst, &o);
        let (b, sb) = df_render(&copies, &o);
        assert!(
            a == b,
            "{precision:?}: depth-first, instances and copies differ"
        );
        assert_eq!(sa.rays, sb.rays, "{precision:?}");
        assert!(sa.rays.eye_hit_rays > 500, "{:?}", sa.rays);
        assert!(
            sa.intersection_tests_by_kind.0[4] > 0,
            "no instance was tested"
        );
        // Breadth-first under a budget that takes several passes.
        for (memory, shading) in [(6 << 20, Shading::Carry), (6 << 20, Shading::Join)] {
            let (c, sc) = bf_render_with(&inst, &o, StoreNumber::Adaptive, memory, shading);
            assert!(c == a, "{precision:?} {shading:?}: breadth-first differs");
            assert_eq!(sc.rays, sa.rays, "{precision:?} {shading:?}");
        }
        let (d, _) = bf_render(&copies, &o, StoreNumber::Fixed(2), 6 << 20);
        assert!(d == a, "{precision:?}: breadth-first copies differ");
    }
}

/// Breadth-first with the models read by each pass that needs them (not
/// held): the same image and counts as held, in both shading modes.
#[test]
fn models_read_per_pass_give_the_same_image_as_models_held() {
    let dir = tempfile::tempdir().unwrap();
    let inst = write(&dir.path().join("inst.sdb"), true);
    let o = RenderOptions {
        width: 48,
        height: 48,
        max_depth: 3,
        ..Default::default()
    };
    let (want, sw) = df_render(&inst, &o);
    for shading in [Shading::Carry, Shading::Join] {
        for models in [ModelHolding::PerPass, ModelHolding::Held] {
            let b = BfOptions {
                memory: 6 << 20,
                store: StoreNumber::Adaptive,
                spill_dir: None,
                shading,
                models,
            };
            let out = sray_engine::bf::render(&inst, &o, &b, &NoProgress).unwrap();
            assert!(
                out.frame.to_rgb8() == want,
                "{shading:?} {models:?}: the image differs from depth-first"
            );
            assert_eq!(out.stats.rays, sw.rays, "{shading:?} {models:?}");
            let d = out.stats.details.unwrap();
            let reads = d["model_reads"].as_u64().unwrap();
            match models {
                ModelHolding::PerPass => {
                    assert_eq!(d["models"], "per-pass", "{d}");
                    // A read per pass (and per shading set with Join).
                    assert!(reads >= d["db_scans"].as_u64().unwrap() - 1, "{d}");
                }
                _ => {
                    assert_eq!(d["models"], "held", "{d}");
                    assert_eq!(reads, 0, "{d}");
                }
            }
        }
    }
    // Pairs past their share of a small budget are tested mid-pass, after
    // the block that passed it: the models are read more often than once
    // a pass; the image is the one of the models held.
    let padded = write_padded(&dir.path().join("padded.sdb"), true, 3000);
    assert!(padded.block_count() > placements().len() as u64);
    let o = RenderOptions {
        width: 96,
        height: 96,
        ..o
    };
    let (want, _) = df_render(&padded, &o);
    for shading in [Shading::Carry, Shading::Join] {
        let b = BfOptions {
            memory: 6 << 20,
            store: StoreNumber::Adaptive,
            spill_dir: None,
            shading,
            models: ModelHolding::PerPass,
        };
        let out = sray_engine::bf::render(&padded, &o, &b, &NoProgress).unwrap();
        assert!(
            out.frame.to_rgb8() == want,
            "{shading:?}: the image differs"
        );
        let d = out.stats.details.unwrap();
        let (reads, scans) = (d["model_reads"].as_u64(), d["db_scans"].as_u64());
        assert!(
            reads > scans,
            "{shading:?}: {reads:?} model reads, {scans:?} scans"
        );
    }
}

#[test]
fn models_are_refused_where_they_cannot_be() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.sdb");
    let mut w = DbWriter::create(&path, Compression::None).unwrap();
    header(&mut w);
    let e = w.instance(3, &DAffine3::IDENTITY).unwrap_err().to_string();
    assert!(e.contains("model 3"), "{e}");
    w.begin_model().unwrap();
    let e = w.begin_model().unwrap_err().to_string();
    assert!(e.contains("inside another"), "{e}");
    let e = w
        .object(&Shape::Sphere(Sphere {
            center: [0.0; 3],
            radius: 1.0,
        }))
        .unwrap_err()
        .to_string();
    assert!(e.contains("triangles only"), "{e}");
    emit(&mut w, &model()[..4], None);
    let e = w.instance(0, &DAffine3::IDENTITY).unwrap_err().to_string();
    assert!(e.contains("do not nest"), "{e}");
    let m = w.end_model().unwrap();
    let e = w.end_model().unwrap_err().to_string();
    assert!(e.contains("not begun"), "{e}");
    let flat = DAffine3::from_scale(DVec3::new(1.0, 0.0, 1.0));
    let e = w.instance(m.index, &flat).unwrap_err().to_string();
    assert!(e.contains("cannot be inverted"), "{e}");
    let huge = DAffine3::from_scale(DVec3::splat(1e40));
    let e = w.instance(m.index, &huge).unwrap_err().to_string();
    assert!(e.contains("single precision"), "{e}");
    w.instance(m.index, &DAffine3::IDENTITY).unwrap();
    w.begin_model().unwrap();
    let e = w.finish().unwrap_err().to_string();
    assert!(e.contains("not ended"), "{e}");
    assert!(!path.exists(), "an unfinished database was left behind");
}

/// Coincident triangles of different instances, and of an instance and
/// a plain object: every tie goes as it goes between the copies (by
/// object, then by the model's triangle), which the materials show.
#[test]
fn ties_between_instances_go_as_between_copies() {
    // A model of two unit squares side by side, of two materials; A
    // places it as it is, B one unit along x, so that B's first square
    // lies exactly on A's second; a plain square after them lies on A's
    // first.
    let square = |x: f32, material: usize| -> Vec<Tri> {
        let v = |a: f32, b: f32| [x + a, 0.0, b];
        vec![
            Tri {
                v: [v(0.0, 0.0), v(1.0, 0.0), v(1.0, 1.0)],
                n: None,
                material,
            },
            Tri {
                v: [v(0.0, 0.0), v(1.0, 1.0), v(0.0, 1.0)],
                n: None,
                material,
            },
        ]
    };
    let tris: Vec<Tri> = square(0.0, 0).into_iter().chain(square(1.0, 1)).collect();
    let at = [DAffine3::IDENTITY, DAffine3::from_translation(DVec3::X)];
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, instances: bool| {
        let path = dir.path().join(name);
        let mut w = DbWriter::create(&path, Compression::None).unwrap();
        w.view(&View {
            from: [1.5, 4.0, 0.5],
            at: [1.5, 0.0, 0.5],
            up: [0.0, 0.0, 1.0],
            angle: 60.0,
            hither: 0.01,
            resolution: [32, 32],
        })
        .unwrap();
        w.light(&Light {
            photometric: None,
            position: [1.5, 5.0, 0.5],
            color: None,
        })
        .unwrap();
        let model = instances.then(|| {
            w.begin_model().unwrap();
            emit(&mut w, &tris, None);
            w.end_model().unwrap()
        });
        for p in &at {
            match &model {
                Some(m) => w.instance(m.index, p).unwrap(),
                None => emit(&mut w, &tris, Some(p)),
            }
        }
        w.material(&Material {
            pbr: None,
            texture: None,
            maps: sray_engine::scene::Maps::NONE,
            color: [0.1, 0.9, 0.1],
            ..MATERIALS[0]
        })
        .unwrap();
        for t in square(0.0, 0) {
            w.object(&Shape::Polygon(Polygon { vertices: &t.v }))
                .unwrap();
        }
        w.finish().unwrap();
        Database::open(&path).unwrap()
    };
    let inst = write("inst.sdb", true);
    let copies = write("copies.sdb", false);
    let o = RenderOptions {
        width: 32,
        height: 32,
        max_depth: 1,
        ..Default::default()
    };
    let (a, _) = df_render(&inst, &o);
    let (b, _) = df_render(&copies, &o);
    assert!(
        a == b,
        "ties between instances go otherwise than between copies"
    );
    let (c, _) = bf_render(&inst, &o, StoreNumber::Fixed(1), 6 << 20);
    assert!(c == a, "breadth-first decides the ties otherwise");
    // Both materials of the model show, and the plain square's green
    // does not (it lies under A's first square, which wins the tie).
    let colors: std::collections::HashSet<[u8; 3]> =
        a.chunks(3).map(|p| [p[0], p[1], p[2]]).collect();
    assert!(
        colors
            .iter()
            .map(|c| c.map(u32::from))
            .all(|c| !(c[1] > 2 * c[0] && c[1] > 2 * c[2])),
        "{colors:?}"
    );
    assert!(colors.iter().any(|c| c[2] > c[0]), "{colors:?}");
    assert!(colors.iter().any(|c| c[0] > c[2]), "{colors:?}");
}

/// An instance record naming a model the file does not have is an error
/// of the file (reading it, verifying it, or rendering it either way),
/// not an instance never hit.
#[test]
fn an_instance_of_a_missing_model_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.sdb");
    let mut w = DbWriter::create(&path, Compression::None).unwrap();
    header(&mut w);
    w.begin_model().unwrap();
    emit(&mut w, &model()[..4], None);
    let m = w.end_model().unwrap();
    w.instance(
        m.index,
        &DAffine3::from_translation(DVec3::new(FAR, 0.0, 0.0)),
    )
    .unwrap();
    // Written as a plain object, past the writer's checks.
    let words = sray_engine::shapes::instance_words(3, &m.bbox, &DAffine3::IDENTITY);
    w.object(&Shape::Instance(sray_engine::shapes::Instance {
        words: &words,
    }))
    .unwrap();
    w.finish().unwrap();
    let db = Database::open(&path).unwrap();
    let o = RenderOptions {
        width: 8,
        height: 8,
        ..Default::default()
    };
    let e = sray_engine::df::render(&db, &o, &NoProgress)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("model 3 of 1"), "{e}");
    for models in [ModelHolding::Held, ModelHolding::PerPass] {
        let b = BfOptions {
            memory: 6 << 20,
            store: StoreNumber::Adaptive,
            spill_dir: None,
            shading: Shading::Carry,
            models,
        };
        let db = Database::open(&path).unwrap();
        let e = sray_engine::bf::render(&db, &o, &b, &NoProgress)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("model 3 of 1"), "{models:?}: {e}");
    }
}

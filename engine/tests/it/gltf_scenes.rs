//! glTF 2.0 scenes made by trimesh (tests/fixtures/gltf/make.py): node
//! transforms, the file's camera and light, a mesh placed four times, and
//! a clear error, never a panic, for bad input.

use sray_engine::Error;
use sray_engine::progress::NoProgress;
use sray_engine::scene::recorder::{Event, Recorder};
use sray_engine::source::SceneSource;
use std::path::{Path, PathBuf};

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/gltf")
}

fn record(path: &Path) -> Result<Recorder, Error> {
    let mut r = Recorder::default();
    SceneSource::parse(path.to_str().unwrap())?.stream_into(&mut r, &NoProgress)?;
    Ok(r)
}

/// Each object's corners, in `f64`.
fn corners(r: &Recorder) -> Vec<Vec<[f64; 3]>> {
    r.objects()
        .map(|o| {
            let n = o.numbers();
            (0..3)
                .map(|i| [0, 1, 2].map(|a| n[3 * i + a] as f64))
                .collect()
        })
        .collect()
}

/// The placements make.py gives the four nodes: (x, z, degrees about y,
/// scale).
const PLACEMENTS: [(f64, f64, f64, f64); 4] = [
    (0.0, 0.0, 0.0, 1.0),
    (2.5, 0.0, 45.0, 0.8),
    (0.0, 2.5, 90.0, 1.2),
    (2.5, 2.5, 180.0, 1.0),
];

#[test]
fn each_node_places_the_mesh_with_its_transform() {
    let r = record(&fixtures().join("spot4.glb")).unwrap();
    let all = corners(&r);
    assert_eq!(all.len() % 4, 0);
    let per = all.len() / 4;
    assert!(per > 5000, "{per} triangles per placement");
    // The first node's transform is the identity: its triangles are the
    // mesh's own; every other node's are them rotated, scaled, moved.
    for (k, &(x, z, deg, s)) in PLACEMENTS.iter().enumerate() {
        let (sin, cos) = deg.to_radians().sin_cos();
        for t in 0..per {
            for (p, q) in all[t].iter().zip(&all[k * per + t]) {
                let want = [
                    s * (cos * p[0] + sin * p[2]) + x,
                    s * p[1],
                    s * (-sin * p[0] + cos * p[2]) + z,
                ];
                for a in 0..3 {
                    assert!(
                        (want[a] - q[a]).abs() <= 1e-5 * (1.0 + want[a].abs()),
                        "node {k}, triangle {t}: {q:?} is not {want:?}"
                    );
                }
            }
        }
    }
}

#[test]
fn a_mesh_placed_four_times_is_the_mesh_copied_four_times() {
    let a = record(&fixtures().join("spot4.glb")).unwrap();
    let b = record(&fixtures().join("spot4_copies.glb")).unwrap();
    assert!(a.objects().eq(b.objects()), "the scenes differ");
}

#[test]
fn the_files_camera_and_light_are_the_scenes() {
    let path = fixtures().join("spot4_light.gltf");
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let node = doc["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n.get("camera").is_some())
        .unwrap();
    let m: Vec<f64> = node["matrix"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let r = record(&path).unwrap();
    let views: Vec<_> = r
        .events
        .iter()
        .filter_map(|e| match e {
            Event::View(v) => Some(*v),
            _ => None,
        })
        .collect();
    assert_eq!(views.len(), 1);
    let v = views[0];
    for a in 0..3 {
        // The camera stands at the node's translation and looks down its
        // -z axis (the file keeps its matrices in single precision).
        assert!((v.from[a] - m[12 + a]).abs() < 1e-5, "{v:?}");
        assert!((v.at[a] - v.from[a] + m[8 + a]).abs() < 1e-5, "{v:?}");
    }
    assert!((v.angle - 45.0).abs() < 1e-4, "{}", v.angle);
    let lights: Vec<_> = r
        .events
        .iter()
        .filter_map(|e| match e {
            Event::Light(l) => Some(*l),
            _ => None,
        })
        .collect();
    assert_eq!(lights.len(), 1, "the file's light and no default ones");
    assert_eq!(lights[0].position, [1.0, 4.0, 3.0]);
    assert_eq!(lights[0].color, Some([1.0, 0.9, 0.8]));
    // The same scene as in the GLB.
    let glb = record(&fixtures().join("spot4.glb")).unwrap();
    assert!(glb.objects().eq(r.objects()));
}

/// Writes `doc` (edited) beside copies of the fixture's buffers.
fn edited(dir: &Path, name: &str, edit: impl Fn(&mut serde_json::Value)) -> PathBuf {
    let src = fixtures().join("spot4_light.gltf");
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&src).unwrap()).unwrap();
    for b in doc["buffers"].as_array().unwrap() {
        let uri = b["uri"].as_str().unwrap();
        std::fs::copy(fixtures().join(uri), dir.join(uri)).unwrap();
    }
    edit(&mut doc);
    let p = dir.join(name);
    std::fs::write(&p, serde_json::to_string(&doc).unwrap()).unwrap();
    p
}

fn error_of(path: &Path) -> String {
    match std::panic::catch_unwind(|| record(path)) {
        Ok(Err(e)) => e.to_string(),
        Ok(Ok(_)) => panic!("{} read without an error", path.display()),
        Err(_) => panic!("{} made the reader panic", path.display()),
    }
}

#[test]
fn bad_files_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases: Vec<(PathBuf, &str)> = vec![
        (
            edited(d, "long.gltf", |doc| {
                doc["accessors"][1]["count"] = serde_json::json!(1_000_000_000u64)
            }),
            "ends past",
        ),
        (
            edited(d, "cycle.gltf", |doc| {
                doc["nodes"][0]["children"] = serde_json::json!([1]);
                doc["nodes"][1]["children"] = serde_json::json!([0]);
            }),
            "cycle",
        ),
        (
            edited(d, "points.gltf", |doc| {
                doc["meshes"][0]["primitives"][0]["mode"] = serde_json::json!(0)
            }),
            "not supported",
        ),
        (
            edited(d, "far.gltf", |doc| {
                doc["nodes"][1]["matrix"][12] = serde_json::json!(1e39)
            }),
            "not a finite point",
        ),
        (
            edited(d, "index.gltf", |doc| {
                doc["accessors"][1]["count"] = serde_json::json!(3);
                doc["accessors"][2]["count"] = serde_json::json!(3)
            }),
            "past its",
        ),
        (
            // Each node the child of the two before it: no cycle, but the
            // placements double every other level.
            edited(d, "dag.gltf", |doc| {
                let n0 = doc["nodes"].as_array().unwrap().len();
                for k in 0..64 {
                    let children: Vec<usize> = [k + 1, k + 2]
                        .into_iter()
                        .filter(|&c| c < 64)
                        .map(|c| n0 + c)
                        .collect();
                    doc["nodes"]
                        .as_array_mut()
                        .unwrap()
                        .push(serde_json::json!({ "children": children }));
                }
                doc["scenes"][0]["nodes"]
                    .as_array_mut()
                    .unwrap()
                    .push(serde_json::json!(n0));
            }),
            "node graph places more than",
        ),
        (
            // A trillion zeros nothing in the file backs.
            edited(d, "zeros.gltf", |doc| {
                let a = &mut doc["accessors"][1];
                a.as_object_mut().unwrap().remove("bufferView");
                a["count"] = serde_json::json!(1_000_000_000_000u64);
                a["sparse"] = serde_json::json!({
                    "count": 1,
                    "indices": {"bufferView": 0, "componentType": 5125},
                    "values": {"bufferView": 0}
                });
            }),
            "without a buffer view",
        ),
        (
            edited(d, "draco.gltf", |doc| {
                doc["extensionsRequired"] = serde_json::json!(["KHR_draco_mesh_compression"])
            }),
            "compressed with KHR_draco_mesh_compression",
        ),
    ];
    // A document of two million empty nodes: 6 MB as text, a gigabyte
    // parsed, refused at 64 MiB before it is parsed.
    let p = edited(d, "objects.gltf", |doc| {
        let nodes = doc["nodes"].as_array_mut().unwrap();
        nodes.extend(std::iter::repeat_n(serde_json::json!({}), 2_000_000));
    });
    let e = read_error(&p, 64 << 20);
    assert!(e.contains("objects.gltf") && e.contains("parsed"), "{e}");
    // An extension required for appearance only is ignored (a warning):
    // the shapes are read.
    let p = edited(d, "transform.gltf", |doc| {
        doc["extensionsRequired"] = serde_json::json!(["KHR_texture_transform"])
    });
    let plain = record(&fixtures().join("spot4_light.gltf")).unwrap();
    assert!(record(&p).unwrap().objects().eq(plain.objects()));
    // Lines beside the triangles (a CAD file's edges) are skipped with a
    // warning; a file of nothing but points or lines is an error.
    let p = edited(d, "edges.gltf", |doc| {
        let mut lines = doc["meshes"][0]["primitives"][0].clone();
        lines["mode"] = serde_json::json!(1);
        doc["meshes"][0]["primitives"]
            .as_array_mut()
            .unwrap()
            .push(lines);
    });
    assert!(record(&p).unwrap().objects().eq(plain.objects()));
    let e = error_of(&edited(d, "points_only.gltf", |doc| {
        doc["meshes"][0]["primitives"][0]["mode"] = serde_json::json!(0)
    }));
    assert!(e.contains("no triangles"), "{e}");
    for (path, says) in &cases {
        let e = error_of(path);
        assert!(
            e.contains(path.file_name().unwrap().to_str().unwrap()),
            "{e}"
        );
        assert!(e.contains(says), "{}: {e}", path.display());
    }
    // A missing buffer file.
    let lonely = tempfile::tempdir().unwrap();
    let p = lonely.path().join("lonely.gltf");
    std::fs::copy(fixtures().join("spot4_light.gltf"), &p).unwrap();
    let e = error_of(&p);
    assert!(e.contains("buffer"), "{e}");
    // Every truncation of a GLB.
    let glb = std::fs::read(fixtures().join("spot4.glb")).unwrap();
    for cut in (0..glb.len()).step_by(997).chain([glb.len() - 1]) {
        let p = d.join("cut.glb");
        std::fs::write(&p, &glb[..cut]).unwrap();
        if SceneSource::parse(p.to_str().unwrap()).is_ok() {
            let _ = error_of(&p);
        }
    }
}

/// Inputs the fuzzer found (fuzz/fuzz_targets/gltf.rs) that once made the
/// reader panic.
#[test]
fn what_the_fuzzer_found_is_an_error() {
    let dir = fixtures().join("bad");
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        let e = error_of(&p);
        assert!(e.contains(p.file_name().unwrap().to_str().unwrap()), "{e}");
    }
}

/// A node with `EXT_mesh_gpu_instancing` draws its mesh once per listed
/// copy (translation, rotation, scale, times the node's transform), and
/// not itself.
#[test]
fn gpu_instancing_draws_each_listed_copy() {
    let dir = tempfile::tempdir().unwrap();
    // Two copies of node 0's mesh: in place, and turned half a turn about
    // y (the quaternion (0, 1, 0, 0)) and moved 5 along x.
    let mut bytes = Vec::new();
    for v in [
        0f32, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0,
    ] {
        bytes.extend(v.to_le_bytes());
    }
    std::fs::write(dir.path().join("copies.bin"), &bytes).unwrap();
    let path = edited(dir.path(), "instanced.gltf", |doc| {
        let buffers = doc["buffers"].as_array_mut().unwrap();
        buffers.push(serde_json::json!({"byteLength": bytes.len(), "uri": "copies.bin"}));
        let b = buffers.len() - 1;
        let views = doc["bufferViews"].as_array_mut().unwrap();
        views.push(serde_json::json!({"buffer": b, "byteOffset": 0, "byteLength": 24}));
        views.push(serde_json::json!({"buffer": b, "byteOffset": 24, "byteLength": 32}));
        let v = views.len() - 2;
        let acc = doc["accessors"].as_array_mut().unwrap();
        acc.push(
            serde_json::json!({"bufferView": v, "componentType": 5126, "count": 2, "type": "VEC3"}),
        );
        acc.push(serde_json::json!({"bufferView": v + 1, "componentType": 5126, "count": 2, "type": "VEC4"}));
        let a = acc.len() - 2;
        doc["nodes"][0]["extensions"] = serde_json::json!({
            "EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": a, "ROTATION": a + 1}}
        });
        doc["extensionsUsed"]
            .as_array_mut()
            .unwrap()
            .push(serde_json::json!("EXT_mesh_gpu_instancing"));
    });
    let plain = corners(&record(&fixtures().join("spot4_light.gltf")).unwrap());
    let got = corners(&record(&path).unwrap());
    let per = plain.len() / 4;
    assert_eq!(
        got.len(),
        5 * per,
        "two copies of node 0 and the three others"
    );
    for t in 0..per {
        assert_eq!(got[t], plain[t], "the first copy is the node itself");
        for (p, q) in plain[t].iter().zip(&got[per + t]) {
            // Half a turn about y, then 5 along x.
            let want = [5.0 - p[0], p[1], -p[2]];
            for a in 0..3 {
                assert!(
                    (want[a] - q[a]).abs() <= 1e-5 * (1.0 + want[a].abs()),
                    "{q:?} {want:?}"
                );
            }
        }
    }
    assert_eq!(
        got[2 * per..],
        plain[per..],
        "the other nodes are as they were"
    );
    // The rotations as normalized shorts (32767 is 1) give the same.
    let mut shorts = bytes[..24].to_vec();
    for q in [0i16, 0, 0, 32767, 0, 32767, 0, 0] {
        shorts.extend(q.to_le_bytes());
    }
    std::fs::write(dir.path().join("shorts.bin"), &shorts).unwrap();
    let short_path = edited(dir.path(), "shorts.gltf", |doc| {
        let text = std::fs::read_to_string(&path).unwrap();
        *doc = serde_json::from_str(&text).unwrap();
        let b = doc["buffers"].as_array().unwrap().len() - 1;
        doc["buffers"][b] = serde_json::json!({"byteLength": shorts.len(), "uri": "shorts.bin"});
        let v = doc["bufferViews"].as_array().unwrap().len() - 1;
        doc["bufferViews"][v]["byteLength"] = serde_json::json!(16);
        let a = doc["accessors"].as_array().unwrap().len() - 1;
        doc["accessors"][a]["componentType"] = serde_json::json!(5122);
        doc["accessors"][a]["normalized"] = serde_json::json!(true);
    });
    assert_eq!(corners(&record(&short_path).unwrap()), got);

    // Written to a database, the mesh is one model placed five times.
    let db = dir.path().join("instanced.sdb");
    crate::common::write_converted(
        &SceneSource::parse(path.to_str().unwrap()).unwrap(),
        &db,
        sray_engine::sdb::Compression::None,
        true,
    );
    let db = sray_engine::sdb::Database::open(&db).unwrap();
    assert_eq!(db.models().len(), 1);
    assert_eq!(db.counts().get(sray_engine::shapes::ShapeKind::Instance), 5);
    assert_eq!(db.object_count(), 5);
}

/// Reads `spot4.glb` from memory or from a file at `memory` bytes of
/// budget.
fn spot4_within(memory: u64, from_file: Option<&Path>) -> Result<Recorder, Error> {
    let path = fixtures().join("spot4.glb");
    let opts = sray_engine::mesh::MeshOptions {
        memory,
        spill_dir: None,
        camera_index: None,
    };
    let mut r = Recorder::default();
    match from_file {
        Some(p) => sray_engine::mesh::gltf_scene::read_gltf(p, &mut r, &NoProgress, &opts)?,
        None => sray_engine::mesh::gltf_scene::read_gltf_bytes(
            &std::fs::read(&path).unwrap(),
            &path,
            None,
            &opts,
            &mut r,
            &NoProgress,
        )?,
    };
    Ok(r)
}

/// A glTF file's buffers are read by offset, not whole: a budget of half
/// the file (too small to hold one primitive's vertices, which are then
/// read by index) gives the same scene, from memory, from the
/// file and from a gzip-compressed file.
#[test]
fn a_gltf_file_larger_than_the_budget_converts_within_it() {
    let path = fixtures().join("spot4.glb");
    let len = std::fs::metadata(&path).unwrap().len();
    let whole = spot4_within(1 << 30, None).unwrap();
    assert!(whole.objects().count() > 20_000);
    let dir = tempfile::tempdir().unwrap();
    let gz = dir.path().join("spot4.glb.gz");
    let mut enc = flate2::write::GzEncoder::new(
        std::fs::File::create(&gz).unwrap(),
        flate2::Compression::fast(),
    );
    std::io::Write::write_all(&mut enc, &std::fs::read(&path).unwrap()).unwrap();
    enc.finish().unwrap();
    let small = len / 2;
    for from in [None, Some(path.as_path()), Some(gz.as_path())] {
        let r = spot4_within(small, from).unwrap();
        assert!(
            whole.objects().eq(r.objects()),
            "{from:?}: the scenes differ"
        );
    }
    // The document itself must fit in a quarter of the budget.
    let e = spot4_within(64, None).unwrap_err().to_string();
    assert!(
        e.contains("spot4.glb") && e.contains("JSON document"),
        "{e}"
    );
}

/// Buffers embedded as data URIs are held with the document: read like
/// external ones, refused when they pass the document's share.
#[test]
fn data_uri_buffers_read_as_files_do_within_the_budget() {
    use base64::Engine as _;
    let dir = tempfile::tempdir().unwrap();
    let p = edited(dir.path(), "embedded.gltf", |doc| {
        for b in doc["buffers"].as_array_mut().unwrap() {
            let bytes = std::fs::read(fixtures().join(b["uri"].as_str().unwrap())).unwrap();
            b["uri"] = serde_json::json!(format!(
                "data:application/octet-stream;base64,{}",
                base64::engine::general_purpose::STANDARD.encode(bytes)
            ));
        }
    });
    let plain = record(&fixtures().join("spot4_light.gltf")).unwrap();
    assert!(record(&p).unwrap().objects().eq(plain.objects()));
    let len = std::fs::metadata(&p).unwrap().len();
    let e = read_error(&p, 4 * len + len / 2);
    assert!(
        e.contains("embedded.gltf") && e.contains("data URIs"),
        "{e}"
    );
}

/// A sparse positions accessor: vertex 0 moved to (10, 10, 10) by a
/// sparse substitution is where every triangle using it finds it; a
/// sparse block past its buffer is an error.
#[test]
fn sparse_accessors_replace_the_listed_elements() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = Vec::new();
    bytes.extend(0u16.to_le_bytes());
    bytes.extend([0u8; 2]);
    for v in [10f32, 10.0, 10.0] {
        bytes.extend(v.to_le_bytes());
    }
    std::fs::write(dir.path().join("sparse.bin"), &bytes).unwrap();
    let sparse = |value_len: usize| {
        move |doc: &mut serde_json::Value| {
            let buffers = doc["buffers"].as_array_mut().unwrap();
            buffers.push(serde_json::json!({"byteLength": 16, "uri": "sparse.bin"}));
            let b = buffers.len() - 1;
            let views = doc["bufferViews"].as_array_mut().unwrap();
            views.push(serde_json::json!({"buffer": b, "byteOffset": 0, "byteLength": 2}));
            views.push(serde_json::json!({"buffer": b, "byteOffset": 4, "byteLength": value_len}));
            let v = views.len() - 2;
            doc["accessors"][1]["sparse"] = serde_json::json!({
                "count": 1,
                "indices": {"bufferView": v, "componentType": 5123},
                "values": {"bufferView": v + 1}
            });
        }
    };
    let plain = corners(&record(&fixtures().join("spot4_light.gltf")).unwrap());
    let got = corners(&record(&edited(dir.path(), "sparse.gltf", sparse(12))).unwrap());
    assert_eq!(got.len(), plain.len());
    let moved = got
        .iter()
        .flatten()
        .filter(|c| **c == [10.0, 10.0, 10.0])
        .count();
    assert!(moved > 0, "no corner was moved");
    let differ = got.iter().zip(&plain).filter(|(a, b)| a != b).count();
    // Every node places the mesh, so each triangle using vertex 0 moves
    // in the first placement (the identity) to the point itself.
    assert!(
        differ >= moved,
        "{differ} triangles differ, {moved} corners moved"
    );
    let e = error_of(&edited(dir.path(), "short.gltf", sparse(8)));
    assert!(e.contains("sparse values"), "{e}");
}

/// The error reading the glTF at `p` within `memory` bytes gives.
fn read_error(p: &Path, memory: u64) -> String {
    let opts = sray_engine::mesh::MeshOptions {
        memory,
        spill_dir: None,
        camera_index: None,
    };
    sray_engine::mesh::gltf_scene::read_gltf(p, &mut Recorder::default(), &NoProgress, &opts)
        .unwrap_err()
        .to_string()
}

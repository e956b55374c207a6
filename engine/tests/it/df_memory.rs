//! What the depth-first tracer holds for a scene: meshes as shared
//! corners and one-byte indices, a voxel start only where a voxel lists
//! something. Counted by the structures themselves (peak memory is
//! measured in BENCHMARKS.md), on real meshes no one here wrote and on
//! SPD meshes, so that a layout that quietly grows is caught.

use crate::common;
use sray_engine::df::DfScene;
use sray_engine::objects::ObjectStore;
use sray_engine::progress::NoProgress;
use sray_engine::render::RenderOptions;
use sray_engine::sdb::{Compression, Database};
use sray_engine::source::SceneSource;
use sray_engine::spd::SpdScene;

#[test]
fn meshes_take_few_bytes_per_triangle_in_memory() {
    let dir = tempfile::tempdir().unwrap();
    // Bounds a little above what each takes today (small meshes pay more
    // for their grids: their triangles are larger against the voxels); a
    // mesh with a normal per vertex holds twice the numbers per corner.
    let mut sources: Vec<(String, SceneSource, f64)> = vec![
        (
            "tetra6".into(),
            SceneSource::Spd {
                scene: SpdScene::Tetra,
                size: 6,
            },
            40.0,
        ),
        (
            "mount6".into(),
            SceneSource::Spd {
                scene: SpdScene::Mount,
                size: 6,
            },
            36.0,
        ),
    ];
    if let Some(m) = common::shared_meshes() {
        for (f, most) in [
            ("dragon_vrip_res4.ply.gz", 42.0),
            ("fandisk.obj", 36.0),
            ("armadillo.off", 32.0),
            ("horse.ply", 36.0),
        ] {
            let src = SceneSource::parse(m.join(f).to_str().unwrap()).unwrap();
            sources.push((f.to_string(), src, most));
        }
    }
    for (name, src, most) in sources {
        for runs in [true, false] {
            let path = dir.path().join("m.sdb");
            common::write_converted(&src, &path, Compression::None, runs);
            let db = Database::open(&path).unwrap();
            let store = ObjectStore::load(&db, &NoProgress).unwrap();
            let opts = RenderOptions {
                width: 16,
                height: 16,
                ..Default::default()
            };
            let scene = DfScene::new(
                &db,
                &store,
                sray_engine::models::Models::default(),
                &opts,
                sray_engine::df::TEXTURE_MEMORY,
            )
            .unwrap();
            let grids: u64 = scene.grids.iter().map(|g| g.bytes()).sum();
            let triangles = db.triangles().unwrap() as f64;
            let per = (store.bytes() + grids) as f64 / triangles;
            // Version 3 records are gathered as version 4 runs are.
            assert!(
                per <= most,
                "{name} (runs in file: {runs}): {per:.1} bytes per triangle \
                 (objects {}, grids {grids})",
                store.bytes()
            );
            let (faces, _) = store.face_counts();
            assert!(
                faces * 100 >= db.object_count() * 95,
                "{name}: {faces} faces"
            );
        }
    }
}

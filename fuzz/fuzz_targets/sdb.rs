//! The object database reader on arbitrary bytes: opening, scanning every
//! block and intersecting every record it accepts, holding the objects as
//! the depth-first tracer does, and loading the models
//! of a version 5 file and testing each instance against its model, must
//! end in a value or an error naming the block, never a panic or an
//! unbounded allocation.
//! Checksums are off in fuzzing builds (see `sdb::reader`), so mutations
//! reach the decoding behind them.
#![no_main]

use libfuzzer_sys::fuzz_target;
use sray_engine::intersect::{Ray, RayQ};
use sray_engine::shapes::intersect;
use sray_engine::math::Vec3;
use sray_engine::models::{Models, Placement};
use sray_engine::progress::NoProgress;
use sray_engine::render::Cutouts;
use sray_engine::sdb::Database;
use sray_engine::shapes::{KindCounts, Shape};
use std::io::Write;

fuzz_target!(|data: &[u8]| {
    let mut f = tempfile::NamedTempFile::new().expect("temporary file");
    f.write_all(data).expect("write");
    let Ok(db) = Database::open(f.path()) else {
        return;
    };
    // A version 8 file's images decode or are refused; a version 9
    // file's tiles are read (a corrupt one is an error kept for the
    // render, not a panic), at every level of every chain; shading's
    // look-ups and cut-outs stay in bounds whatever the bindings say.
    if let Ok((sc, _)) = sray_engine::render::ShadeScene::open(&db, 2, 1e-6, 1 << 20) {
        let s = sray_engine::texture::Sampler::default();
        for t in sc.textures.iter() {
            for level in 0..t.levels() {
                let _ = t.sample_level(&s, [0.3, 0.7], level);
                let _ = t.sample_level(&s, [-1.3, 2.5], level);
            }
        }
        let _ = sc.texture_error();
        let _ = Cutouts::new(&db.scene().materials, sc.textures.clone());
    }
    let _ = db.bbox();
    let Ok(mut scan) = db.scan() else { return };
    let (o, d) = (Vec3::new(-3.0, 0.1, 0.2), Vec3::new(1.0, 0.01, 0.02));
    let ray = RayQ::from_vec3(o, d);
    let mut placements = Vec::new();
    while let Ok(Some(block)) = scan.next_block() {
        for o in block.objects() {
            let _ = o.shape.prepare();
            if let Some(t) = intersect::<f64>(&o.shape, &o.bbox, &ray, 0.0, f64::INFINITY) {
                let _ = o.shape.surface(&ray, t);
            }
            let _ = (o.index, o.rank, o.material);
            if let Shape::Instance(i) = o.shape {
                placements.push(Placement::of(&i));
            }
        }
    }
    // The depth-first tracer's store takes the blocks' triangle runs as
    // they are stored, checked as runs.
    if let Ok(store) = sray_engine::objects::ObjectStore::load(&db, &NoProgress) {
        store.each_bbox(|_, _| {});
    }
    // Models are small in the seeds; a mutated count must not ask for
    // more memory than the file backs.
    let Ok(models) = Models::load(&db, 1, false, &NoProgress) else { return };
    let mut tests = KindCounts::default();
    for pl in &placements {
        let r = Ray {
            q: &ray,
            o,
            d,
            t_min: 0.0,
            t_max: f64::INFINITY,
        };
        if let Some((t, p)) = models.nearest(pl, r, &mut tests) {
            let _ = models.surface(pl, p, &RayQ::from_vec3(o, d), t);
        }
        let _ = models.blocks(pl, r, &mut tests);
    }
});

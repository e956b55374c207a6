//! Ray origins exactly on a surface: measures how often a secondary ray
//! finds the surface it leaves (surface acne) and how often a shadow ray
//! misses a blocker closer than the epsilon (lost shadows), with the
//! epsilon and the spawning code the tracers use, over the first hits of
//! the seven SPD scenes (tests/fixtures/spd). Brute force: every ray
//! against every object, so that no grid can hide or cause anything.
//!
//! The figures are printed (`cargo test --release -p sray-engine --test it
//! self_intersection:: -- --nocapture`) and quoted in
//! docs/stability.md ("Self-intersection").

use crate::common;

use sray_engine::intersect::RayQ;
use sray_engine::math::{Real, Vec3};
use sray_engine::progress::NoProgress;
use sray_engine::render::{Camera, Precision, ShadeScene, Spawn, epsilon, shade};
use sray_engine::scene::Aabb;
use sray_engine::sdb::{Compression, Database, DbWriter};
use sray_engine::shapes::OwnedShape;
use sray_engine::shapes::intersect;
use sray_engine::source::SceneSource;

const SIDE: u32 = 32;

#[derive(Default, Debug)]
struct Tally {
    secondary: u64,
    /// Secondary rays whose nearest hit beyond the epsilon is the object
    /// they leave, closer than 1e-4 of the scene's size.
    self_hits: u64,
    shadow: u64,
    /// Shadow rays toward a light with another object in (0, eps]: a
    /// blocker the epsilon hides.
    lost_blockers: u64,
}

/// Every object of a database, each owning its geometry: a brute-force
/// search needs no grid.
struct Objects(Vec<(OwnedShape, Aabb, u32)>);

impl Objects {
    fn load(db: &Database) -> Objects {
        let mut all = Vec::new();
        let mut scan = db.scan().unwrap();
        while let Some(b) = scan.next_block().unwrap() {
            all.extend(
                b.objects()
                    .map(|o| (OwnedShape::from_shape(&o.shape), o.bbox, o.material)),
            );
        }
        Objects(all)
    }
}

/// Nearest hit of `ray` in `(t_min, t_max)` over all objects, ties to the
/// smaller id as in the tracers.
fn nearest<R: Real>(
    objs: &Objects,
    ray: &RayQ<f64>,
    t_min: f64,
    t_max: f64,
    skip: Option<u32>,
) -> Option<(u32, f64)> {
    let q = ray.cast::<R>();
    let mut best: Option<(u32, f64)> = None;
    for (id, (shape, bbox, _)) in objs.0.iter().enumerate() {
        let id = id as u32;
        if Some(id) == skip {
            continue;
        }
        let limit = best.map_or(t_max, |b| b.1);
        if let Some(t) = intersect::<R>(
            &shape.shape(),
            bbox,
            &q,
            R::from_f64(t_min),
            R::from_f64(limit),
        ) {
            let t = t.to_f64();
            if best.is_none_or(|b| t < b.1) {
                best = Some((id, t));
            }
        }
    }
    best
}

fn measure<R: Real>(db: &Database, objs: &Objects, precision: Precision, eps_scale: f64) -> Tally {
    let h = db.scene();
    let eps = epsilon(&db.bbox(), precision) * eps_scale;
    let size = db.bbox().diagonal();
    let sc = ShadeScene::new(h, 5, eps).unwrap();
    let cam = Camera::new(&h.view, SIDE, SIDE).unwrap();
    let mut tally = Tally::default();
    for row in 0..=SIDE {
        for col in 0..=SIDE {
            let d = cam.direction(col, row);
            let eye = RayQ::from_vec3(cam.eye, d);
            let Some((id, t)) = nearest::<R>(objs, &eye, 0.0, f64::INFINITY, None) else {
                continue;
            };
            let (shape, _, material) = &objs.0[id as usize];
            let surf = shape.shape().surface(&eye, t);
            let m = &h.materials[*material as usize];
            let mut spawned: Vec<(Vec3, f64, bool)> = Vec::new();
            shade(&sc, d, 1, 1.0, &surf, m, &mut |s| match s {
                Spawn::Shadow { dir, dist, .. } => spawned.push((dir, dist, true)),
                Spawn::Reflect { dir, .. } | Spawn::Refract { dir, .. } => {
                    spawned.push((dir, f64::INFINITY, false))
                }
                Spawn::Emit { .. } => {}
            });
            for (dir, dist, is_shadow) in spawned {
                let ray = RayQ::from_vec3(surf.p, dir);
                tally.secondary += 1;
                if let Some((hit, th)) = nearest::<R>(objs, &ray, eps, dist, None)
                    && hit == id
                    && th < 1e-4 * size
                {
                    tally.self_hits += 1;
                }
                if is_shadow {
                    tally.shadow += 1;
                    if nearest::<R>(objs, &ray, 0.0, eps.min(dist), Some(id)).is_some() {
                        tally.lost_blockers += 1;
                    }
                }
            }
        }
    }
    tally
}

fn pct(a: u64, b: u64) -> f64 {
    100.0 * a as f64 / b.max(1) as f64
}

#[test]
fn secondary_rays_do_not_find_their_own_surface() {
    let dir = tempfile::tempdir().unwrap();
    let mut totals = [(0u64, 0u64, 0u64, 0u64); 3];
    for (name, size) in common::DEFAULT_SCENES {
        let path = dir.path().join(format!("{name}.sdb"));
        let mut w = DbWriter::create(&path, Compression::None).unwrap();
        SceneSource::nff(common::spd_fixtures().join(format!("{name}{size}.nff")))
            .stream_into(&mut w, &NoProgress)
            .unwrap();
        w.finish().unwrap();
        let db = Database::open(&path).unwrap();
        let objs = Objects::load(&db);
        let runs = [
            ("double", measure::<f64>(&db, &objs, Precision::Double, 1.0)),
            ("single", measure::<f32>(&db, &objs, Precision::Single, 1.0)),
            (
                "double, no epsilon",
                measure::<f64>(&db, &objs, Precision::Double, 0.0),
            ),
        ];
        for (i, (what, t)) in runs.iter().enumerate() {
            eprintln!(
                "{name}{size} {what}: {} of {} secondary rays hit their own surface ({:.4}%), \
                 {} of {} shadow rays have a blocker inside the epsilon ({:.4}%)",
                t.self_hits,
                t.secondary,
                pct(t.self_hits, t.secondary),
                t.lost_blockers,
                t.shadow,
                pct(t.lost_blockers, t.shadow)
            );
            totals[i].0 += t.self_hits;
            totals[i].1 += t.secondary;
            totals[i].2 += t.lost_blockers;
            totals[i].3 += t.shadow;
        }
    }
    for (what, t) in ["double", "single", "double, no epsilon"]
        .iter()
        .zip(totals)
    {
        eprintln!(
            "all scenes, {what}: self-hits {:.4}% of {} rays, lost blockers {:.4}% of {} shadow rays",
            pct(t.0, t.1),
            t.1,
            pct(t.2, t.3),
            t.3
        );
    }
    // With the tracers' epsilon: no self-hit at all, in either precision,
    // and hardly a blocker lost (one closer than 1e-7 of the scene).
    assert_eq!(totals[0].0, 0, "double precision: self-hits");
    assert_eq!(totals[1].0, 0, "single precision: self-hits");
    assert!(totals[0].2 * 1000 <= totals[0].3, "double: lost blockers");
    // Single precision needs a 2000 times larger epsilon, which hides
    // contact shadows where spheres touch (measured: 0.27% of shadow rays,
    // 1.1% on balls4).
    assert!(totals[1].2 * 50 <= totals[1].3, "single: lost blockers");
    // The measurement has teeth: without the epsilon, acne is common.
    assert!(
        totals[2].0 * 100 > totals[2].1,
        "without an epsilon only {} of {} rays hit themselves",
        totals[2].0,
        totals[2].1
    );
}

//! A dense model in a sparse world: thousands of small triangles in a unit
//! box on a wide floor strewn with spheres. By default the model gets a
//! grid of its own (a dense region of the database's density summary).
//! With one grid (`--grids 1`, the paper's setup), sized for the whole
//! floor, the model falls into a few voxels, and the depth-first tracer
//! gives those voxels a hierarchy of their objects instead of a list.
//! Either way the image must be the breadth-first tracer's (which keeps
//! plain lists), bit for bit, in both precisions and at any thread count,
//! including where hits tie (triangles repeated under larger ids, in
//! another colour).

use sray_engine::bf::StoreNumber;
use sray_engine::nff::read_nff_from;
use sray_engine::progress::NoProgress;
use sray_engine::render::{Aggregates, GridRes, Precision, RenderOptions};
use sray_engine::sdb::{Compression, Database, DbWriter};
use std::fmt::Write;
use std::path::Path;

use crate::common::{Render, bf_render, df_render};

/// A small deterministic generator (64-bit LCG), so the scene is the same
/// everywhere.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

/// The scene, seen from `distance` times the usual eye's distance with a
/// field of view as much narrower (the same picture, but eye rays that
/// start far from the model).
fn crowd_nff(triangles: usize, spheres: usize, distance: f64) -> String {
    crowd_nff_spread(triangles, spheres, distance, 50.0)
}

/// As [`crowd_nff`], the spheres within `spread` of the centre.
fn crowd_nff_spread(triangles: usize, spheres: usize, distance: f64, spread: f64) -> String {
    let mut r = Lcg(2026);
    let mut s = String::new();
    let (from, angle) = ([1.6, 0.8, 2.0].map(|c| c * distance), 35.0 / distance);
    writeln!(
        s,
        "v\nfrom {} {} {}\nat 0 0.4 0\nup 0 1 0\nangle {angle}\nhither 0.001\nresolution 48 48",
        from[0],
        from[1] + 0.4,
        from[2]
    )
    .unwrap();
    s.push_str("b 0.1 0.1 0.2\nl 3 8 4 0.9 0.9 0.9\nl -4 5 1 0.5 0.5 0.5\n");
    s.push_str("f 0.6 0.6 0.6 1 0 0 0 1\np 4\n-50 0 -50\n-50 0 50\n50 0 50\n50 0 -50\n");
    s.push_str("f 0.9 0.3 0.2 0.6 0.4 20 0 1\n");
    for _ in 0..spheres {
        let (x, z) = (r.range(-spread, spread), r.range(-spread, spread));
        if x.abs() < 2.0 && z.abs() < 2.0 {
            continue;
        }
        writeln!(s, "s {x:.4} 0.2 {z:.4} 0.2").unwrap();
    }
    s.push_str("f 0.8 0.8 0.7 0.7 0.3 30 0 1\n");
    let mut tris = Vec::new();
    for _ in 0..triangles {
        let c = [r.range(-0.5, 0.5), r.range(0.0, 1.0), r.range(-0.5, 0.5)];
        let v: Vec<[f64; 3]> = (0..3)
            .map(|_| std::array::from_fn(|i| c[i] + r.range(-0.06, 0.06)))
            .collect();
        tris.push(v);
    }
    // Every tenth triangle again, later in the file and in another
    // colour: exact ties, which the smaller id must win whichever is
    // tested first.
    let again: Vec<_> = tris.iter().step_by(10).cloned().collect();
    let polygon = |s: &mut String, t: &Vec<[f64; 3]>| {
        s.push_str("p 3\n");
        for v in t {
            writeln!(s, "{} {} {}", v[0], v[1], v[2]).unwrap();
        }
    };
    for t in &tris {
        polygon(&mut s, t);
    }
    s.push_str("f 0.1 0.9 0.1 0.7 0.3 30 0 1\n");
    for t in &again {
        polygon(&mut s, t);
    }
    s
}

fn database(nff: &str, dir: &Path) -> Database {
    let path = dir.join("crowd.sdb");
    let mut w = DbWriter::create(&path, Compression::None).unwrap();
    read_nff_from(nff.as_bytes(), Path::new("crowd.nff"), &mut w, &NoProgress).unwrap();
    w.finish().unwrap();
    Database::open(&path).unwrap()
}

fn opts(threads: usize, precision: Precision) -> RenderOptions {
    RenderOptions {
        width: 48,
        height: 48,
        max_depth: 3,
        threads,
        precision,
        ..Default::default()
    }
}

/// One grid for everything, as in the paper's single-grid setup: the
/// model crowds a few of its voxels.
fn one_grid(threads: usize, precision: Precision) -> RenderOptions {
    RenderOptions {
        multiple_grids: false,
        ..opts(threads, precision)
    }
}

/// `o` testing crowded groups one by one: the model's voxels stay
/// crowded (the depth-first tracer gives them hierarchies).
fn no_aggregates(o: RenderOptions) -> RenderOptions {
    RenderOptions {
        aggregates: Aggregates::Off,
        ..o
    }
}

/// `o` holding crowded groups as aggregates in both tracers (by default
/// only breadth-first does).
fn aggregates(o: RenderOptions) -> RenderOptions {
    RenderOptions {
        aggregates: Aggregates::On,
        ..o
    }
}

fn assert_same(what: &str, want: &Render, got: &Render) {
    let differing = want.0.iter().zip(&got.0).filter(|(a, b)| a != b).count();
    assert_eq!(differing, 0, "{what}: {differing} channel values differ");
    assert_eq!(want.1.rays, got.1.rays, "{what}: ray counts differ");
}

/// The model's triangles: 6,000 and every tenth again.
const MODEL: u64 = 6600;

#[test]
fn crowded_voxels_get_a_hierarchy_and_the_same_image() {
    let dir = tempfile::tempdir().unwrap();
    let db = database(&crowd_nff(6000, 3000, 1.0), dir.path());
    for precision in [Precision::Double, Precision::Single] {
        let bf = bf_render(&db, &one_grid(2, precision), StoreNumber::Adaptive, 1 << 30);
        let df = df_render(&db, &no_aggregates(one_grid(2, precision)));
        let nested: u64 = df.1.grids.iter().map(|g| g.nested_voxels).sum();
        assert!(
            nested > 0,
            "the model should crowd some voxel: {:?}",
            df.1.grids
        );
        assert!(
            df.1.rays.eye_hit_rays > 48 * 48 / 2,
            "the view should be mostly model and floor"
        );
        assert_same(&format!("{precision:?}: df against bf"), &bf, &df);
        assert_same(
            &format!("{precision:?}: df, one thread"),
            &bf,
            &df_render(&db, &no_aggregates(one_grid(1, precision))),
        );
        // Finer grids leave fewer voxels crowded, and one voxel puts every
        // object in a single hierarchy.
        for res in [[1, 1, 1], [3, 2, 3], [40, 2, 40]] {
            let o = RenderOptions {
                grid_res: GridRes::Fixed(res),
                ..no_aggregates(one_grid(2, precision))
            };
            assert_same(
                &format!("{precision:?}: df, grid {res:?}"),
                &bf,
                &df_render(&db, &o),
            );
        }
    }
}

/// With the grids planned from the database's density summary, the
/// model gets a grid of its own (no voxel of the floor's grid holds it),
/// in both tracers, and the image does not change.
#[test]
fn a_dense_model_gets_a_grid_of_its_own_and_the_same_image() {
    let dir = tempfile::tempdir().unwrap();
    let db = database(&crowd_nff(6000, 3000, 1.0), dir.path());
    let precision = Precision::Single;
    let want = df_render(&db, &one_grid(2, precision));
    let df = df_render(&db, &opts(2, precision));
    let bf = bf_render(&db, &opts(2, precision), StoreNumber::Adaptive, 1 << 30);
    let tight = bf_render(&db, &opts(2, precision), StoreNumber::Adaptive, 4 << 20);
    for (what, r) in [("df", &df), ("bf", &bf), ("bf, 4 MiB", &tight)] {
        // Nearly all the model (a few triangles at its edge, whose centres
        // fall in a sparse cell of the density lattice, stay behind) in a
        // grid about the model's size.
        let model = r.1.grids.iter().filter(|g| {
            let size = (0..3).map(|i| g.hi[i] - g.lo[i]).fold(0.0, f64::max);
            g.objects >= MODEL * 95 / 100 && g.objects <= MODEL && size < 1.5
        });
        assert_eq!(
            model.count(),
            1,
            "{what}: the model's grid: {:?}",
            r.1.grids
        );
        assert_eq!(
            r.1.grids.iter().map(|g| g.objects).sum::<u64>(),
            db.object_count()
        );
        assert_same(&format!("{what}, grids of their own"), &want, r);
    }
    assert_eq!(
        df.1.grids.iter().map(|g| g.nested_voxels).sum::<u64>(),
        0,
        "nothing crowded left: {:?}",
        df.1.grids
    );
}

/// Eye rays from about 107,000 units away: single precision rounds their
/// hits by a few thousandths, beyond a margin sized by the grid alone
/// (1e-5 of 100 units, which gave 112 wrong channel values here). The
/// boxes of the hierarchies must still let every hit through.
#[test]
fn a_far_eye_finds_the_same_hits_in_the_hierarchy() {
    let dir = tempfile::tempdir().unwrap();
    let db = database(&crowd_nff(3000, 500, 40_000.0), dir.path());
    for precision in [Precision::Single, Precision::Double] {
        let bf = bf_render(&db, &one_grid(1, precision), StoreNumber::Adaptive, 1 << 30);
        assert!(
            bf.1.rays.eye_hit_rays > 48 * 48 / 2,
            "the view should be mostly model and floor"
        );
        assert_same(
            &format!("{precision:?}: bf, objects one by one"),
            &bf,
            &bf_render(
                &db,
                &no_aggregates(one_grid(1, precision)),
                StoreNumber::Adaptive,
                1 << 30,
            ),
        );
        for res in [[1, 1, 1], [3, 2, 3]] {
            let o = RenderOptions {
                grid_res: GridRes::Fixed(res),
                ..one_grid(1, precision)
            };
            let df = df_render(&db, &no_aggregates(o.clone()));
            assert!(df.1.grids[0].nested_voxels > 0);
            assert_same(&format!("{precision:?}: df, grid {res:?}"), &bf, &df);
            let df = df_render(&db, &aggregates(o));
            assert!(df.1.grids[0].aggregates > 0, "{:?}", df.1.grids);
            assert_same(
                &format!("{precision:?}: df aggregates, grid {res:?}"),
                &bf,
                &df,
            );
        }
    }
}

/// A database whose density summary disagrees with its records (every
/// entry's box moved along x by a quarter of its width, checksums made
/// good again) is an error naming the tables in both tracers, not objects
/// silently left out of their grid.
#[test]
fn a_density_summary_that_lies_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let db = database(&crowd_nff(6000, 3000, 1.0), dir.path());
    let entries = db.density().unwrap().entries.len();
    let info = sray_engine::info::scene_info(db.path(), &NoProgress).unwrap();
    assert_eq!(info.dense_regions.map(|r| r.len()), Some(1));
    let path = db.path().to_path_buf();
    drop(db);
    let mut bytes = std::fs::read(&path).unwrap();
    let word = |b: &[u8], at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap());
    let (tables_at, tables_len) = (word(&bytes, 120) as usize, word(&bytes, 128) as usize);
    assert_eq!(tables_at + tables_len, bytes.len());
    // The entries end the tables: cell, class, count, then min and max.
    let float = |b: &[u8], at: usize| f32::from_le_bytes(b[at..at + 4].try_into().unwrap());
    for k in 0..entries {
        let e = bytes.len() - (entries - k) * 40;
        let (lo, hi) = (float(&bytes, e + 16), float(&bytes, e + 28));
        let shift = 0.25 * (hi - lo);
        bytes[e + 16..e + 20].copy_from_slice(&(lo + shift).to_le_bytes());
        bytes[e + 28..e + 32].copy_from_slice(&(hi + shift).to_le_bytes());
    }
    let crc = crc32fast::hash(&bytes[tables_at..]);
    bytes[168..172].copy_from_slice(&crc.to_le_bytes());
    let crc = crc32fast::hash(&bytes[..252]);
    bytes[252..256].copy_from_slice(&crc.to_le_bytes());
    let bad = dir.path().join("bad.sdb");
    std::fs::write(&bad, &bytes).unwrap();
    let db = Database::open(&bad).unwrap();
    let o = opts(1, Precision::Double);
    let e = sray_engine::df::render(&db, &o, &NoProgress)
        .err()
        .expect("df refuses");
    assert!(e.to_string().contains("disagree"), "{e}");
    let b = sray_engine::bf::BfOptions {
        memory: 1 << 30,
        store: StoreNumber::Adaptive,
        spill_dir: None,
        shading: sray_engine::bf::Shading::Carry,
        models: Default::default(),
    };
    let e = sray_engine::bf::render(&db, &o, &b, &NoProgress)
        .err()
        .expect("bf refuses");
    assert!(e.to_string().contains("disagree"), "{e}");
}

/// Spheres only near the model: the floor is set apart as huge, and the
/// model is a dense region among the spheres, so there are three grids,
/// the most a plan makes; the breadth-first tracer (a walk per grid in
/// every ray slot) takes them, in ample and in tight memory.
#[test]
fn a_region_and_a_huge_floor_make_three_grids_in_both_tracers() {
    let dir = tempfile::tempdir().unwrap();
    let db = database(&crowd_nff_spread(6000, 1500, 1.0, 8.0), dir.path());
    let precision = Precision::Double;
    let want = df_render(&db, &one_grid(2, precision));
    let df = df_render(&db, &opts(2, precision));
    assert_eq!(df.1.grids.len(), 3, "{:?}", df.1.grids);
    let bf = bf_render(&db, &opts(2, precision), StoreNumber::Adaptive, 1 << 30);
    let tight = bf_render(&db, &opts(2, precision), StoreNumber::Adaptive, 4 << 20);
    for (what, r) in [("df", &df), ("bf", &bf), ("bf, 4 MiB", &tight)] {
        assert_eq!(r.1.grids.len(), 3, "{what}: {:?}", r.1.grids);
        assert_same(&format!("{what}, three grids"), &want, r);
    }
}

/// With one grid the model crowds a few voxels, and both tracers hold its
/// groups of objects as aggregates (a hierarchy per group; breadth-first
/// builds it as the block is read): the image of the depth-first tracer
/// without them and of the paper's one-by-one tests (`--full-scans`), in
/// both precisions, in a database in input order and in spatial order,
/// and the same counts whatever the threads or the memory (in 4 MiB the
/// rays take many passes, so their mailboxes and last voxels carry over).
#[test]
fn crowded_groups_are_aggregates_in_both_tracers_and_the_image_is_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let nff = crowd_nff(6000, 3000, 1.0);
    let spatial = {
        let path = dir.path().join("spatial.sdb");
        let mut w = DbWriter::create(&path, Compression::None)
            .unwrap()
            .spatial(64 << 20, None);
        read_nff_from(nff.as_bytes(), Path::new("crowd.nff"), &mut w, &NoProgress).unwrap();
        w.finish().unwrap();
        Database::open(&path).unwrap()
    };
    let input = database(&nff, dir.path());
    let walks = |r: &Render| {
        r.1.details.as_ref().unwrap()["aggregate_walks"]
            .as_u64()
            .unwrap()
    };
    for (order, db) in [("input order", &input), ("spatial order", &spatial)] {
        for precision in [Precision::Double, Precision::Single] {
            let what = format!("{order}, {precision:?}");
            let want = df_render(db, &no_aggregates(one_grid(2, precision)));
            let df = df_render(db, &aggregates(one_grid(2, precision)));
            // Nearly all of the model's 103 groups (a few at its edges
            // share a group with spheres or are cut by the file's order).
            assert_same(&format!("{what}: df with aggregates"), &want, &df);
            // In spatial order most of the model's 103 groups are patches
            // crowding a voxel or two; in this input order (triangles at
            // random) a group spreads over the whole model, but the model's
            // box spans a few voxels and crowds them: most groups are
            // aggregates all the same.
            let held = df.1.grids[0].aggregates;
            assert!(held > 30, "{what}: {:?}", df.1.grids);
            let bf = bf_render(db, &one_grid(2, precision), StoreNumber::Adaptive, 1 << 30);
            assert!(walks(&bf) > 1000, "{what}: {} aggregate walks", walks(&bf));
            // Found from the same groups of the same grid, except that
            // breadth-first reads a block at a time: a group the input
            // order's blocks cut in two is objects there, one at most at
            // each block's end (a spatial order's blocks begin where
            // groups do).
            let cut = match order {
                "input order" => db.block_count() - 1,
                _ => 0,
            };
            let bf_held = bf.1.grids[0].aggregates;
            assert!(
                bf_held <= held && bf_held + cut >= held,
                "{what}: {bf_held} aggregates breadth-first, {held} depth-first"
            );
            assert_same(&format!("{what}: bf against df"), &want, &bf);
            for (threads, memory) in [(1, 1 << 30), (2, 4 << 20), (3, 4 << 20)] {
                let other = bf_render(
                    db,
                    &one_grid(threads, precision),
                    StoreNumber::Adaptive,
                    memory,
                );
                let how = format!("{what}: {threads} threads in {memory} bytes");
                assert_same(&how, &want, &other);
                assert_eq!(
                    bf.1.intersection_tests_by_kind, other.1.intersection_tests_by_kind,
                    "{how}"
                );
                assert_eq!(walks(&bf), walks(&other), "{how}");
            }
            let mut paper = db.clone();
            paper.set_full_scans(true);
            let full = bf_render(
                &paper,
                &one_grid(2, precision),
                StoreNumber::Adaptive,
                4 << 20,
            );
            assert_same(&format!("{what}: the paper's passes"), &want, &full);
            assert_eq!(walks(&full), 0, "{what}");
            assert_eq!(full.1.grids[0].aggregates, 0, "{what}");
            if held > 0 {
                assert!(
                    bf.1.intersection_tests * 3 < full.1.intersection_tests * 2,
                    "{what}: {} tests with aggregates, {} one by one",
                    bf.1.intersection_tests,
                    full.1.intersection_tests
                );
            }
        }
    }
}

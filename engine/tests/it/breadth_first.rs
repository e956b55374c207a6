//! The breadth-first tracer gives exactly the depth-first image and SPD
//! counts, whatever its store number, memory budget, grids, compression and
//! threads; and its own counts do not depend on the number of threads.

use crate::common;

use sray_engine::bf::{self, BfOptions, StoreNumber};
use sray_engine::df;
use sray_engine::progress::NoProgress;
use sray_engine::render::{RenderOptions, RenderStats};
use sray_engine::sdb::{Compression, Database, DbWriter};
use sray_engine::source::SceneSource;
use std::path::{Path, PathBuf};

const SIZE: u32 = 40;

fn convert(nff: &Path, dir: &Path, c: Compression) -> PathBuf {
    let out = dir.join(format!(
        "{}-{}.sdb",
        nff.file_stem().unwrap().to_str().unwrap(),
        c.name()
    ));
    let mut w = DbWriter::create(&out, c).unwrap();
    SceneSource::nff(nff.to_path_buf())
        .stream_into(&mut w, &NoProgress)
        .unwrap();
    w.finish().unwrap();
    out
}

fn opts(threads: usize, grids: bool) -> RenderOptions {
    RenderOptions {
        width: SIZE,
        height: SIZE,
        threads,
        multiple_grids: grids,
        ..Default::default()
    }
}

fn df_render(db: &Database) -> (Vec<u8>, RenderStats) {
    common::df_render(db, &opts(2, true))
}

use common::bf_render;

fn assert_same(name: &str, what: &str, a: &(Vec<u8>, RenderStats), b: &(Vec<u8>, RenderStats)) {
    assert!(a.0 == b.0, "{name} ({what}): images differ");
    assert_eq!(a.1.rays, b.1.rays, "{name} ({what}): SPD counts differ");
}

const PLENTY: u64 = 1 << 30;

#[test]
fn every_store_number_gives_the_depth_first_image() {
    let dir = tempfile::tempdir().unwrap();
    for (name, size) in common::DEFAULT_SCENES {
        let path = convert(
            &common::spd_fixtures().join(format!("{name}{size}.nff")),
            dir.path(),
            Compression::None,
        );
        let db = Database::open(&path).unwrap();
        let reference = df_render(&db);
        for store in [
            StoreNumber::Fixed(1),
            StoreNumber::Fixed(2),
            StoreNumber::Adaptive,
            StoreNumber::Budget,
        ] {
            let got = bf_render(&db, &opts(2, true), store, PLENTY);
            assert_same(name, &format!("store {store:?}"), &reference, &got);
            assert_eq!(got.1.mode, "bf");
        }
    }
}

#[test]
fn budgets_from_a_few_hundred_kilobytes_to_plenty() {
    let dir = tempfile::tempdir().unwrap();
    for (name, size) in [("balls", 4), ("gears", 4), ("rings", 7), ("teapot", 12)] {
        let path = convert(
            &common::spd_fixtures().join(format!("{name}{size}.nff")),
            dir.path(),
            Compression::None,
        );
        let db = Database::open(&path).unwrap();
        let reference = df_render(&db);
        let mut spilled = false;
        for memory in [600 << 10, 1 << 20, 4 << 20, PLENTY] {
            let got = bf_render(&db, &opts(2, true), StoreNumber::Adaptive, memory);
            assert_same(name, &format!("memory {memory}"), &reference, &got);
            let extra = got.1.details.as_ref().unwrap();
            spilled |= extra["spill_bytes_written"].as_u64().unwrap() > 0;
            if memory == 600 << 10 {
                // A tight budget means ray filling: more passes than rays fit.
                let passes: u64 = extra["passes"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|p| p.as_u64().unwrap())
                    .sum();
                assert!(passes > 10, "{name}: only {passes} passes at 600 KiB");
            }
        }
        assert!(spilled, "{name}: nothing ever spilled to disk");
    }
}

#[test]
fn one_grid_or_several_and_compression() {
    let dir = tempfile::tempdir().unwrap();
    for (name, size) in [("balls", 4), ("tree", 11), ("gears", 4)] {
        let nff = common::spd_fixtures().join(format!("{name}{size}.nff"));
        let plain = Database::open(&convert(&nff, dir.path(), Compression::None)).unwrap();
        let packed = Database::open(&convert(&nff, dir.path(), Compression::Zstd(3))).unwrap();
        let reference = df_render(&plain);
        let several = bf_render(&plain, &opts(2, true), StoreNumber::Adaptive, PLENTY);
        let one = bf_render(&plain, &opts(2, false), StoreNumber::Adaptive, PLENTY);
        assert!(
            several.1.grids.len() > 1,
            "{name}: expected the ground in a grid of its own"
        );
        assert_eq!(one.1.grids.len(), 1);
        assert_same(name, "several grids", &reference, &several);
        assert_same(name, "one grid", &reference, &one);
        let z = bf_render(&packed, &opts(2, true), StoreNumber::Adaptive, 2 << 20);
        assert_same(name, "zstd", &reference, &z);
        // Compression changes what is read from disk, not what is tested.
        assert_eq!(z.1.intersection_tests, several.1.intersection_tests);
    }
}

#[test]
fn counts_do_not_depend_on_threads_or_budget() {
    let dir = tempfile::tempdir().unwrap();
    for (name, size) in [("mount", 6), ("rings", 7), ("tetra", 6)] {
        let path = convert(
            &common::spd_fixtures().join(format!("{name}{size}.nff")),
            dir.path(),
            Compression::None,
        );
        let db = Database::open(&path).unwrap();
        let a = bf_render(&db, &opts(1, true), StoreNumber::Adaptive, PLENTY);
        for (threads, memory) in [(2, PLENTY), (3, PLENTY), (2, 1 << 20)] {
            let b = bf_render(&db, &opts(threads, true), StoreNumber::Adaptive, memory);
            assert_same(name, &format!("{threads} threads"), &a, &b);
            assert_eq!(
                a.1.intersection_tests_by_kind, b.1.intersection_tests_by_kind,
                "{name}"
            );
            let (x, y) = (a.1.details.as_ref().unwrap(), b.1.details.as_ref().unwrap());
            for k in [
                "ray_voxel_registrations",
                "tests_skipped_last_voxel",
                "tests_skipped_mailbox",
                "rays_per_round",
            ] {
                assert_eq!(
                    x[k], y[k],
                    "{name}: {k} with {threads} threads, {memory} bytes"
                );
            }
            if memory == PLENTY {
                for k in [
                    "passes",
                    "remaining_rays_per_pass",
                    "store_numbers",
                    "db_scans",
                ] {
                    assert_eq!(x[k], y[k], "{name}: {k} with {threads} threads");
                }
            }
        }
    }
}

fn passes_of(st: &RenderStats) -> Vec<u64> {
    st.details.as_ref().unwrap()["passes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_u64().unwrap())
        .collect()
}

/// The budget's store number: a round's last pass gives the walks it cut
/// short what its rays left of the registrations, so a round whose rays
/// all fit takes one or two passes (the paper's rule: up to four here,
/// the last ones for a few long walks), with the depth-first image at every budget and
/// threads, and (with room for every ray) work counts that do not depend
/// on the threads.
#[test]
fn the_budget_store_number_saves_a_round_s_last_passes() {
    let dir = tempfile::tempdir().unwrap();
    let mut saved = 0;
    for (name, size) in [("mount", 6), ("rings", 7), ("tetra", 6), ("gears", 4)] {
        let path = convert(
            &common::spd_fixtures().join(format!("{name}{size}.nff")),
            dir.path(),
            Compression::None,
        );
        let db = Database::open(&path).unwrap();
        let reference = df_render(&db);
        let adaptive = bf_render(&db, &opts(2, true), StoreNumber::Adaptive, PLENTY);
        let budget = bf_render(&db, &opts(2, true), StoreNumber::Budget, PLENTY);
        assert_same(name, "budget", &reference, &budget);
        assert_eq!(budget.1.details.as_ref().unwrap()["store_number"], "budget");
        // Every round's rays fit in the slots here: at most two passes
        // each (one, unless the walks cut short need more than is left).
        let (a, b) = (passes_of(&adaptive.1), passes_of(&budget.1));
        assert!(
            b.iter().all(|&p| p <= 2),
            "{name}: passes {b:?} (adaptive {a:?})"
        );
        saved += a.iter().sum::<u64>() - b.iter().sum::<u64>();
        for memory in [1 << 20, 4 << 20, PLENTY] {
            let one = bf_render(&db, &opts(1, true), StoreNumber::Budget, memory);
            assert_same(name, &format!("budget, {memory} bytes"), &reference, &one);
            for threads in [2, 3] {
                let b = bf_render(&db, &opts(threads, true), StoreNumber::Budget, memory);
                assert_same(name, &format!("budget, {threads} threads"), &one, &b);
                if memory < PLENTY {
                    // Where a round's last pass cannot register all its
                    // rays, which wait depends on the threads, and so do
                    // the work counts (not the image or the hits).
                    continue;
                }
                assert_eq!(
                    one.1.intersection_tests_by_kind, b.1.intersection_tests_by_kind,
                    "{name}: tests with {threads} threads, {memory} bytes"
                );
                let (x, y) = (
                    one.1.details.as_ref().unwrap(),
                    b.1.details.as_ref().unwrap(),
                );
                for k in [
                    "ray_voxel_registrations",
                    "tests_skipped_last_voxel",
                    "tests_skipped_mailbox",
                    "passes",
                    "db_scans",
                ] {
                    assert_eq!(
                        x[k], y[k],
                        "{name}: {k} with {threads} threads, {memory} bytes"
                    );
                }
            }
        }
    }
    assert!(saved > 0, "the budget's store number saved no pass");
}

#[test]
fn the_paper_s_rules_do_their_work() {
    let dir = tempfile::tempdir().unwrap();
    let path = convert(
        &common::spd_fixtures().join("rings7.nff"),
        dir.path(),
        Compression::None,
    );
    let db = Database::open(&path).unwrap();
    let (_, st) = bf_render(&db, &opts(2, true), StoreNumber::Fixed(1), PLENTY);
    let x = st.details.unwrap();
    // The last-voxel rule and the mailbox both save tests.
    assert!(x["tests_skipped_last_voxel"].as_u64().unwrap() > 0);
    assert!(x["tests_skipped_mailbox"].as_u64().unwrap() > 0);
    // With the store number fixed at one, the remaining rays fall pass after
    // pass (Fig. 3a), and the adaptive store number needs fewer passes.
    let remaining = x["remaining_rays_per_pass"][0].as_array().unwrap();
    assert!(remaining.len() > 3);
    assert!(remaining.windows(2).all(|w| w[1].as_u64() <= w[0].as_u64()));
    let (_, ad) = bf_render(&db, &opts(2, true), StoreNumber::Adaptive, PLENTY);
    let y = ad.details.unwrap();
    let passes = |v: &serde_json::Value| {
        v["passes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p.as_u64().unwrap())
            .sum::<u64>()
    };
    assert!(
        passes(&y) < passes(&x),
        "adaptive {} vs fixed {}",
        passes(&y),
        passes(&x)
    );
    // Store numbers grow as rays finish.
    let sn = y["store_numbers"][0].as_array().unwrap();
    assert!(
        sn.last().unwrap().as_f64() > sn.first().unwrap().as_f64(),
        "{sn:?}"
    );
}

#[test]
fn too_small_a_budget_says_the_minimum() {
    let dir = tempfile::tempdir().unwrap();
    let path = convert(
        &common::spd_fixtures().join("balls4.nff"),
        dir.path(),
        Compression::None,
    );
    let db = Database::open(&path).unwrap();
    let b = BfOptions {
        memory: 64 << 10,
        store: StoreNumber::Adaptive,
        spill_dir: None,
        shading: Default::default(),
        models: Default::default(),
    };
    let e = bf::render(&db, &opts(1, true), &b, &NoProgress)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("too small") && e.contains("needs at least"),
        "{e}"
    );
}

/// Jittered supersampling: both tracers trace the same eye rays and agree;
/// the image differs from corner sampling but stays close to it.
#[test]
fn jittered_samples_agree_between_tracers() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["balls4", "teapot12"] {
        let path = convert(
            &common::spd_fixtures().join(format!("{name}.nff")),
            dir.path(),
            Compression::None,
        );
        let db = Database::open(&path).unwrap();
        let o = RenderOptions {
            samples: 4,
            ..opts(2, true)
        };
        let d = df::render(&db, &o, &NoProgress).unwrap();
        let b = bf_render(&db, &o, StoreNumber::Adaptive, 1 << 20);
        let dd = (d.frame.to_rgb8(), d.stats);
        assert_same(name, "4 samples", &dd, &b);
        assert_eq!(dd.1.rays.eye_rays, (SIZE * SIZE * 4) as u64);
        // More samples converge: 4 jittered samples are closer to 16 than
        // the corner-sampled image is.
        let sixteen = df::render(
            &db,
            &RenderOptions {
                samples: 16,
                ..opts(2, true)
            },
            &NoProgress,
        )
        .unwrap()
        .frame
        .to_rgb8();
        let mean_diff = |a: &[u8], b: &[u8]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| (*x as i64 - *y as i64).unsigned_abs())
                .sum::<u64>() as f64
                / a.len() as f64
        };
        let (e4, e1) = (
            mean_diff(&dd.0, &sixteen),
            mean_diff(&df_render(&db).0, &sixteen),
        );
        assert!(
            e4 < e1,
            "{name}: 4 samples {e4}, corners {e1} from 16 samples"
        );
    }
}

#[test]
fn passes_leave_unread_the_blocks_no_ray_is_near() {
    // tetra6 (4,096 triangles, about five 64 KiB blocks, in the
    // generator's recursive, spatially coherent order) in budgets that
    // take many passes: late passes have few rays, in a few places.
    let dir = tempfile::tempdir().unwrap();
    for c in [Compression::None, Compression::Zstd(3)] {
        let path = convert(&common::spd_fixtures().join("tetra6.nff"), dir.path(), c);
        let db = Database::open(&path).unwrap();
        assert!(db.block_count() >= 4, "{} blocks", db.block_count());
        let want = df_render(&db);
        // 64 MiB is enough for the passes to read ahead on a thread of
        // their own; 600 KiB is not.
        for memory in [64 << 20, 600 << 10] {
            let got = bf_render(&db, &opts(2, true), StoreNumber::Fixed(1), memory);
            assert_same("tetra6", c.name(), &want, &got);
            let x = got.1.details.unwrap();
            let scans = x["db_scans"].as_u64().unwrap();
            let skipped = x["db_blocks_skipped"].as_u64().unwrap();
            let read = x["db_bytes_read"].as_u64().unwrap();
            assert!(
                skipped > 0,
                "{}: no block skipped in {scans} scans",
                c.name()
            );
            // Every scan but the grids' build could have read every block.
            assert!(
                read < scans * db.file_bytes(),
                "{read} bytes in {scans} scans"
            );
            // The paper's shading join passes over blocks nobody hit: in
            // the small budget, where a round's hits need several shading
            // sets, it skips more than the intersection passes alone.
            let join = common::bf_render_with(
                &db,
                &opts(2, true),
                StoreNumber::Fixed(1),
                memory,
                bf::Shading::Join,
            );
            assert_same("tetra6", "join", &want, &join);
            let y = join.1.details.unwrap();
            let join_skipped = y["db_blocks_skipped"].as_u64().unwrap();
            if memory < 1 << 20 {
                assert!(join_skipped > skipped, "{join_skipped} vs {skipped}");
            }
            // The paper's passes (`--full-scans`, for `sray bench`): every
            // pass and every join reads every block; the same image.
            let mut full = db.clone();
            full.set_full_scans(true);
            let blocks_bytes = db.blocks_bytes();
            for shading in [bf::Shading::Carry, bf::Shading::Join] {
                let got = common::bf_render_with(
                    &full,
                    &opts(2, true),
                    StoreNumber::Fixed(1),
                    memory,
                    shading,
                );
                assert_same("tetra6", "full scans", &want, &got);
                let z = got.1.details.unwrap();
                assert_eq!(z["db_blocks_skipped"].as_u64(), Some(0));
                let scans = z["db_scans"].as_u64().unwrap();
                let read = z["db_bytes_read"].as_u64().unwrap();
                // A join stops after the last block holding a hit.
                match shading {
                    bf::Shading::Carry => assert_eq!(read, scans * blocks_bytes, "{scans} scans"),
                    _ => assert!(read <= scans * blocks_bytes, "{scans} scans"),
                }
            }
        }
    }
}

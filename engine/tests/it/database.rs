//! The object database: round trips, and a clear error (never a panic, never
//! a wrong scene) for every corrupt, truncated or foreign file.

use crate::common;

use sray_engine::Error;
use sray_engine::info::scene_info;
use sray_engine::progress::NoProgress;
use sray_engine::scene::recorder::Recorder;
use sray_engine::sdb::{Compression, Database, DbWriter};
use sray_engine::source::{SceneSource, stream_database};
use sray_engine::spd::SpdScene;
use std::path::{Path, PathBuf};

fn write_db(src: &SceneSource, path: &Path, c: Compression) {
    let mut w = DbWriter::create(path, c).unwrap();
    src.stream_into(&mut w, &NoProgress).unwrap();
    w.finish().unwrap();
}

/// Reads every object of the database; the first error, if any.
fn read_all(path: &Path) -> Result<u64, Error> {
    let db = Database::open(path)?;
    let mut n = 0;
    let mut scan = db.scan()?;
    while let Some(b) = scan.next_block()? {
        for o in b.objects() {
            std::hint::black_box(o.shape.bounds());
            n += 1;
        }
    }
    assert_eq!(n, db.object_count());
    Ok(n)
}

fn small_db(dir: &Path, c: Compression) -> PathBuf {
    let p = dir.join(format!("tree3-{}.sdb", c.name()));
    write_db(
        &SceneSource::Spd {
            scene: SpdScene::Tree,
            size: 3,
        },
        &p,
        c,
    );
    p
}

#[test]
fn round_trip_preserves_the_scene() {
    let dir = tempfile::tempdir().unwrap();
    for (name, size) in [("gears", 2), ("teapot", 3), ("rings", 2), ("mount", 3)] {
        for c in [Compression::None, Compression::Zstd(3)] {
            let src = SceneSource::Spd {
                scene: name.parse().unwrap(),
                size,
            };
            let path = dir.path().join("x.sdb");
            write_db(&src, &path, c);
            let mut direct = Recorder::default();
            src.stream_into(&mut direct, &NoProgress).unwrap();
            let mut replayed = Recorder::default();
            stream_database(&Database::open(&path).unwrap(), &mut replayed, &NoProgress).unwrap();
            // Materials are stored deduplicated, so compare objects and the
            // material in force for each.
            let objs = |r: &Recorder| r.objects().cloned().collect::<Vec<_>>();
            assert_eq!(objs(&direct), objs(&replayed), "{name} {c:?}");
        }
    }
}

#[test]
fn many_blocks_and_compression_read_alike() {
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().join("p.sdb");
    let z = dir.path().join("z.sdb");
    let src = SceneSource::Spd {
        scene: SpdScene::Tetra,
        size: 8,
    };
    write_db(&src, &plain, Compression::None);
    write_db(&src, &z, Compression::Zstd(1));
    let (a, b) = (Database::open(&plain).unwrap(), Database::open(&z).unwrap());
    assert!(a.block_count() > 3, "{}", a.block_count());
    // Triangle runs leave zstd less to find than records did.
    assert!(b.file_bytes() < a.file_bytes() * 4 / 5);
    let collect = |db: &Database| {
        let mut v = Vec::new();
        let mut s = db.scan().unwrap();
        while let Some(bl) = s.next_block().unwrap() {
            v.extend(bl.objects().map(|o| {
                (
                    o.index,
                    o.material,
                    o.bbox,
                    sray_engine::shapes::OwnedShape::from_shape(&o.shape),
                )
            }));
        }
        (v, s.stats().bytes_read)
    };
    let (va, ra) = collect(&a);
    let (vb, rb) = collect(&b);
    assert_eq!(va, vb);
    assert_eq!(va.len(), 65_536);
    assert!(va.iter().enumerate().all(|(i, o)| o.0 as usize == i));
    // Bytes read are the stored bytes: all of the blocks, nothing more.
    assert_eq!(ra, a.file_bytes() - 256 - tables_len(&a));
    assert!(rb < ra * 4 / 5);
    // Both store the triangles as runs, 4,456,448 bytes of records in
    // about an eighth of that.
    assert!(a.has_runs() && b.has_runs());
    assert_eq!(a.decoded_bytes(), 65_536 * 68);
    assert_eq!(a.run_counts().run_triangles, 65_536);
    assert!(a.raw_bytes() < a.decoded_bytes() / 6, "{}", a.raw_bytes());
}

fn tables_len(db: &Database) -> u64 {
    let s = db.scene();
    let classes = db.sizes().classes.iter().filter(|c| c.count > 0).count();
    // The density summary: lattice level and origin, entry count, entries.
    let cells = db.density().map_or(0, |d| d.entries.len());
    (11 * 8
        + 8
        + 12
        + 4
        + 40 * s.lights.len()
        + 4
        + 32 * s.materials.len()
        + 4
        + 36 * classes
        + 4
        + 24
        + 4
        + 40 * cells) as u64
}

#[test]
fn every_flipped_byte_is_detected() {
    let dir = tempfile::tempdir().unwrap();
    for c in [Compression::None, Compression::Zstd(3)] {
        let path = small_db(dir.path(), c);
        let good = std::fs::read(&path).unwrap();
        assert!(read_all(&path).is_ok());
        let bad = dir.path().join("bad.sdb");
        for i in 0..good.len() {
            for mask in [0x01u8, 0x80] {
                let mut b = good.clone();
                b[i] ^= mask;
                std::fs::write(&bad, &b).unwrap();
                match read_all(&bad) {
                    Err(Error::Database {
                        location, message, ..
                    }) => {
                        assert!(!location.is_empty() && !message.is_empty());
                    }
                    Err(e) => panic!("byte {i}: unexpected error kind {e}"),
                    Ok(_) => panic!("byte {i} flipped with {mask:#x} went unnoticed ({c:?})"),
                }
            }
        }
    }
}

#[test]
fn every_truncation_is_detected() {
    let dir = tempfile::tempdir().unwrap();
    let path = small_db(dir.path(), Compression::Zstd(3));
    let good = std::fs::read(&path).unwrap();
    let bad = dir.path().join("short.sdb");
    for len in 0..good.len() {
        std::fs::write(&bad, &good[..len]).unwrap();
        let e = read_all(&bad).unwrap_err();
        assert!(matches!(e, Error::Database { .. }), "length {len}: {e}");
    }
    // And trailing junk.
    let mut long = good.clone();
    long.extend_from_slice(b"junk");
    std::fs::write(&bad, &long).unwrap();
    assert!(read_all(&bad).is_err());
}

#[test]
fn errors_name_the_block() {
    let dir = tempfile::tempdir().unwrap();
    let src = SceneSource::Spd {
        scene: SpdScene::Tetra,
        size: 8,
    };
    let path = dir.path().join("t.sdb");
    write_db(&src, &path, Compression::None);
    let mut b = std::fs::read(&path).unwrap();
    // A byte in the middle of the file is in some block after the first.
    let mid = b.len() / 2;
    b[mid] ^= 0x10;
    std::fs::write(&path, &b).unwrap();
    let e = read_all(&path).unwrap_err().to_string();
    assert!(
        e.contains("t.sdb: block ") && e.contains("checksum mismatch"),
        "{e}"
    );
    assert!(!e.contains("block 0 "), "{e}");
}

#[test]
fn wrong_magic_and_wrong_version() {
    let dir = tempfile::tempdir().unwrap();
    let path = small_db(dir.path(), Compression::None);
    let good = std::fs::read(&path).unwrap();
    let bad = dir.path().join("bad.sdb");

    std::fs::write(&bad, b"p 3\n0 0 0\n").unwrap();
    let e = Database::open(&bad).unwrap_err().to_string();
    assert!(e.contains("wrong magic"), "{e}");

    // A future version with a valid header checksum (2 is a database
    // whose geometry is relative to an origin, 3 one with a density
    // summary, 4 one with triangle runs, 5 one with models, 6 one in
    // spatial order, 7 one with glTF materials and lights, 8 one with
    // textures, 9 one with tiled textures).
    let mut b = good.clone();
    b[8..12].copy_from_slice(&10u32.to_le_bytes());
    let crc = crc32fast::hash(&b[..252]);
    b[252..256].copy_from_slice(&crc.to_le_bytes());
    std::fs::write(&bad, &b).unwrap();
    let e = Database::open(&bad).unwrap_err().to_string();
    assert!(e.contains("version 10 is not supported"), "{e}");
}

#[test]
fn info_agrees_between_nff_and_database() {
    let dir = tempfile::tempdir().unwrap();
    for (name, size) in common::DEFAULT_SCENES {
        let nff = common::spd_fixtures().join(format!("{name}{size}.nff"));
        for c in [Compression::None, Compression::Zstd(5)] {
            let db = dir.path().join(format!("{name}.sdb"));
            write_db(&SceneSource::nff(nff.clone()), &db, c);
            let a = scene_info(&nff, &NoProgress).unwrap();
            let b = scene_info(&db, &NoProgress).unwrap();
            assert_eq!(
                (a.objects, a.counts, a.lights),
                (b.objects, b.counts, b.lights),
                "{name}"
            );
            assert_eq!(
                (a.materials, a.material_statements),
                (b.materials, b.material_statements),
                "{name}"
            );
            assert_eq!((a.bbox_min, a.bbox_max), (b.bbox_min, b.bbox_max), "{name}");
            assert_eq!(b.compression, c.name());
        }
    }
}

#[test]
fn unfinished_writer_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("never.sdb");
    {
        let mut w = DbWriter::create(&path, Compression::None).unwrap();
        SceneSource::Spd {
            scene: SpdScene::Balls,
            size: 2,
        }
        .stream_into(&mut w, &NoProgress)
        .unwrap();
        // dropped without finish()
    }
    assert!(!path.exists());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "temporary file left behind"
    );
}

/// Checksums and records are checked by the first full scan only; a file
/// changed after it was opened (so no longer the file that was checked) is
/// refused by the next scan instead of being trusted, and `scan_checked`
/// checks every block again.
#[test]
fn later_scans_trust_only_the_file_that_was_checked() {
    let dir = tempfile::tempdir().unwrap();
    for c in [Compression::None, Compression::Zstd(3)] {
        let path = small_db(dir.path(), c);
        let db = Database::open(&path).unwrap();
        for _ in 0..3 {
            let mut scan = db.scan().unwrap();
            let mut n = 0;
            while let Some(b) = scan.next_block().unwrap() {
                n += b.objects().count() as u64;
            }
            assert_eq!(n, db.object_count());
        }
        // Flip a byte inside the first block, after the checks were done.
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[600] ^= 0x40;
        std::thread::sleep(std::time::Duration::from_millis(20));
        std::fs::write(&path, &bytes).unwrap();
        let err = match db.scan() {
            Err(e) => e.to_string(),
            Ok(_) => panic!("a changed file was scanned ({c:?})"),
        };
        assert!(err.contains("changed on disk"), "{err}");
        // Reopened, the file is checked again and the flipped byte found.
        let checked = |db: &Database| -> Result<(), Error> {
            let mut scan = db.scan_checked()?;
            while scan.next_block()?.is_some() {}
            Ok(())
        };
        let failed = Database::open(&path).and_then(|db| checked(&db)).is_err();
        assert!(failed, "the flipped byte went unnoticed ({c:?})");
    }
}

/// A scan read ahead on a thread of its own gives the blocks, the
/// prepared data and the counters of a scan on the caller's thread; it
/// passes over the blocks it is told to skip once the layout is known,
/// and stops at the first error of either side.
#[test]
fn read_ahead_scans_agree_with_plain_scans_and_stop_on_errors() {
    use sray_engine::sdb::scan_blocks;
    let dir = tempfile::tempdir().unwrap();
    for c in [Compression::None, Compression::Zstd(3)] {
        let path = write_tetra(dir.path(), c);
        let db = Database::open(&path).unwrap();
        assert!(db.block_count() >= 4, "{} blocks", db.block_count());
        let run = |ahead: usize, skip: &(dyn Fn(u64) -> bool + Sync)| {
            let mut seen = Vec::new();
            let stats = scan_blocks::<u64>(
                db.scan().unwrap(),
                ahead,
                skip,
                &|b, p| *p = b.words().iter().map(|&w| w as u64).sum(),
                &mut |batch| {
                    for (b, p) in batch {
                        seen.push((b.index, b.first_object, b.object_count, **p));
                    }
                    Ok(())
                },
            )
            .unwrap();
            (seen, stats.bytes_read, stats.blocks_skipped)
        };
        // The first scan learns the layout: nothing is skipped yet.
        let all = run(0, &|i| i % 2 == 1);
        assert_eq!(all.0.len() as u64, db.block_count());
        assert_eq!(all.2, 0);
        let odd = |i: u64| i % 2 == 1;
        let plain = run(0, &odd);
        // Batches of any size, smaller and larger than the blocks.
        for batch in [1, 3, 32] {
            assert_eq!(run(batch, &|_| false), all, "batches of {batch}");
            assert_eq!(run(batch, &odd), plain, "batches of {batch}");
        }
        assert!(plain.0.iter().all(|b| b.0 % 2 == 0));
        assert_eq!(plain.2, db.block_count() / 2);
        assert!(plain.1 < all.1);
        // The caller's error stops the scan and is returned.
        for ahead in [0, 3, 32] {
            let mut n = 0;
            let e = scan_blocks::<()>(
                db.scan().unwrap(),
                ahead,
                &|_| false,
                &|_, _| {},
                &mut |_| {
                    // (A read-ahead scan gives blocks in batches: the
                    // first call may hold them all.)
                    n += 1;
                    Err(Error::Invalid("stop here".into()))
                },
            )
            .unwrap_err();
            assert!(e.to_string().contains("stop here"), "{e}");
            assert_eq!(n, 1);
        }
        // A corrupt block found by the reader thread is an error, after
        // the blocks before it.
        let mut bytes = std::fs::read(&path).unwrap();
        // Halfway through the blocks (the tables follow them).
        let at = 256 + (bytes.len() - 256 - tables_len(&db) as usize) / 2;
        bytes[at] ^= 0x10;
        let bad = dir.path().join("bad.sdb");
        std::fs::write(&bad, &bytes).unwrap();
        let db = Database::open(&bad).unwrap();
        let mut n = 0u64;
        let e = scan_blocks::<()>(
            db.scan().unwrap(),
            3,
            &|_| false,
            &|_, _| {},
            &mut |batch| {
                n += batch.len() as u64;
                Ok(())
            },
        )
        .unwrap_err();
        assert!(matches!(e, Error::Database { .. }), "{e}");
        assert!(n > 0 && n < db.block_count(), "{n} blocks before the error");
    }
}

fn write_tetra(dir: &Path, c: Compression) -> PathBuf {
    let p = dir.join(format!("tetra6-{}.sdb", c.name()));
    write_db(
        &SceneSource::Spd {
            scene: SpdScene::Tetra,
            size: 6,
        },
        &p,
        c,
    );
    p
}

/// A database written before version 3 (no density summary) still opens,
/// plans its grids from the size summary alone, and renders exactly as
/// the same scene converted today, in both tracers.
#[test]
fn databases_of_version_1_still_read_and_render() {
    use sray_engine::bf::StoreNumber;
    use sray_engine::render::RenderOptions;
    let old = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/db/gears1-v1-zstd.sdb");
    let old = Database::open(&old).unwrap();
    assert!(old.density().is_none());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("gears1.sdb");
    let src = SceneSource::Spd {
        scene: SpdScene::Gears,
        size: 1,
    };
    write_db(&src, &path, Compression::Zstd(3));
    let new = Database::open(&path).unwrap();
    assert!(new.density().is_some_and(|d| d.usable()));
    assert_eq!(old.object_count(), new.object_count());
    let o = RenderOptions {
        width: 32,
        height: 32,
        max_depth: 3,
        ..Default::default()
    };
    let want = common::df_render(&new, &o);
    assert_eq!(common::df_render(&old, &o).0, want.0);
    let bf = common::bf_render(&old, &o, StoreNumber::Adaptive, 1 << 30);
    assert_eq!(bf.0, want.0);
}

/// Every block of `db`: its first object, object count and records.
fn blocks(db: &Database) -> Vec<(u64, u32, Vec<u32>)> {
    let mut v = Vec::new();
    let mut s = db.scan().unwrap();
    while let Some(b) = s.next_block().unwrap() {
        v.push((b.first_object, b.object_count, b.words().to_vec()));
    }
    v
}

#[test]
fn triangle_runs_read_back_the_records_of_version_3_bit_for_bit() {
    // Real meshes no one here wrote, and SPD scenes of every kind, written
    // as version 3 (records) and as version 4 (triangle runs), plain and
    // compressed: the blocks read back hold the same records, so every
    // tracer sees the same scene. Bounds on bytes per triangle hold what
    // runs gain on meshes whose file order is coherent.
    let dir = tempfile::tempdir().unwrap();
    let mut sources: Vec<(String, SceneSource, Option<f64>)> = [
        (SpdScene::Tetra, 5, Some(9.0)),
        (SpdScene::Mount, 5, Some(11.0)),
        (SpdScene::Gears, 2, None),
        (SpdScene::Balls, 2, None),
        (SpdScene::Teapot, 6, Some(22.0)),
    ]
    .into_iter()
    .map(|(scene, size, most)| {
        (
            format!("{scene:?}{size}"),
            SceneSource::Spd { scene, size },
            most,
        )
    })
    .collect();
    if let Some(m) = common::shared_meshes() {
        for (f, most) in [
            ("dragon_vrip_res4.ply.gz", Some(21.0)),
            ("spot.obj", Some(16.0)),
            ("fandisk.obj", Some(11.0)),
            ("armadillo.off", None),
            ("horse.ply", Some(50.0)),
        ] {
            let src = SceneSource::parse(m.join(f).to_str().unwrap()).unwrap();
            sources.push((f.to_string(), src, most));
        }
    }
    for (name, src, most) in sources {
        for c in [Compression::None, Compression::Zstd(3)] {
            let (old, new) = (dir.path().join("v3.sdb"), dir.path().join("v4.sdb"));
            for (path, runs) in [(&old, false), (&new, true)] {
                common::write_converted(&src, path, c, runs);
            }
            let (a, b) = (Database::open(&old).unwrap(), Database::open(&new).unwrap());
            assert_eq!((a.version(), b.version()), (3, 4));
            // A file without a run (no triangles) is read as version 3 is.
            assert!(!a.has_runs());
            assert_eq!(b.has_runs(), b.run_counts().runs > 0, "{name}");
            assert_eq!(a.decoded_bytes(), b.decoded_bytes(), "{name}");
            assert!(blocks(&a) == blocks(&b), "{name} {c:?}: records differ");
            if let (Some(most), Compression::None) = (most, c) {
                let per = b.raw_bytes() as f64 / b.triangles().unwrap() as f64;
                assert!(per <= most, "{name}: {per:.1} bytes per triangle");
                assert!(b.run_counts().run_triangles * 100 > b.object_count() * 95);
            }
        }
    }
}

#[test]
fn a_header_that_lies_about_runs_is_an_error() {
    // tetra5 stores its triangles as runs, in several blocks. Each field
    // is changed with the header's checksum made right again, as a
    // careless tool would.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.sdb");
    write_db(
        &SceneSource::Spd {
            scene: SpdScene::Tetra,
            size: 5,
        },
        &path,
        Compression::None,
    );
    let good = std::fs::read(&path).unwrap();
    let db = Database::open(&path).unwrap();
    assert!(db.has_runs() && db.block_count() > 1);
    let bad = dir.path().join("bad.sdb");
    // Offsets of the header's fields (sdb::format::RawHeader).
    const BLOCK_RAW_MAX: usize = 24;
    const DECODED_BYTES: usize = 216;
    const RUNS: usize = 224;
    const BLOCK_STORED_MAX: usize = 240;
    let u32_at = |b: &[u8], at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
    let u64_at = |b: &[u8], at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap());
    let with = |at: usize, bytes: &[u8]| {
        let mut b = good.clone();
        b[at..at + bytes.len()].copy_from_slice(bytes);
        let crc = crc32fast::hash(&b[..252]);
        b[252..256].copy_from_slice(&crc.to_le_bytes());
        std::fs::write(&bad, &b).unwrap();
    };
    let decoded = u64_at(&good, DECODED_BYTES);
    assert_eq!(decoded, Database::open(&path).unwrap().decoded_bytes());
    let raw_max = u32_at(&good, BLOCK_RAW_MAX);

    // Caught at open.
    with(DECODED_BYTES, &(decoded * 1000).to_le_bytes());
    let e = Database::open(&bad).unwrap_err().to_string();
    assert!(e.contains("expanded size"), "{e}");
    with(BLOCK_STORED_MAX, &(raw_max + 4).to_le_bytes());
    let e = Database::open(&bad).unwrap_err().to_string();
    assert!(e.contains("block size"), "{e}");
    // Caught by the first scan.
    for (at, bytes, says) in [
        (
            DECODED_BYTES,
            (decoded + 4).to_le_bytes().to_vec(),
            "bytes of records",
        ),
        (RUNS, 0u64.to_le_bytes().to_vec(), "unknown kind"),
        (
            BLOCK_STORED_MAX,
            64u32.to_le_bytes().to_vec(),
            "out of range",
        ),
    ] {
        with(at, &bytes);
        let e = read_all(&bad).unwrap_err().to_string();
        assert!(e.contains(says), "{e}");
    }
}

/// A version 6 block whose header claims two billion objects, with ids
/// of zero bits each (the fuzzer's find: a tiny file that asked for
/// 8 GB of ids): an error before anything is decoded for them.
#[test]
fn a_block_claiming_more_objects_than_the_file_has_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.sdb");
    let mut w = sray_engine::sdb::DbWriter::create(&path, Compression::None)
        .unwrap()
        .spatial(1 << 20, Some(dir.path()));
    sray_engine::source::SceneSource::Spd {
        scene: SpdScene::Tree,
        size: 1,
    }
    .stream_into(&mut w, &sray_engine::progress::NoProgress)
    .unwrap();
    w.finish().unwrap();
    assert!(Database::open(&path).unwrap().is_spatial());
    let mut b = std::fs::read(&path).unwrap();
    // Block 0's header follows the 256-byte file header: object_count at
    // 16, its payload's length at 24, the CRC (of the header with a zero
    // CRC, then the payload) at 28.
    const H: usize = 256;
    b[H + 16..H + 20].copy_from_slice(&0x8000_0007u32.to_le_bytes());
    // The ids' header: the smallest id 0, width 0.
    b[H + 32..H + 40].copy_from_slice(&[0; 8]);
    let len = u32::from_le_bytes(b[H + 24..H + 28].try_into().unwrap()) as usize;
    b[H + 28..H + 32].copy_from_slice(&[0; 4]);
    let mut c = crc32fast::Hasher::new();
    c.update(&b[H..H + 32]);
    c.update(&b[H + 32..H + 32 + len]);
    b[H + 28..H + 32].copy_from_slice(&c.finalize().to_le_bytes());
    std::fs::write(&path, &b).unwrap();
    let e = read_all(&path).unwrap_err().to_string();
    assert!(e.contains("block 0") && e.contains("more objects"), "{e}");
}

/// In spatial order a block ends where a group of 64 objects (an
/// aggregate's) begins, so that no aggregate is cut and a pass that
/// passes over a block passes over whole aggregates; in input order
/// blocks end where their bytes say, as before.
#[test]
fn spatial_blocks_begin_where_a_group_of_objects_begins() {
    let dir = tempfile::tempdir().unwrap();
    let firsts = |spatial: bool| {
        let path = dir.path().join(format!("t{spatial}.sdb"));
        let mut w = sray_engine::sdb::DbWriter::create(&path, Compression::None).unwrap();
        if spatial {
            w = w.spatial(1 << 20, Some(dir.path()));
        }
        sray_engine::source::SceneSource::Spd {
            scene: SpdScene::Gears,
            size: 3,
        }
        .stream_into(&mut w, &sray_engine::progress::NoProgress)
        .unwrap();
        w.finish().unwrap();
        let db = Database::open(&path).unwrap();
        let mut scan = db.scan().unwrap();
        let mut firsts = Vec::new();
        while let Some(b) = scan.next_block().unwrap() {
            firsts.push(b.first_object);
        }
        firsts
    };
    let spatial = firsts(true);
    assert!(spatial.len() > 3, "{spatial:?}");
    let group = sray_engine::grid::aggregate::SIZE as u64;
    assert!(spatial.iter().all(|f| f % group == 0), "{spatial:?}");
    let input = firsts(false);
    assert!(input.iter().any(|f| f % group != 0), "{input:?}");
}

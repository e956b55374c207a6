//! The SPD generators against real SPD output (tests/fixtures/spd) and
//! against the object counts of the paper's Tables 2 and 3.

use crate::common;

use common::{DEFAULT_SCENES, spd_fixtures};
use sray_engine::Error;
use sray_engine::nff::read_nff;
use sray_engine::progress::NoProgress;
use sray_engine::scene::recorder::{Event, Recorder};
use sray_engine::scene::{Light, Material, SceneSink, View};
use sray_engine::sdb::{Compression, DbWriter};
use sray_engine::shapes::Shape;
use sray_engine::spd::SpdScene;

fn generated(name: &str, size: u32) -> Recorder {
    let scene: SpdScene = name.parse().unwrap();
    let mut r = Recorder::default();
    scene.generate(size, &mut r, &NoProgress).unwrap();
    r
}

fn from_file(name: &str, size: u32) -> Recorder {
    let mut r = Recorder::default();
    read_nff(
        &spd_fixtures().join(format!("{name}{size}.nff")),
        &mut r,
        &NoProgress,
    )
    .unwrap();
    r
}

/// Same objects in the same order, same kinds, materials, lights, camera
/// and background; coordinates within 1e-4 of the scene's extent.
#[test]
fn generators_reproduce_the_seven_shared_scenes() {
    for (name, size) in DEFAULT_SCENES {
        let gen_ = generated(name, size);
        let file = from_file(name, size);
        assert_eq!(
            gen_.events.len(),
            file.events.len(),
            "{name}: number of statements"
        );
        // The scene's extent, from the file's objects.
        let mut bb = sray_engine::scene::Aabb::EMPTY;
        for o in file.objects() {
            bb.union(&o.shape().bounds());
        }
        let tol = 1e-4 * bb.extent().into_iter().fold(0.0, f64::max);
        let mut worst = 0.0f64;
        for (i, (g, f)) in gen_.events.iter().zip(&file.events).enumerate() {
            match (g, f) {
                (Event::Object(a), Event::Object(b)) => {
                    assert_eq!(a.kind, b.kind, "{name}: statement {i}");
                    let (na, nb) = (a.numbers(), b.numbers());
                    assert_eq!(na.len(), nb.len(), "{name}: statement {i} vertex count");
                    for (x, y) in na.iter().zip(nb) {
                        worst = worst.max((*x as f64 - *y as f64).abs());
                    }
                }
                (a, b) => assert_eq!(a, b, "{name}: statement {i}"),
            }
        }
        assert!(
            worst <= tol,
            "{name}: coordinates differ by up to {worst}, tolerance {tol}"
        );
    }
}

fn database_bytes(source: &Recorder, dir: &std::path::Path, name: &str) -> Vec<u8> {
    let path = dir.join(name);
    let mut w = DbWriter::create(&path, Compression::None).unwrap();
    source.replay(&mut w).unwrap();
    w.finish().unwrap();
    std::fs::read(&path).unwrap()
}

/// Generating `spd:NAME:SIZE` and converting the SPD's NFF file give
/// byte-identical object databases, so both render identically.
#[test]
fn generated_and_converted_databases_are_identical() {
    let dir = tempfile::tempdir().unwrap();
    for (name, size) in DEFAULT_SCENES {
        let a = database_bytes(&generated(name, size), dir.path(), "gen.sdb");
        let b = database_bytes(&from_file(name, size), dir.path(), "nff.sdb");
        assert!(a == b, "{name}{size}: databases differ");
    }
}

/// Counts objects without keeping them.
#[derive(Default)]
struct Count(u64);

impl SceneSink for Count {
    fn background(&mut self, _: [f32; 3]) -> Result<(), Error> {
        Ok(())
    }
    fn view(&mut self, _: &View) -> Result<(), Error> {
        Ok(())
    }
    fn light(&mut self, _: &Light) -> Result<(), Error> {
        Ok(())
    }
    fn material(&mut self, _: &Material) -> Result<(), Error> {
        Ok(())
    }
    fn object(&mut self, _: &Shape<'_>) -> Result<(), Error> {
        self.0 += 1;
        Ok(())
    }
}

fn count(name: &str, size: u32) -> u64 {
    let scene: SpdScene = name.parse().unwrap();
    let mut c = Count::default();
    scene.generate(size, &mut c, &NoProgress).unwrap();
    let predicted = scene.object_count(size).unwrap();
    assert_eq!(
        c.0, predicted,
        "{name} {size}: generated vs predicted count"
    );
    c.0
}

/// Table 2 of the paper (object counts per size factor).
#[test]
fn table2_object_counts() {
    let table: &[(&str, u32, u64)] = &[
        ("balls", 4, 7_382),
        ("balls", 5, 66_431),
        ("balls", 6, 597_872),
        ("gears", 4, 9_345),
        ("gears", 5, 18_251),
        ("gears", 6, 31_537),
        ("gears", 7, 50_079),
        ("gears", 8, 74_753),
        ("gears", 9, 106_435),
        ("gears", 10, 146_001),
        ("mount", 6, 8_196),
        ("mount", 7, 32_772),
        ("mount", 8, 131_076),
        ("rings", 7, 8_401),
        ("rings", 10, 23_101),
        ("rings", 13, 49_141),
        ("rings", 16, 89_761),
        ("rings", 17, 107_101),
        ("tetra", 6, 4_096),
        ("tetra", 7, 16_384),
        ("tetra", 8, 65_536),
        ("tetra", 9, 262_144),
        ("tree", 11, 8_191),
        ("tree", 12, 16_383),
        ("tree", 13, 32_767),
        ("tree", 14, 65_535),
        ("tree", 15, 131_071),
        ("tree", 16, 262_143),
    ];
    for &(name, size, expect) in table {
        assert_eq!(count(name, size), expect, "{name} {size}");
    }
}

/// Table 3 of the paper: the three large scenes, generated in full.
#[test]
fn table3_object_counts() {
    let big = [
        ("mount", 11, 8_388_612u64),
        ("rings", 80, 10_432_801),
        ("tetra", 12, 16_777_216),
    ];
    let handles: Vec<_> = big
        .into_iter()
        .map(|(n, s, e)| std::thread::spawn(move || (n, count(n, s), e)))
        .collect();
    for h in handles {
        let (n, got, expect) = h.join().unwrap();
        assert_eq!(got, expect, "{n}");
    }
}

#[test]
fn teapot_counts_match_the_spd_formula_at_small_sizes() {
    // 65 n^2 - 8 n: n^2 squares and 64 n^2 triangles less 8 n degenerate.
    for n in 1..=6 {
        count("teapot", n);
    }
}

#[test]
fn sizes_out_of_range_are_refused() {
    for scene in SpdScene::ALL {
        let mut c = Count::default();
        let e = scene.generate(0, &mut c, &NoProgress).unwrap_err();
        assert!(e.to_string().contains("out of range"), "{e}");
        let e = scene
            .generate(scene.max_size() + 1, &mut c, &NoProgress)
            .unwrap_err();
        assert!(e.to_string().contains("out of range"), "{e}");
        assert_eq!(c.0, 0);
    }
}

//! Helpers shared by the engine's integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

/// The seven default SPD scenes as NFF, written by the SPD programs (real
/// input no one here wrote): the vendored copies in `tests/fixtures/spd`
/// at the workspace root, or `$SRAY_SHARED_DIR/spd` when that variable is
/// set.
pub fn spd_fixtures() -> PathBuf {
    if let Ok(d) = std::env::var("SRAY_SHARED_DIR") {
        return PathBuf::from(d).join("spd");
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/spd")
}

/// Whether this runs in CI (`CI=true`, which `.ci/run` exports): there,
/// a test must not skip for want of ../shared.
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true" || v == "1")
}

/// `shared/meshes` beside the repository (`$SRAY_SHARED_DIR/meshes` when
/// that is set): real meshes, not vendored; CI has them. When it is
/// absent, says so on stderr and returns None, so that the caller can
/// skip: `let Some(m) = shared_meshes() else { return };`; in CI, fails
/// saying so instead.
pub fn shared_meshes() -> Option<PathBuf> {
    let m = match std::env::var("SRAY_SHARED_DIR") {
        Ok(d) => Some(PathBuf::from(d).join("meshes")).filter(|d| d.is_dir()),
        Err(_) => std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .ancestors()
            .map(|d| d.join("shared").join("meshes"))
            .find(|d| d.is_dir()),
    };
    if m.is_none() {
        let why = format!(
            "../shared/meshes not found (searched upward from {} for shared/meshes; set \
             SRAY_SHARED_DIR to its parent)",
            env!("CARGO_MANIFEST_DIR")
        );
        assert!(
            !in_ci(),
            "{why}; in CI (CI=true) this test must run, not skip: .ci/run expects ../shared \
             beside the repository"
        );
        eprintln!("skipping: {why}");
    }
    m
}

/// The seven default scenes and their files.
pub const DEFAULT_SCENES: [(&str, u32); 7] = [
    ("balls", 4),
    ("gears", 4),
    ("mount", 6),
    ("rings", 7),
    ("tetra", 6),
    ("tree", 11),
    ("teapot", 12),
];

use sray_engine::bf::{self, BfOptions, Shading, StoreNumber};
use sray_engine::progress::NoProgress;
use sray_engine::render::{RenderOptions, RenderStats};
use sray_engine::sdb::Database;

/// An image's RGB bytes and the render's statistics.
pub type Render = (Vec<u8>, RenderStats);

/// A depth-first render.
pub fn df_render(db: &Database, o: &RenderOptions) -> Render {
    let out = sray_engine::df::render(db, o, &NoProgress).unwrap();
    (out.frame.to_rgb8(), out.stats)
}

/// A breadth-first render with the given store number and budget.
pub fn bf_render(db: &Database, o: &RenderOptions, store: StoreNumber, memory: u64) -> Render {
    bf_render_with(db, o, store, memory, Shading::Carry)
}

/// As [`bf_render`], shading as given.
pub fn bf_render_with(
    db: &Database,
    o: &RenderOptions,
    store: StoreNumber,
    memory: u64,
    shading: Shading,
) -> Render {
    let b = BfOptions {
        memory,
        store,
        spill_dir: None,
        shading,
        models: Default::default(),
    };
    let out = bf::render(db, o, &b, &NoProgress).unwrap();
    (out.frame.to_rgb8(), out.stats)
}

/// Writes `src` to a database at `path` as `sray convert` does (a mesh
/// gets its default view and lights); `runs: false` writes version 3
/// records instead of version 4 triangle runs.
pub fn write_converted(
    src: &sray_engine::source::SceneSource,
    path: &std::path::Path,
    c: sray_engine::sdb::Compression,
    runs: bool,
) {
    use sray_engine::scene::setup::{Setup, SetupSink};
    let mut w = sray_engine::sdb::DbWriter::create(path, c).unwrap();
    if !runs {
        w = w.without_runs();
    }
    let setup = Setup::default();
    let mut s = SetupSink::new(&mut w, &setup);
    src.stream_into(&mut s, &NoProgress).unwrap();
    s.finish().unwrap();
    w.finish().unwrap();
}

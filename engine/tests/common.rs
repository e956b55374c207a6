//! Helpers shared by the engine's integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

/// `shared/spd`, the real SPD output that sits beside the repository
/// (override with SRAY_SHARED_DIR). CI always has it.
pub fn shared_spd() -> PathBuf {
    if let Ok(d) = std::env::var("SRAY_SHARED_DIR") {
        return PathBuf::from(d).join("spd");
    }
    let mut dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    loop {
        let cand = dir.join("shared").join("spd");
        if cand.is_dir() {
            return cand;
        }
        if !dir.pop() {
            panic!(
                "cannot find shared/spd beside the repository (set SRAY_SHARED_DIR); \
                 these tests check sray against real SPD output"
            );
        }
    }
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

use sray_engine::bf::{self, BfOptions, StoreNumber};
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
    let b = BfOptions {
        memory,
        store,
        spill_dir: None,
    };
    let out = bf::render(db, o, &b, &NoProgress).unwrap();
    (out.frame.to_rgb8(), out.stats)
}

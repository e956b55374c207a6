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

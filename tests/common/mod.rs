//! Helpers for the end-to-end tests: run the real `sray` binary.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn sray() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sray"))
}

/// Runs `sray ARGS` in `dir`.
pub fn run(dir: &Path, args: &[&str]) -> Output {
    sray()
        .current_dir(dir)
        .args(args)
        .output()
        .expect("run sray")
}

/// Runs and requires success; returns stdout.
pub fn ok(dir: &Path, args: &[&str]) -> String {
    let o = run(dir, args);
    assert!(
        o.status.success(),
        "sray {args:?} failed: {}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

/// Runs and requires failure; returns stderr.
pub fn fails(dir: &Path, args: &[&str]) -> String {
    let o = run(dir, args);
    assert!(!o.status.success(), "sray {args:?} should have failed");
    let err = String::from_utf8(o.stderr).unwrap();
    assert!(!err.contains("panicked"), "sray {args:?} panicked:\n{err}");
    err
}

/// `shared/spd` beside the repository (override with SRAY_SHARED_DIR).
pub fn shared_spd() -> PathBuf {
    if let Ok(d) = std::env::var("SRAY_SHARED_DIR") {
        return PathBuf::from(d).join("spd");
    }
    let mut dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    loop {
        let c = dir.join("shared").join("spd");
        if c.is_dir() {
            return c;
        }
        assert!(
            dir.pop(),
            "cannot find shared/spd beside the repository (set SRAY_SHARED_DIR)"
        );
    }
}

pub fn json(s: &str) -> serde_json::Value {
    serde_json::from_str(s).unwrap_or_else(|e| panic!("not JSON ({e}):\n{s}"))
}

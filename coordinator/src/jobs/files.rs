//! The journal's files: each written crash-safely, the rounds' files
//! named by round, and the stale ones cleared.

use anyhow::Context;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

pub(super) fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// Writes `name` in `dir` crash-safely: a temporary file, fsync, rename,
/// fsync of the directory.
pub fn write_atomic(
    dir: &Path,
    name: &str,
    fill: impl FnOnce(&mut BufWriter<&File>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let tmp = dir.join(format!("{name}.tmp"));
    let f = File::create(&tmp).with_context(|| tmp.display().to_string())?;
    {
        let mut w = BufWriter::with_capacity(1 << 20, &f);
        fill(&mut w)?;
        w.flush().with_context(|| tmp.display().to_string())?;
    }
    f.sync_all().with_context(|| tmp.display().to_string())?;
    drop(f);
    let path = dir.join(name);
    std::fs::rename(&tmp, &path).with_context(|| path.display().to_string())?;
    File::open(dir)
        .and_then(|d| d.sync_all())
        .with_context(|| dir.display().to_string())?;
    Ok(())
}

pub(super) fn unhex(s: &str) -> Option<Vec<u8>> {
    if !s.len().is_multiple_of(2) {
        return None;
    }
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(s.get(i..i + 2)?, 16).ok())
        .collect()
}

/// The round of the newest checkpoint frame in `dir`.
pub(super) fn latest_frame(dir: &Path) -> Option<u32> {
    std::fs::read_dir(dir)
        .ok()?
        .flatten()
        .filter_map(|f| {
            f.file_name()
                .to_str()?
                .strip_prefix("frame-")?
                .strip_suffix(".bin")?
                .parse::<u32>()
                .ok()
        })
        .max()
}

/// Removes temporary files and the files of rounds other than `keep`.
pub(super) fn remove_stale(dir: &Path, keep: Option<u32>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    for f in rd.flatten() {
        let name = f.file_name().to_string_lossy().to_string();
        let round_file = name
            .strip_suffix(".bin")
            .and_then(|s| s.strip_prefix("rays-").or_else(|| s.strip_prefix("frame-")))
            .and_then(|n| n.parse::<u32>().ok());
        let stale = name.ends_with(".tmp") || round_file.is_some_and(|r| Some(r) != keep);
        if stale {
            let _ = std::fs::remove_file(f.path());
        }
    }
}

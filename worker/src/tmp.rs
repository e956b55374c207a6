//! The worker's own spill directory: `sray-worker-PID-RANDOM` under its
//! `--tmp-dir`, locked (an exclusive `flock` on its `lock` file) for as
//! long as the worker lives, and removed when it ends. A worker that was
//! killed (SIGKILL, power loss) leaves its directory behind, unlocked: the
//! next worker started on the same `--tmp-dir` removes it. Several live
//! workers may share a `--tmp-dir`: a locked directory is never touched.

use anyhow::Context;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::time::Duration;

const PREFIX: &str = "sray-worker-";

/// A directory without a lock file is one being made (the lock is taken
/// right after the directory is made) unless it is older than this.
const UNLOCKED_GRACE: Duration = Duration::from_secs(60);

pub struct TmpDir {
    path: PathBuf,
    /// Held (locked) while the worker lives.
    _lock: File,
}

impl TmpDir {
    /// Removes what killed workers left in `base` (default: the system's
    /// temporary directory) and makes this worker's directory there.
    pub fn claim(base: Option<&Path>) -> anyhow::Result<TmpDir> {
        let base = base.map_or_else(std::env::temp_dir, Path::to_path_buf);
        std::fs::create_dir_all(&base)
            .with_context(|| format!("cannot create the spill directory {}", base.display()))?;
        remove_stale(&base);
        let name = format!(
            "{PREFIX}{}-{:08x}",
            std::process::id(),
            sray_proto::ids::random_u64() as u32
        );
        let path = base.join(name);
        std::fs::create_dir(&path)
            .with_context(|| format!("cannot create the spill directory {}", path.display()))?;
        let lock_path = path.join("lock");
        let lock = File::create(&lock_path)
            .with_context(|| format!("cannot create {}", lock_path.display()))?;
        lock.lock()
            .with_context(|| format!("cannot lock {}", lock_path.display()))?;
        Ok(TmpDir { path, _lock: lock })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for TmpDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.path);
    }
}

/// Removes the directories of workers that are gone (their lock is free).
fn remove_stale(base: &Path) {
    let Ok(rd) = std::fs::read_dir(base) else {
        return;
    };
    for e in rd.flatten() {
        let name = e.file_name().to_string_lossy().to_string();
        if !name.starts_with(PREFIX) || !e.file_type().is_ok_and(|t| t.is_dir()) {
            continue;
        }
        let dir = e.path();
        let gone = match File::open(dir.join("lock")) {
            // Free: its worker is gone (the lock ends with the process).
            Ok(f) => f.try_lock().is_ok(),
            Err(_) => e
                .metadata()
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| t.elapsed().ok())
                .is_some_and(|age| age > UNLOCKED_GRACE),
        };
        if gone {
            let bytes = du(&dir);
            match std::fs::remove_dir_all(&dir) {
                Ok(()) => tracing::info!(
                    dir = %dir.display(),
                    bytes,
                    "removed the spill files of a worker that was killed"
                ),
                Err(err) => {
                    tracing::warn!(dir = %dir.display(), error = %err, "cannot remove the spill files of a worker that was killed")
                }
            }
        }
    }
}

/// Bytes of the files under `dir`.
fn du(dir: &Path) -> u64 {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return 0;
    };
    rd.flatten()
        .map(|e| match e.file_type() {
            Ok(t) if t.is_dir() => du(&e.path()),
            Ok(_) => e.metadata().map_or(0, |m| m.len()),
            Err(_) => 0,
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_killed_workers_directory_goes_a_live_ones_stays() {
        let base = tempfile::tempdir().unwrap();
        let live = TmpDir::claim(Some(base.path())).unwrap();
        std::fs::write(live.path().join("rays.bin"), b"live").unwrap();
        // A killed worker's: its lock file is there, and free.
        let dead = base.path().join(format!("{PREFIX}1-dead"));
        std::fs::create_dir(&dead).unwrap();
        std::fs::write(dead.join("lock"), b"").unwrap();
        std::fs::write(dead.join("rays.bin"), vec![0u8; 4096]).unwrap();
        // One being made (no lock file yet, and new): left alone.
        let young = base.path().join(format!("{PREFIX}2-young"));
        std::fs::create_dir(&young).unwrap();
        let other = TmpDir::claim(Some(base.path())).unwrap();
        assert!(!dead.exists());
        assert!(young.exists());
        assert!(live.path().join("rays.bin").exists());
        let p = other.path().to_path_buf();
        drop(other);
        assert!(!p.exists());
    }
}

//! What the coordinator knows: its workers, the task queue and the jobs.
//!
//! A task is one stage (intersect or shade) of one shard of one round of a
//! job, or a verification: a re-trace of a sample of a shard on another
//! worker. It is queued and given to workers as *attempts*; usually one at
//! a time, but a task that runs far longer than its finished siblings gets
//! a backup attempt on another worker (MapReduce's backup tasks): the
//! first complete output wins, later ones are dropped. An output that
//! arrives for an attempt that is no longer live (its worker was declared
//! dead or quarantined, the task was done elsewhere) is dropped.
//!
//! Failures: a task that failed on a worker is never given to that worker
//! again (`excluded`), and fails its job after `max_attempts` failures; a
//! worker with `quarantine_after` failures within `quarantine` is
//! quarantined for `quarantine` (it gets no task, by session and by name,
//! so registering again does not lift it). A worker caught returning wrong
//! output by verification is quarantined the same way and *distrusted*:
//! every output of it the job has not yet built on is redone elsewhere.
//!
//! Workers are named by a random session secret issued at registration
//! (not a counter), so a caller cannot act for another worker by guessing.
//!
//! [`Shared`] is here; its methods are in the rooms of their jobs:
//! `registry.rs` (workers), `queue.rs` (tasks in, tasks out to workers),
//! `outcomes.rs` (how an attempt ends), `pace.rs` (how fast workers
//! trace), `quarantine.rs`, `stragglers.rs`
//! (backup attempts, tasks waiting too long) and `monitor.rs` (the
//! housekeeping loop); `inner.rs` holds what the lock guards.

mod counters;
mod inner;
pub mod monitor;
mod outcomes;
mod pace;
mod quarantine;
mod queue;
mod registry;
mod stragglers;

// The settings, where the sray binary has always found them.
pub use crate::config::{Config, Limits, MIN_WORKER_MEMORY};

use crate::jobs::Jobs;
use crate::scenes::SceneStore;
use anyhow::Context;
use counters::{Counters, Traffic};
use inner::Inner;
use sray_engine::spill::{MemoryShare, SpillDir};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use tokio::sync::Notify;

/// Everything the service, the drivers and the monitor share.
pub struct Shared {
    pub cfg: Config,
    pub run_id: String,
    pub scenes: SceneStore,
    pub spill: SpillDir,
    /// What records in flight may hold in memory (`records_memory`).
    pub records: MemoryShare,
    pub traffic: Traffic,
    pub counters: Counters,
    pub jobs: Jobs,
    inner: Mutex<Inner>,
    task_ready: Notify,
    started: Instant,
    stopping: AtomicBool,
    pub stop: Notify,
    /// Jobs whose tracing has ended, counted as each one's last round
    /// finishes (before its image is encoded and kept): `sray render
    /// --local-workers` stops its workers then, while the image is made.
    pub traced: tokio::sync::watch::Sender<u64>,
    /// The spill directory's parent (removed when the coordinator ends).
    spill_parent: PathBuf,
}

impl Drop for Shared {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.spill_parent);
    }
}

/// Why a worker's call was refused.
pub enum Refusal {
    UnknownWorker,
    NotYours,
    Stopping,
}

impl Shared {
    pub fn new(cfg: Config) -> anyhow::Result<Arc<Shared>> {
        let scenes = SceneStore::new(&cfg.data_dir)?;
        let (spill, spill_parent) = spill_dir(&cfg)?;
        let jobs = Jobs::new(&cfg.data_dir)?;
        let records = MemoryShare::new(cfg.records_memory);
        Ok(Arc::new(Shared {
            cfg,
            run_id: sray_proto::ids::new_session(),
            scenes,
            records,
            spill,
            traffic: Traffic::default(),
            counters: Counters::default(),
            jobs,
            inner: Mutex::new(Inner::default()),
            task_ready: Notify::new(),
            started: Instant::now(),
            stopping: AtomicBool::new(false),
            stop: Notify::new(),
            traced: tokio::sync::watch::Sender::new(0),
            spill_parent,
        }))
    }

    fn lock(&self) -> MutexGuard<'_, Inner> {
        // A panic while holding the lock is a bug; keep serving regardless.
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Stop accepting work: long polls and watchers end now.
    pub fn begin_stop(&self) {
        self.stopping.store(true, Ordering::SeqCst);
        self.stop.notify_waiters();
        self.task_ready.notify_waiters();
        self.jobs.wake_all();
    }

    pub fn is_stopping(&self) -> bool {
        self.stopping.load(Ordering::SeqCst)
    }

    pub fn uptime(&self) -> Duration {
        self.started.elapsed()
    }
}

/// The coordinator's spill directory: a fixed place per data directory,
/// emptied at start, so that the files of a coordinator that was killed
/// are removed by the next one.
fn spill_dir(cfg: &Config) -> anyhow::Result<(SpillDir, PathBuf)> {
    std::fs::create_dir_all(&cfg.data_dir).with_context(|| {
        format!(
            "cannot create the data directory {}",
            cfg.data_dir.display()
        )
    })?;
    let canon = std::fs::canonicalize(&cfg.data_dir)?;
    let tag = &blake3::hash(canon.as_os_str().as_encoded_bytes()).to_hex()[..16];
    // Absolute, so that a message about a spill file names it whole.
    let base = match &cfg.tmp_dir {
        Some(t) => {
            std::fs::create_dir_all(t)
                .with_context(|| format!("cannot create the directory {}", t.display()))?;
            std::fs::canonicalize(t)?
        }
        None => canon.clone(),
    };
    let dir = base.join(format!("sray-coordinator-{tag}"));
    if dir.exists() {
        let n = std::fs::read_dir(&dir).map_or(0, |r| r.count());
        if n > 0 {
            tracing::info!(dir = %dir.display(), "removing the spill files of an earlier run");
        }
        std::fs::remove_dir_all(&dir).with_context(|| dir.display().to_string())?;
    }
    Ok((SpillDir::new(Some(&dir))?, dir))
}

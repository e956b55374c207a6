//! The coordinator's housekeeping, every heartbeat: silent workers
//! declared dead, finished jobs expired, scenes over the store's cap
//! evicted.

use super::Shared;
use crate::jobs::JobState;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Runs until the process ends: declares silent workers dead, expires
/// finished jobs and evicts scenes over the store's cap.
pub async fn run(shared: Arc<Shared>) {
    let mut tick = tokio::time::interval(shared.cfg.heartbeat);
    let mut last_expiry = Instant::now();
    loop {
        tick.tick().await;
        shared.reap();
        shared.wake_delayed();
        if last_expiry.elapsed() >= Duration::from_secs(1) {
            last_expiry = Instant::now();
            let sh = shared.clone();
            let _ = tokio::task::spawn_blocking(move || housekeeping(&sh)).await;
        }
    }
}

/// Expires finished jobs past their retention and evicts scenes over the
/// store's cap (least recently used first, never one a running job uses).
fn housekeeping(shared: &Shared) {
    let now = Instant::now();
    for e in shared.jobs.all() {
        let expired = {
            let v = e.view();
            v.state != JobState::Running
                && v.finished
                    .is_some_and(|f| now.duration_since(f) >= shared.cfg.job_retention)
        };
        if expired {
            shared.jobs.remove(&e.id);
            match std::fs::remove_dir_all(&e.dir) {
                Ok(()) => tracing::info!(job = %e.id, "finished job expired: removed"),
                Err(err) => {
                    tracing::warn!(job = %e.id, error = %err, "finished job expired, but its journal could not be removed")
                }
            }
        }
    }
    let in_use: Vec<String> = shared
        .jobs
        .running()
        .iter()
        .map(|e| e.scene.clone())
        .collect();
    shared.scenes.evict(shared.cfg.scene_store_max, &in_use);
}

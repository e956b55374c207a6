//! The workers: registration, heartbeats, what `sray status` shows of
//! them, who may take work, and declaring the silent ones dead.

use super::Shared;
use super::inner::{Worker, lose_pinned_to, requeue_if_idle};
use super::quarantine::quarantined_now;
use crate::task::WorkerTag;
use sray_proto::v1;
use std::collections::HashSet;
use std::sync::atomic::Ordering;
use std::time::Instant;

impl Shared {
    /// A new worker session, and the worker's public id.
    pub fn register(
        &self,
        name: String,
        address: String,
        threads: u32,
        memory: u64,
    ) -> (String, String) {
        let session = sray_proto::ids::new_session();
        let mut g = self.lock();
        g.workers_ever += 1;
        let id = format!("w{}", g.workers_ever);
        self.counters
            .workers_registered
            .fetch_add(1, Ordering::Relaxed);
        g.workers.insert(
            session.clone(),
            Worker {
                id: id.clone(),
                address,
                tasks_done: 0,
                failures: 0,
                name,
                threads,
                memory,
                last_beat: Instant::now(),
                running: HashSet::new(),
                overdue: HashSet::new(),
                wake: Default::default(),
            },
        );
        (session, id)
    }

    /// Every worker as `sray status` shows it, by id.
    pub fn worker_status(&self) -> Vec<v1::WorkerStatus> {
        let g = self.lock();
        let now = Instant::now();
        let mut out: Vec<(u64, v1::WorkerStatus)> = g
            .workers
            .iter()
            .map(|(session, w)| {
                let quarantined = quarantined_now(&g.quarantined, session, &w.name, now);
                let mut tasks: Vec<String> = w
                    .running
                    .iter()
                    .filter_map(|(id, _)| g.tasks.get(id))
                    .map(|t| describe_task(&t.task))
                    .collect();
                tasks.sort();
                let state = if quarantined {
                    "quarantined"
                } else if tasks.is_empty() {
                    "idle"
                } else {
                    "busy"
                };
                let n = w.id.trim_start_matches('w').parse().unwrap_or(u64::MAX);
                (
                    n,
                    v1::WorkerStatus {
                        id: w.id.clone(),
                        name: w.name.clone(),
                        address: w.address.clone(),
                        state: state.into(),
                        tasks,
                        memory_bytes: w.memory,
                        threads: w.threads,
                        tasks_done: w.tasks_done,
                        failures: w.failures,
                        quarantined,
                        last_seen_seconds: now.duration_since(w.last_beat).as_secs_f64(),
                    },
                )
            })
            .collect();
        out.sort_by_key(|(n, _)| *n);
        out.into_iter().map(|(_, w)| w).collect()
    }

    /// The worker's name, for logs ("?" if unknown).
    pub fn worker_name(&self, session: &str) -> String {
        self.lock()
            .workers
            .get(session)
            .map_or_else(|| "?".into(), |w| w.name.clone())
    }

    /// Records a beat; false if the worker is not known (any more).
    pub fn beat(&self, session: &str) -> bool {
        let mut g = self.lock();
        match g.workers.get_mut(session) {
            Some(w) => {
                w.last_beat = Instant::now();
                true
            }
            None => false,
        }
    }

    /// Whether the worker `session` is registered.
    pub fn is_connected(&self, session: &str) -> bool {
        self.lock().workers.contains_key(session)
    }

    /// A worker to recompute lost records on: registered, not
    /// quarantined, not among `avoid` (sessions); the one running the
    /// fewest tasks, then the one that has done the fewest.
    pub fn recompute_worker(&self, avoid: &[String]) -> Option<String> {
        // A round's checks each avoid more workers: a set, not a search of
        // the list for every worker.
        let avoid: HashSet<&str> = avoid.iter().map(String::as_str).collect();
        let g = self.lock();
        let now = Instant::now();
        g.workers
            .iter()
            .filter(|(s, w)| {
                !avoid.contains(s.as_str()) && !quarantined_now(&g.quarantined, s, &w.name, now)
            })
            .min_by_key(|(_, w)| (w.running.len() + w.overdue.len(), w.tasks_done))
            .map(|(s, _)| s.clone())
    }

    pub fn worker_count(&self) -> usize {
        self.lock().workers.len()
    }

    /// Workers registered, the smallest `--memory` among them (0: none),
    /// and the rays a worker traces of scene `scene` per second of its
    /// busy time (`None` until measured).
    pub fn fleet(&self, scene: &str) -> (usize, u64, Option<f64>) {
        let g = self.lock();
        let min = g.workers.values().map(|w| w.memory).min().unwrap_or(0);
        (g.workers.len(), min, g.pace.worker_rays_per_second(scene))
    }

    /// Workers that may take a task that excludes `excluded` (sessions
    /// or names), not counting quarantined ones.
    pub fn eligible_workers(&self, excluded: &[WorkerTag]) -> usize {
        let g = self.lock();
        let now = Instant::now();
        g.workers
            .iter()
            .filter(|(s, w)| {
                !quarantined_now(&g.quarantined, s, &w.name, now)
                    && !excluded
                        .iter()
                        .any(|e| e.session == **s || e.name == w.name)
            })
            .count()
    }

    /// Declares silent workers dead and queues their tasks again.
    pub fn reap(&self) {
        let now = Instant::now();
        let dead: Vec<String> = {
            let mut g = self.lock();
            g.quarantined.retain(|_, q| q.until > now);
            g.workers
                .iter()
                .filter(|(_, w)| now.duration_since(w.last_beat) > self.cfg.worker_timeout)
                .map(|(s, _)| s.clone())
                .collect()
        };
        for s in dead {
            self.forget_worker(&s, "worker missed its heartbeats: declared dead");
        }
    }

    /// The worker `session` leaves (it is stopping): its tasks go to others
    /// now. False if it was not known.
    pub fn leave(&self, session: &str) -> bool {
        self.forget_worker(session, "worker left")
    }

    /// Forgets a worker: its running tasks are queued again, the tasks
    /// pinned to it lost.
    fn forget_worker(&self, session: &str, why: &str) -> bool {
        let mut g = self.lock();
        let Some(w) = g.workers.remove(session) else {
            return false;
        };
        tracing::warn!(name = %w.name, "{why}");
        for (id, a) in w.running {
            if let Some(t) = g.tasks.get_mut(&id) {
                t.live.remove(&a);
            }
            requeue_if_idle(&mut g, id);
        }
        lose_pinned_to(&mut g, session, "the worker holding its input is gone");
        drop(g);
        self.task_ready.notify_waiters();
        true
    }
}

/// A task in a line, for `sray status`: job, round, stage, rays.
pub fn describe_task(t: &v1::Task) -> String {
    let stage = match v1::Stage::try_from(t.stage) {
        Ok(v1::Stage::Intersect) => "intersect",
        Ok(v1::Stage::Shade) => "shade",
        _ => "?",
    };
    format!(
        "job {} round {} {stage} rays {}+{}{}",
        t.job_id.get(..8).unwrap_or(&t.job_id),
        t.round,
        t.first_ray,
        t.ray_count,
        if t.verification {
            " (verification)"
        } else {
            ""
        }
    )
}

//! How an attempt ends: its output taken (the first complete one wins),
//! its stream broken, or its failure counted against the task and the
//! worker; and a done task's output thrown away to be made again.

use super::Shared;
use super::inner::{TaskState, drop_attempt, live_attempt, lose, requeue_if_idle};
use crate::task::{TaskEvent, TaskOutput, WorkerTag};
use sray_proto::v1;
use std::sync::atomic::Ordering;
use std::time::Instant;

impl Shared {
    /// A complete output arrived: the task is done, if `r` is a live
    /// attempt of it (else the output is dropped and false returned). The
    /// first output wins; other live attempts are dropped.
    pub fn complete(&self, r: &v1::TaskRef, output: TaskOutput) -> bool {
        let mut g = self.lock();
        if live_attempt(&g, r).is_none() {
            return false;
        }
        let t = g.tasks.get_mut(&r.task_id).expect("checked");
        let a = &t.live[&r.attempt];
        t.took = Some(a.since.elapsed());
        let worker = a.worker.clone();
        t.state = TaskState::Done;
        let c = &self.counters;
        let (task, rays) = if t.task.stage == v1::Stage::Intersect as i32 {
            (&c.tasks_intersect, &c.rays_intersected)
        } else {
            (&c.tasks_shade, &c.rays_shaded)
        };
        task.fetch_add(1, Ordering::Relaxed);
        rays.fetch_add(t.task.ray_count, Ordering::Relaxed);
        if t.task.verification {
            c.tasks_verification.fetch_add(1, Ordering::Relaxed);
        }
        tracing::debug!(
            job = %t.task.job_id,
            task = r.task_id,
            attempt = r.attempt,
            worker = %worker.name,
            stage = t.task.stage,
            round = t.task.round,
            rays = t.task.ray_count,
            seconds = t.took.map_or(0.0, |d| d.as_secs_f64()),
            "task completed"
        );
        let ev = TaskEvent::Done {
            task: r.task_id,
            shard: t.shard,
            output,
            worker: worker.clone(),
        };
        let _ = t.events.send(ev);
        let attempts: Vec<u32> = t.live.keys().copied().collect();
        if let Some(w) = g.workers.get_mut(&worker.session) {
            w.tasks_done += 1;
        }
        for a in attempts {
            drop_attempt(&mut g, r.task_id, a);
        }
        true
    }

    /// The output stream of `r` broke: the attempt is dropped, and the
    /// task queued again if no other attempt is live.
    pub fn abandon(&self, r: &v1::TaskRef, why: &str) {
        let mut g = self.lock();
        if live_attempt(&g, r).is_none() {
            return;
        }
        tracing::warn!(task = r.task_id, why, "attempt abandoned");
        drop_attempt(&mut g, r.task_id, r.attempt);
        requeue_if_idle(&mut g, r.task_id);
        drop(g);
        self.task_ready.notify_waiters();
    }

    /// The worker says the task failed (or its output was refused): never
    /// again on that worker; the job fails after `max_attempts` failures.
    pub fn fail(&self, r: &v1::TaskRef, error: String) {
        let mut g = self.lock();
        if live_attempt(&g, r).is_none() {
            return;
        }
        let max = self.cfg.max_attempts as usize;
        let worker = drop_attempt(&mut g, r.task_id, r.attempt).expect("live");
        tracing::warn!(task = r.task_id, worker = %worker.name, error = %error, "task failed");
        self.counters.tasks_failed.fetch_add(1, Ordering::Relaxed);
        if let Some(w) = g.workers.get_mut(&worker.session) {
            w.failures += 1;
        }
        let t = g.tasks.get_mut(&r.task_id).expect("live");
        t.failures.push(format!("{}: {error}", worker.name));
        t.excluded.insert(worker.session.clone());
        t.excluded.insert(worker.name.clone());
        if t.pinned {
            let why = format!("it failed where its input is: {error}");
            lose(&mut g, r.task_id, &why);
        } else if t.failures.len() >= max {
            t.state = TaskState::Done;
            let msg = t.failures.join("; ");
            let _ = t.events.send(TaskEvent::Failed {
                task: r.task_id,
                error: msg,
            });
        } else {
            requeue_if_idle(&mut g, r.task_id);
        }
        // Repeated failures quarantine the worker.
        let now = Instant::now();
        let window = self.cfg.quarantine;
        let recent = g.failures.entry(worker.name.clone()).or_default();
        recent.retain(|t| now.duration_since(*t) < window);
        recent.push(now);
        if recent.len() >= self.cfg.quarantine_after as usize {
            recent.clear();
            drop(g);
            self.quarantine(
                &worker,
                &format!(
                    "{} task failures within {} s",
                    self.cfg.quarantine_after,
                    window.as_secs()
                ),
            );
            return;
        }
        drop(g);
        self.task_ready.notify_waiters();
    }

    /// Queues a done task again (its output was thrown away), never on
    /// the workers in `avoid`.
    pub fn redo(&self, id: u64, avoid: &WorkerTag) -> bool {
        let mut g = self.lock();
        let Some(t) = g.tasks.get_mut(&id) else {
            return false;
        };
        t.excluded.insert(avoid.session.clone());
        t.excluded.insert(avoid.name.clone());
        t.state = TaskState::Queued;
        t.took = None;
        t.backup = false;
        t.queued_at = Instant::now();
        let job = t.task.job_id.clone();
        tracing::info!(job = %job, task = id, round = t.task.round, stage = t.task.stage, "task requeued: its output is redone elsewhere");
        *g.requeued.entry(job).or_default() += 1;
        g.requeued_total += 1;
        g.queue.push_front(id);
        drop(g);
        self.task_ready.notify_waiters();
        true
    }
}

//! How an attempt ends: its output taken (the first complete one wins),
//! its stream broken, or its failure counted against the task and the
//! worker; and a done task's output thrown away to be made again.

use super::Shared;
use super::inner::{Inner, TaskState, drop_attempt, live_attempt, lose, requeue_if_idle};
use crate::task::{TaskEvent, TaskOutput, WorkerTag};
use sray_proto::v1;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// How long a task waits after the coordinator failed to keep its
/// records, before it is given out again.
const LOCAL_FAULT_PAUSE: Duration = Duration::from_secs(1);

/// The attempt `r` has ended (an output or a failure came, in time or
/// not): if it had timed out, its worker may take tasks again.
fn ended_overdue(g: &mut Inner, r: &v1::TaskRef) {
    if let Some(w) = g.workers.get_mut(&r.session) {
        w.overdue.remove(&(r.task_id, r.attempt));
    }
}

impl Shared {
    /// A complete output arrived: the task is done, if `r` is a live
    /// attempt of it (else the output is dropped and false returned). The
    /// first output wins; other live attempts are dropped.
    pub fn complete(&self, r: &v1::TaskRef, output: TaskOutput) -> bool {
        let mut g = self.lock();
        ended_overdue(&mut g, r);
        if live_attempt(&g, r).is_none() {
            return false;
        }
        // The tasks and the workers' pace are apart under the lock.
        let inner = &mut *g;
        let t = inner.tasks.get_mut(&r.task_id).expect("checked");
        let a = &t.live[&r.attempt];
        t.took = Some(a.since.elapsed());
        let worker = a.worker.clone();
        t.state = TaskState::Done;
        t.local_fault = None;
        t.blocked_since = None;
        let c = &self.counters;
        let intersect = t.task.stage == v1::Stage::Intersect as i32;
        let (task, rays) = if intersect {
            (&c.tasks_intersect, &c.rays_intersected)
        } else {
            (&c.tasks_shade, &c.rays_shaded)
        };
        task.fetch_add(1, Ordering::Relaxed);
        rays.fetch_add(t.task.ray_count, Ordering::Relaxed);
        if let Some(scene) = &t.task.scene {
            inner.pace.record(
                &scene.hash,
                intersect,
                t.task.ray_count,
                output.summary.seconds,
            );
        }
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
    /// A worker that lacked room for it is not blamed (it gets the task
    /// back after `room_retry`), nor one that hands it back as it stops.
    pub fn fail(&self, r: &v1::TaskRef, error: String, kind: v1::FailureKind) {
        let mut g = self.lock();
        ended_overdue(&mut g, r);
        if live_attempt(&g, r).is_none() {
            return;
        }
        let max = self.cfg.max_attempts as usize;
        let worker = drop_attempt(&mut g, r.task_id, r.attempt).expect("live");
        match kind {
            v1::FailureKind::Task => {}
            v1::FailureKind::NoRoom => {
                tracing::warn!(task = r.task_id, worker = %worker.name, error = %error, "no room for the task on the worker: it goes elsewhere");
                let t = g.tasks.get_mut(&r.task_id).expect("live");
                t.no_room.insert(
                    worker.session.clone(),
                    (Instant::now(), format!("{}: no room: {error}", worker.name)),
                );
                if t.pinned {
                    let why = format!("it found no room where its input is: {error}");
                    lose(&mut g, r.task_id, &why);
                } else {
                    requeue_if_idle(&mut g, r.task_id);
                }
                drop(g);
                self.task_ready.notify_waiters();
                return;
            }
            v1::FailureKind::HandedBack => {
                tracing::info!(task = r.task_id, worker = %worker.name, "task handed back: the worker is stopping");
                requeue_if_idle(&mut g, r.task_id);
                drop(g);
                self.task_ready.notify_waiters();
                return;
            }
        }
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
        drop(g);
        self.count_fault(&worker, "task failures");
        self.task_ready.notify_waiters();
    }

    /// One more fault (a failure, a timeout) of `worker` within the
    /// quarantine window: `quarantine_after` of them quarantine it.
    pub(super) fn count_fault(&self, worker: &WorkerTag, what: &str) {
        let mut g = self.lock();
        let now = Instant::now();
        let window = self.cfg.quarantine;
        let recent = g.failures.entry(worker.name.clone()).or_default();
        recent.retain(|t| now.duration_since(*t) < window);
        recent.push(now);
        if recent.len() >= self.cfg.quarantine_after as usize {
            recent.clear();
            drop(g);
            self.quarantine(
                worker,
                &format!(
                    "{} {what} within {} s",
                    self.cfg.quarantine_after,
                    window.as_secs()
                ),
            );
        }
    }

    /// The coordinator itself could not serve the input of `r` or keep
    /// its output (its own disk): the attempt ends without blame to the
    /// worker, and the task waits a moment before it is given out again.
    pub fn local_fault(&self, r: &v1::TaskRef, error: &str) {
        let mut g = self.lock();
        let Some(t) = g.tasks.get_mut(&r.task_id) else {
            return;
        };
        let now = Instant::now();
        if t.local_fault.is_none() {
            tracing::error!(task = r.task_id, job = %t.task.job_id, error, "the coordinator cannot keep a task's records: no worker is blamed");
            t.local_fault = Some((now, error.to_string()));
        }
        t.not_before = Some(now + LOCAL_FAULT_PAUSE);
        if live_attempt(&g, r).is_none() {
            return;
        }
        drop_attempt(&mut g, r.task_id, r.attempt);
        requeue_if_idle(&mut g, r.task_id);
        drop(g);
        self.task_ready.notify_waiters();
    }

    /// Wakes the workers waiting for a task when a task held back (after
    /// a fault of the coordinator's own) may go out again.
    pub fn wake_delayed(&self) {
        let mut g = self.lock();
        let now = Instant::now();
        let mut due = false;
        for t in g.tasks.values_mut() {
            if t.not_before.is_some_and(|at| at <= now) {
                t.not_before = None;
                due = true;
            }
        }
        drop(g);
        if due {
            self.task_ready.notify_waiters();
        }
    }

    /// Tasks among `ids` the coordinator could not keep records of: since
    /// when, and why (the first fault).
    pub fn local_faults(&self, ids: &[u64]) -> Vec<(u64, Instant, String)> {
        let g = self.lock();
        ids.iter()
            .filter_map(|id| {
                let t = g.tasks.get(id)?;
                let (at, why) = t.local_fault.clone()?;
                Some((*id, at, why))
            })
            .collect()
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
        t.blocked_since = None;
        let job = t.task.job_id.clone();
        tracing::info!(job = %job, task = id, round = t.task.round, stage = t.task.stage, "task requeued: its output is redone elsewhere");
        *g.requeued.entry(job).or_default() += 1;
        g.requeued_total += 1;
        super::inner::push_queued(&mut g, id, true);
        drop(g);
        self.task_ready.notify_waiters();
        true
    }
}

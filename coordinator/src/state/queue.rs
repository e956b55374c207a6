//! The task queue: tasks in (a stage's shards, their samples), the next
//! one out to a worker that asks, and a running task's input.

use super::inner::{Attempt, TaskEntry, TaskState, live_attempt, lose};
use super::quarantine::quarantined_now;
use super::{Refusal, Shared};
use crate::task::{TaskEvent, TaskInput, WorkerTag};
use sray_proto::v1;
use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;

impl Shared {
    /// Queues tasks; their outcomes go to `events`. Returns their ids.
    /// `avoid`: workers the tasks must not go to (verification).
    pub fn enqueue(
        &self,
        tasks: Vec<(v1::Task, usize, Arc<TaskInput>)>,
        events: &mpsc::UnboundedSender<TaskEvent>,
        avoid: &[WorkerTag],
    ) -> Vec<u64> {
        let mut g = self.lock();
        let mut ids = Vec::with_capacity(tasks.len());
        for (mut task, shard, input) in tasks {
            let mut id = sray_proto::ids::random_u64();
            while id == 0 || g.tasks.contains_key(&id) {
                id = sray_proto::ids::random_u64();
            }
            task.task_id = id;
            task.attempt = 0;
            let prefer = input.held.preferred(task.first_ray, task.ray_count);
            let pinned = input.held.pinned && prefer.is_some();
            // Gone, or quarantined (it would not get the task in time).
            let holder_gone = pinned
                && prefer.as_ref().is_some_and(|s| {
                    !g.workers.contains_key(s)
                        || g.quarantined
                            .get(s)
                            .is_some_and(|q| q.until > Instant::now())
                });
            g.tasks.insert(
                id,
                TaskEntry {
                    task,
                    shard,
                    state: TaskState::Queued,
                    failures: Vec::new(),
                    input,
                    events: events.clone(),
                    live: HashMap::new(),
                    next_attempt: 1,
                    excluded: avoid
                        .iter()
                        .flat_map(|w| [w.session.clone(), w.name.clone()])
                        .collect(),
                    took: None,
                    backup: false,
                    queued_at: Instant::now(),
                    prefer,
                    pinned,
                },
            );
            g.queue.push_back(id);
            ids.push(id);
            if holder_gone {
                lose(&mut g, id, "the worker holding its input is gone");
            }
        }
        drop(g);
        self.task_ready.notify_waiters();
        ids
    }

    /// Drops tasks (their stage ended, or the job did).
    pub fn forget_tasks(&self, ids: &[u64]) {
        let mut g = self.lock();
        for id in ids {
            if let Some(t) = g.tasks.remove(id) {
                for (a, at) in t.live {
                    if let Some(w) = g.workers.get_mut(&at.worker.session) {
                        w.running.remove(&(*id, a));
                    }
                }
            }
        }
        let tasks = std::mem::take(&mut g.tasks);
        g.queue.retain(|t| tasks.contains_key(t));
        g.tasks = tasks;
    }

    /// Forgets a finished job's counters.
    pub fn end_job(&self, job: &str) {
        let mut g = self.lock();
        g.requeued.remove(job);
        g.backups.remove(job);
    }

    /// Tasks queued again (after a worker loss or failure), and backup
    /// attempts issued, so far for job `job`.
    pub fn requeued(&self, job: &str) -> (u64, u64) {
        let g = self.lock();
        (
            g.requeued.get(job).copied().unwrap_or(0),
            g.backups.get(job).copied().unwrap_or(0),
        )
    }

    /// Tasks queued with no attempt live (waiting for a worker), tasks
    /// running, and tasks queued again so far.
    pub fn task_counts(&self) -> (u64, u64, u64) {
        let g = self.lock();
        let mut queued = 0;
        let mut running = 0;
        for t in g.tasks.values() {
            match t.state {
                TaskState::Queued => queued += 1,
                TaskState::Running => running += 1,
                TaskState::Done => {}
            }
        }
        (queued, running, g.requeued_total)
    }

    /// The next task for the worker `session`, waiting up to `wait`.
    pub async fn next_task(
        &self,
        session: &str,
        wait: Duration,
    ) -> Result<Option<v1::Task>, Refusal> {
        let deadline = tokio::time::Instant::now() + wait;
        loop {
            let notified = self.task_ready.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            if self.is_stopping() {
                return Err(Refusal::Stopping);
            }
            {
                let mut g = self.lock();
                let now = Instant::now();
                let Some(w) = g.workers.get_mut(session) else {
                    return Err(Refusal::UnknownWorker);
                };
                w.last_beat = now;
                let tag = WorkerTag {
                    session: session.to_string(),
                    name: w.name.clone(),
                };
                if !quarantined_now(&g, &tag, now) {
                    let g = &mut *g;
                    // The first task this worker may run, unless a later
                    // one's input is held here.
                    let mut first = None;
                    let mut mine = None;
                    g.queue.retain(|id| {
                        let Some(t) = g.tasks.get(id) else {
                            return false;
                        };
                        if t.state == TaskState::Done {
                            return false;
                        }
                        if mine.is_none()
                            && !t.excludes(&tag)
                            && !t.live.values().any(|a| a.worker.session == tag.session)
                        {
                            first.get_or_insert(*id);
                            if t.prefer.as_deref() == Some(session) {
                                mine = Some(*id);
                            }
                        }
                        true
                    });
                    let pick = mine.or(first);
                    if let Some(id) = pick
                        && let Some(i) = g.queue.iter().position(|&x| x == id)
                    {
                        g.queue.remove(i);
                    }
                    if let Some(id) = pick {
                        let t = g.tasks.get_mut(&id).expect("picked");
                        let attempt = t.next_attempt;
                        t.next_attempt += 1;
                        t.state = TaskState::Running;
                        t.live.insert(
                            attempt,
                            Attempt {
                                worker: tag.clone(),
                                since: now,
                            },
                        );
                        let mut task = t.task.clone();
                        task.attempt = attempt;
                        if let Some(w) = g.workers.get_mut(session) {
                            w.running.insert((id, attempt));
                        }
                        return Ok(Some(task));
                    }
                }
            }
            tokio::select! {
                r = tokio::time::timeout_at(deadline, notified) => {
                    if r.is_err() {
                        return Ok(None);
                    }
                }
                _ = self.stop.notified() => return Err(Refusal::Stopping),
            }
        }
    }

    /// The input of a task the worker is running.
    pub fn task_input(&self, r: &v1::TaskRef) -> Result<(v1::Task, Arc<TaskInput>), Refusal> {
        let g = self.lock();
        let t = live_attempt(&g, r).ok_or(Refusal::NotYours)?;
        let mut task = t.task.clone();
        task.attempt = r.attempt;
        Ok((task, t.input.clone()))
    }
}

//! What the coordinator's lock guards: the workers, the tasks and their
//! live attempts, the quarantine list; and the few steps every change of
//! them shares (an attempt dropped, a task queued again or lost).

use crate::task::{TaskEvent, TaskInput, WorkerTag};
use sray_proto::v1;
use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::{Notify, mpsc};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TaskState {
    Queued,
    Running,
    Done,
}

/// One attempt of a task: the worker given it, and since when.
pub(super) struct Attempt {
    pub(super) worker: WorkerTag,
    pub(super) since: Instant,
}

pub struct TaskEntry {
    pub task: v1::Task,
    pub shard: usize,
    pub state: TaskState,
    pub failures: Vec<String>,
    pub input: Arc<TaskInput>,
    pub(super) events: mpsc::UnboundedSender<TaskEvent>,
    pub(super) live: HashMap<u32, Attempt>,
    pub(super) next_attempt: u32,
    /// Sessions and names of workers this task must not go to.
    pub(super) excluded: HashSet<String>,
    /// How long the winning attempt took.
    pub(super) took: Option<Duration>,
    pub(super) backup: bool,
    /// When it was last queued with no attempt live.
    pub(super) queued_at: Instant,
    /// The worker that holds (most of) its input, if any: it gets the
    /// task first.
    pub(super) prefer: Option<String>,
    /// Only `prefer` may run it (see [`crate::task::Held::pinned`]).
    pub(super) pinned: bool,
    /// Workers (by session) that lacked room for it, when, and what they
    /// said: it goes back to one only once `room_retry` has passed.
    pub(super) no_room: HashMap<String, (Instant, String)>,
    /// Not to be given out before then (the coordinator's own fault made
    /// it wait).
    pub(super) not_before: Option<Instant>,
    /// The coordinator could not keep its input or output (its own disk):
    /// since when, and why. Cleared when the task is done.
    pub(super) local_fault: Option<(Instant, String)>,
    /// Since when no worker may take it (all failed it, lacked room for
    /// it, or are quarantined); cleared when a worker that may takes it.
    pub(super) blocked_since: Option<Instant>,
}

impl TaskEntry {
    pub(super) fn excludes(&self, session: &str, name: &str) -> bool {
        (self.pinned && self.prefer.as_deref() != Some(session))
            || self.excluded.contains(session)
            || self.excluded.contains(name)
    }

    /// Why the worker `w` may not take this task at `now`, if it may not
    /// (quarantine aside): it failed it, or lacked room for it lately.
    pub(super) fn refuses(&self, w: &WorkerTag, now: Instant, room_retry: Duration) -> bool {
        self.excludes(&w.session, &w.name)
            || self
                .no_room
                .get(&w.session)
                .is_some_and(|(at, _)| now.duration_since(*at) < room_retry)
            || self.not_before.is_some_and(|t| now < t)
    }
}

/// Loses every task pinned to the worker `session` (its records can no
/// longer be had).
pub(super) fn lose_pinned_to(g: &mut Inner, session: &str, why: &str) {
    let waiting: Vec<u64> = g
        .tasks
        .iter()
        .filter(|(_, t)| t.pinned && t.prefer.as_deref() == Some(session))
        .map(|(id, _)| *id)
        .collect();
    for id in waiting {
        lose(g, id, why);
    }
}

/// Ends a pinned task whose input cannot be had any more (its worker is
/// gone, or failed it): its stage hears [`TaskEvent::Lost`].
pub(super) fn lose(g: &mut Inner, id: u64, why: &str) {
    if let Some(t) = g.tasks.get_mut(&id)
        && t.state != TaskState::Done
    {
        t.state = TaskState::Done;
        tracing::warn!(job = %t.task.job_id, task = id, why, "task input lost");
        let _ = t.events.send(TaskEvent::Lost {
            task: id,
            error: why.to_string(),
        });
    }
}

pub struct Worker {
    /// Public id for display (`w1`, `w2`, ...): never the session.
    pub id: String,
    /// Where its registration came from.
    pub address: String,
    pub tasks_done: u64,
    pub failures: u64,
    pub name: String,
    pub threads: u32,
    pub memory: u64,
    pub(super) last_beat: Instant,
    pub(super) running: HashSet<(u64, u32)>,
    /// Attempts of this worker that ran past their deadline and have not
    /// ended: while there is one, the worker is given no other task.
    pub(super) overdue: HashSet<(u64, u32)>,
    /// Wakes this worker's wait for a task alone (a task pinned to it was
    /// queued), where `Shared::task_ready` wakes every worker waiting.
    pub(super) wake: Arc<Notify>,
}

impl Worker {
    /// Whether it may be given a task now: a worker runs one task at a
    /// time, and one whose task timed out gets no other until that one
    /// ends.
    pub(super) fn free(&self) -> bool {
        self.running.is_empty() && self.overdue.is_empty()
    }
}

pub(super) struct Quarantine {
    pub(super) until: Instant,
    pub(super) why: String,
}

#[derive(Default)]
pub(super) struct Inner {
    pub(super) workers: HashMap<String, Worker>,
    /// By session and by name.
    pub(super) quarantined: HashMap<String, Quarantine>,
    /// Recent failures by worker name.
    pub(super) failures: HashMap<String, Vec<Instant>>,
    /// Tasks any worker may take (or some: see [`TaskEntry::refuses`]),
    /// in the order they go out; re-queued ones go to the front.
    pub(super) queue: VecDeque<u64>,
    /// Tasks only one worker may take (pinned to the worker holding
    /// their input), by that worker's session: a worker asking for a task
    /// searches its own and the shared queue, not every worker's pinned
    /// tasks (with records at the workers, nearly every task is pinned).
    pub(super) pinned_queue: HashMap<String, VecDeque<u64>>,
    /// By task id. Every request for a task looks up each queued task
    /// here, so the hash is foldhash's, not SipHash: the ids are the
    /// coordinator's own random numbers, so no caller can choose keys
    /// that collide.
    pub(super) tasks: HashMap<u64, TaskEntry, foldhash::fast::RandomState>,
    pub(super) requeued: HashMap<String, u64>,
    /// When each job was last given a task (fair turns between jobs).
    pub(super) last_given: HashMap<String, Instant>,
    pub(super) backups: HashMap<String, u64>,
    pub(super) workers_ever: u64,
    /// Tasks queued again (worker lost, failed, output redone), ever.
    pub(super) requeued_total: u64,
    /// How fast workers trace, by scene (shard sizing).
    pub(super) pace: super::pace::Paces,
    /// Job ids a job's recomputations run under (see
    /// `driver/recover.rs`), and the job's own.
    pub(super) aliases: HashMap<String, String>,
}

/// The task `r` names, if `r` is a live attempt of it by the caller.
pub(super) fn live_attempt<'a>(g: &'a Inner, r: &v1::TaskRef) -> Option<&'a TaskEntry> {
    let t = g.tasks.get(&r.task_id)?;
    let a = t.live.get(&r.attempt)?;
    (t.state != TaskState::Done
        && sray_proto::ids::same(a.worker.session.as_bytes(), r.session.as_bytes()))
    .then_some(t)
}

/// Removes a live attempt; returns its worker.
pub(super) fn drop_attempt(g: &mut Inner, id: u64, attempt: u32) -> Option<WorkerTag> {
    let t = g.tasks.get_mut(&id)?;
    let a = t.live.remove(&attempt)?;
    if let Some(w) = g.workers.get_mut(&a.worker.session) {
        w.running.remove(&(id, attempt));
    }
    Some(a.worker)
}

/// Queues a task again if it is not done and no attempt of it is live
/// (a pinned task is lost instead: it could only go back where it was).
pub(super) fn requeue_if_idle(g: &mut Inner, id: u64) {
    if g.tasks
        .get(&id)
        .is_some_and(|t| t.pinned && t.live.is_empty())
    {
        return lose(g, id, "its attempt ended where its input is");
    }
    if let Some(t) = g.tasks.get_mut(&id)
        && t.state != TaskState::Done
        && t.live.is_empty()
    {
        t.state = TaskState::Queued;
        t.backup = false;
        t.queued_at = Instant::now();
        let job = t.task.job_id.clone();
        tracing::info!(job = %job, task = id, round = t.task.round, stage = t.task.stage, "task requeued");
        *g.requeued.entry(job).or_default() += 1;
        g.requeued_total += 1;
        // To the front: a re-queued task holds up its whole stage.
        push_queued(g, id, true);
    }
}

/// Queues task `id` (already in `g.tasks`) where the workers that may
/// take it look: its holder's queue if it is pinned, else the shared
/// one; at the front (`front`) or the back.
pub(super) fn push_queued(g: &mut Inner, id: u64, front: bool) {
    let Some(t) = g.tasks.get(&id) else { return };
    let q = match (t.pinned, &t.prefer) {
        (true, Some(holder)) => g.pinned_queue.entry(holder.clone()).or_default(),
        _ => &mut g.queue,
    };
    if front {
        q.push_front(id);
    } else {
        q.push_back(id);
    }
}

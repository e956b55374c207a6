//! What the coordinator knows: its workers, the task queue and the jobs.
//!
//! A task is one stage (intersect or shade) of one shard of one round of a
//! job. It is queued, given to one worker at a time (`Running`, with an
//! attempt number), and done once: an output that arrives for an attempt
//! that is no longer current (the worker was declared dead, the task went
//! elsewhere) is dropped. A worker that misses its heartbeats, or whose
//! output stream breaks, has its task queued again; a task that fails
//! `max_attempts` times fails its job.

use crate::scenes::SceneStore;
use sray_engine::bf::{Contribution, RayRec, ResultRec};
use sray_engine::spill::{RecordFile, SpillDir};
use sray_proto::v1;
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use tokio::sync::{Notify, mpsc};

/// The coordinator's settings.
#[derive(Clone, Debug)]
pub struct Config {
    /// How often workers beat.
    pub heartbeat: Duration,
    /// A worker silent this long is dead; its task goes to another.
    pub worker_timeout: Duration,
    /// A job with work to do and no worker for this long fails.
    pub worker_wait: Duration,
    /// Rays per shard, unless a job asks otherwise.
    pub shard_rays: u64,
    /// Failures of one task that fail its job.
    pub max_attempts: u32,
    /// Uploaded scenes.
    pub data_dir: PathBuf,
    /// Rays, results and outputs in flight (default: the system's temp dir).
    pub tmp_dir: Option<PathBuf>,
}

impl Default for Config {
    fn default() -> Config {
        Config {
            heartbeat: Duration::from_millis(1000),
            worker_timeout: Duration::from_secs(5),
            worker_wait: Duration::from_secs(60),
            shard_rays: 1 << 16,
            max_attempts: 3,
            data_dir: PathBuf::from("sray-data"),
            tmp_dir: None,
        }
    }
}

/// Bytes on the wire (records and scene chunks, not protocol framing).
#[derive(Default, Debug)]
pub struct Traffic {
    pub to_workers: AtomicU64,
    pub from_workers: AtomicU64,
    pub scene_bytes: AtomicU64,
    pub scene_chunks: AtomicU64,
}

impl Traffic {
    pub fn snapshot(&self) -> [u64; 4] {
        [
            self.to_workers.load(Ordering::Relaxed),
            self.from_workers.load(Ordering::Relaxed),
            self.scene_bytes.load(Ordering::Relaxed),
            self.scene_chunks.load(Ordering::Relaxed),
        ]
    }
}

/// A task's input, as `TaskInput` serves it, and the bounds its output
/// must respect.
#[derive(Default)]
pub struct TaskInput {
    /// The round's rays (absent for eye rays, which workers make).
    pub rays: Option<Arc<RecordFile<RayRec>>>,
    /// The shard's results (shading).
    pub results: Option<Arc<RecordFile<ResultRec>>>,
    pub objects: u64,
    /// Frame slots (pixel corners, or pixels): the bound of contributions.
    pub corners: u64,
}

/// A task's output, as received.
#[derive(Default)]
pub struct TaskOutput {
    pub results: Option<RecordFile<ResultRec>>,
    pub contributions: Option<RecordFile<Contribution>>,
    pub rays: Option<RecordFile<RayRec>>,
    /// Results that hit something (intersection).
    pub hits: u64,
    pub summary: v1::TaskSummary,
}

/// What a job's driver hears about its tasks.
// One event per task, moved once through a channel: the size difference
// between the variants costs nothing worth a box.
#[allow(clippy::large_enum_variant)]
pub enum TaskEvent {
    Done {
        task: u64,
        shard: usize,
        output: TaskOutput,
    },
    Failed {
        task: u64,
        error: String,
    },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TaskState {
    Queued,
    Running { worker: u64 },
    Done,
}

pub struct TaskEntry {
    pub task: v1::Task,
    pub shard: usize,
    pub state: TaskState,
    pub failures: Vec<String>,
    pub input: Arc<TaskInput>,
    events: mpsc::UnboundedSender<TaskEvent>,
}

pub struct Worker {
    pub name: String,
    pub threads: u32,
    pub memory: u64,
    last_beat: Instant,
    task: Option<u64>,
}

#[derive(Default)]
struct Inner {
    workers: BTreeMap<u64, Worker>,
    next_worker: u64,
    next_task: u64,
    next_job: u64,
    queue: VecDeque<u64>,
    tasks: HashMap<u64, TaskEntry>,
    /// Per job, the events its client has not yet taken.
    watchers: HashMap<u64, mpsc::Receiver<v1::JobEvent>>,
    requeued: HashMap<u64, u64>,
    cancelled: std::collections::HashSet<u64>,
}

/// Everything the service, the drivers and the monitor share.
pub struct Shared {
    pub cfg: Config,
    pub scenes: SceneStore,
    pub spill: SpillDir,
    pub traffic: Traffic,
    inner: Mutex<Inner>,
    task_ready: Notify,
    started: Instant,
}

/// Why a worker's call was refused.
pub enum Refusal {
    UnknownWorker,
    NotYours,
}

impl Shared {
    pub fn new(cfg: Config) -> anyhow::Result<Arc<Shared>> {
        let scenes = SceneStore::new(&cfg.data_dir)?;
        let spill = SpillDir::new(cfg.tmp_dir.as_deref())?;
        Ok(Arc::new(Shared {
            cfg,
            scenes,
            spill,
            traffic: Traffic::default(),
            inner: Mutex::new(Inner {
                next_worker: 1,
                next_task: 1,
                next_job: 1,
                ..Default::default()
            }),
            task_ready: Notify::new(),
            started: Instant::now(),
        }))
    }

    fn lock(&self) -> MutexGuard<'_, Inner> {
        // A panic while holding the lock is a bug; keep serving regardless.
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub fn register(&self, name: String, threads: u32, memory: u64) -> u64 {
        let mut g = self.lock();
        let id = g.next_worker;
        g.next_worker += 1;
        g.workers.insert(
            id,
            Worker {
                name,
                threads,
                memory,
                last_beat: Instant::now(),
                task: None,
            },
        );
        id
    }

    /// Records a beat; false if the worker is not known (any more).
    pub fn beat(&self, worker: u64) -> bool {
        let mut g = self.lock();
        match g.workers.get_mut(&worker) {
            Some(w) => {
                w.last_beat = Instant::now();
                true
            }
            None => false,
        }
    }

    pub fn worker_count(&self) -> usize {
        self.lock().workers.len()
    }

    /// The smallest memory budget among the workers (to plan grids every
    /// worker can hold), if any worker is there.
    pub fn min_worker_memory(&self) -> Option<u64> {
        self.lock().workers.values().map(|w| w.memory).min()
    }

    /// A new job number and the channel its client watches.
    pub fn new_job(&self) -> (u64, mpsc::Sender<v1::JobEvent>) {
        let mut g = self.lock();
        let id = g.next_job;
        g.next_job += 1;
        let (tx, rx) = mpsc::channel(64);
        g.watchers.insert(id, rx);
        (id, tx)
    }

    /// The job's events, for its one watcher.
    pub fn take_watcher(&self, job: u64) -> Option<mpsc::Receiver<v1::JobEvent>> {
        self.lock().watchers.remove(&job)
    }

    /// Queues tasks; their outcomes go to `events`. Returns their ids.
    pub fn enqueue(
        &self,
        tasks: Vec<(v1::Task, usize, Arc<TaskInput>)>,
        events: &mpsc::UnboundedSender<TaskEvent>,
    ) -> Vec<u64> {
        let mut g = self.lock();
        let mut ids = Vec::with_capacity(tasks.len());
        for (mut task, shard, input) in tasks {
            let id = g.next_task;
            g.next_task += 1;
            task.task_id = id;
            task.attempt = 1;
            g.tasks.insert(
                id,
                TaskEntry {
                    task,
                    shard,
                    state: TaskState::Queued,
                    failures: Vec::new(),
                    input,
                    events: events.clone(),
                },
            );
            g.queue.push_back(id);
            ids.push(id);
        }
        drop(g);
        self.task_ready.notify_waiters();
        ids
    }

    /// Drops a job's remaining tasks (it ended or was cancelled).
    pub fn forget_tasks(&self, ids: &[u64]) {
        let mut g = self.lock();
        for id in ids {
            g.tasks.remove(id);
        }
        let tasks = std::mem::take(&mut g.tasks);
        g.queue.retain(|t| tasks.contains_key(t));
        g.tasks = tasks;
        for w in g.workers.values_mut() {
            if w.task.is_some_and(|t| ids.contains(&t)) {
                w.task = None;
            }
        }
    }

    /// A client asked to stop job `job`.
    pub fn cancel(&self, job: u64) {
        self.lock().cancelled.insert(job);
    }

    pub fn is_cancelled(&self, job: u64) -> bool {
        self.lock().cancelled.contains(&job)
    }

    /// Forgets a finished job's bookkeeping.
    pub fn end_job(&self, job: u64) {
        let mut g = self.lock();
        g.cancelled.remove(&job);
        g.requeued.remove(&job);
        g.watchers.remove(&job);
    }

    /// Tasks queued again so far for job `job`'s driver to report.
    pub fn requeued(&self, job: u64) -> u64 {
        self.lock().requeued.get(&job).copied().unwrap_or(0)
    }

    /// The next task for `worker`, waiting up to `wait` for one.
    pub async fn next_task(
        &self,
        worker: u64,
        wait: Duration,
    ) -> Result<Option<v1::Task>, Refusal> {
        let deadline = tokio::time::Instant::now() + wait;
        loop {
            let notified = self.task_ready.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            {
                let mut g = self.lock();
                let Some(w) = g.workers.get_mut(&worker) else {
                    return Err(Refusal::UnknownWorker);
                };
                w.last_beat = Instant::now();
                while let Some(id) = g.queue.pop_front() {
                    let Some(t) = g.tasks.get_mut(&id) else {
                        continue;
                    };
                    if t.state != TaskState::Queued {
                        continue;
                    }
                    t.state = TaskState::Running { worker };
                    let task = t.task.clone();
                    if let Some(w) = g.workers.get_mut(&worker) {
                        w.task = Some(id);
                    }
                    return Ok(Some(task));
                }
            }
            if tokio::time::timeout_at(deadline, notified).await.is_err() {
                return Ok(None);
            }
        }
    }

    /// The input of a task the worker is running.
    pub fn task_input(&self, r: &v1::TaskRef) -> Result<(v1::Task, Arc<TaskInput>), Refusal> {
        let g = self.lock();
        let t = g.tasks.get(&r.task_id).ok_or(Refusal::NotYours)?;
        if t.state
            != (TaskState::Running {
                worker: r.worker_id,
            })
            || t.task.attempt != r.attempt
        {
            return Err(Refusal::NotYours);
        }
        Ok((t.task.clone(), t.input.clone()))
    }

    /// Whether `r` is the current attempt of a running task.
    pub fn is_current(&self, r: &v1::TaskRef) -> bool {
        self.task_input(r).is_ok()
    }

    /// A complete output arrived: the task is done, if `r` is still its
    /// current attempt (else the output is dropped and false returned).
    pub fn complete(&self, r: &v1::TaskRef, output: TaskOutput) -> bool {
        let mut g = self.lock();
        let Some(t) = g.tasks.get_mut(&r.task_id) else {
            return false;
        };
        if t.state
            != (TaskState::Running {
                worker: r.worker_id,
            })
            || t.task.attempt != r.attempt
        {
            return false;
        }
        t.state = TaskState::Done;
        let ev = TaskEvent::Done {
            task: r.task_id,
            shard: t.shard,
            output,
        };
        let _ = t.events.send(ev);
        if let Some(w) = g.workers.get_mut(&r.worker_id) {
            w.task = None;
        }
        true
    }

    /// The output stream of `r` broke: the task goes back in the queue.
    pub fn abandon(&self, r: &v1::TaskRef, why: &str) {
        let mut g = self.lock();
        if g.tasks.get(&r.task_id).is_some_and(|t| {
            t.state
                == (TaskState::Running {
                    worker: r.worker_id,
                })
                && t.task.attempt == r.attempt
        }) {
            tracing::warn!(
                task = r.task_id,
                worker = r.worker_id,
                why,
                "task queued again"
            );
            requeue(&mut g, r.task_id);
            if let Some(w) = g.workers.get_mut(&r.worker_id) {
                w.task = None;
            }
            drop(g);
            self.task_ready.notify_waiters();
        }
    }

    /// The worker says the task failed.
    pub fn fail(&self, r: &v1::TaskRef, error: String) {
        let mut g = self.lock();
        let max = self.cfg.max_attempts as usize;
        let Some(t) = g.tasks.get_mut(&r.task_id) else {
            return;
        };
        if t.state
            != (TaskState::Running {
                worker: r.worker_id,
            })
            || t.task.attempt != r.attempt
        {
            return;
        }
        tracing::warn!(task = r.task_id, worker = r.worker_id, error = %error, "task failed");
        t.failures.push(error);
        if t.failures.len() >= max {
            t.state = TaskState::Done;
            let msg = t.failures.join("; ");
            let _ = t.events.send(TaskEvent::Failed {
                task: r.task_id,
                error: msg,
            });
        } else {
            requeue(&mut g, r.task_id);
        }
        if let Some(w) = g.workers.get_mut(&r.worker_id) {
            w.task = None;
        }
        drop(g);
        self.task_ready.notify_waiters();
    }

    /// Declares silent workers dead and queues their tasks again.
    pub fn reap(&self) {
        let mut g = self.lock();
        let now = Instant::now();
        let dead: Vec<u64> = g
            .workers
            .iter()
            .filter(|(_, w)| now.duration_since(w.last_beat) > self.cfg.worker_timeout)
            .map(|(&id, _)| id)
            .collect();
        if dead.is_empty() {
            return;
        }
        for id in dead {
            let w = g.workers.remove(&id).expect("listed above");
            tracing::warn!(worker = id, name = %w.name, "worker missed its heartbeats: declared dead");
            if let Some(t) = w.task
                && g.tasks
                    .get(&t)
                    .is_some_and(|e| e.state == (TaskState::Running { worker: id }))
            {
                requeue(&mut g, t);
            }
        }
        drop(g);
        self.task_ready.notify_waiters();
    }

    pub fn uptime(&self) -> Duration {
        self.started.elapsed()
    }
}

fn requeue(g: &mut Inner, id: u64) {
    if let Some(t) = g.tasks.get_mut(&id) {
        t.state = TaskState::Queued;
        t.task.attempt += 1;
        let job = t.task.job_id;
        *g.requeued.entry(job).or_default() += 1;
        // To the front: a re-queued task holds up its whole stage.
        g.queue.push_front(id);
    }
}

/// Runs until the process ends: declares silent workers dead.
pub async fn monitor(shared: Arc<Shared>) {
    let mut tick = tokio::time::interval(shared.cfg.heartbeat);
    loop {
        tick.tick().await;
        shared.reap();
    }
}

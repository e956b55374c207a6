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

use crate::scenes::SceneStore;
use sray_engine::bf::{Contribution, RayRec, ResultRec};
use sray_engine::spill::{MemoryShare, Records, SpillDir};
use sray_proto::v1;
use std::collections::{HashMap, HashSet, VecDeque};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use tokio::sync::{Notify, mpsc};

/// What a client may ask of this coordinator: every request is checked
/// against these before anything is allocated for it.
#[derive(Clone, Debug)]
pub struct Limits {
    /// Width x height.
    pub max_pixels: u64,
    /// Eye rays per pixel.
    pub max_samples: u32,
    /// Depth of the ray tree.
    pub max_depth: u32,
    /// Size of an uploaded object database.
    pub max_scene_bytes: u64,
    /// Jobs running at once (finished ones kept for fetching not counted).
    pub max_jobs: usize,
    /// Voxels of a fixed main grid (each worker allocates it).
    pub max_grid_voxels: u64,
}

impl Default for Limits {
    fn default() -> Limits {
        Limits {
            max_pixels: 16 << 20,
            max_samples: 64,
            max_depth: 16,
            max_scene_bytes: 64 << 30,
            max_jobs: 16,
            max_grid_voxels: 1 << 27,
        }
    }
}

/// The coordinator's settings.
#[derive(Clone, Debug)]
pub struct Config {
    /// How often workers beat.
    pub heartbeat: Duration,
    /// A worker silent this long is dead; its task goes to another.
    pub worker_timeout: Duration,
    /// A job with work to do and no worker that may do it for this long
    /// fails.
    pub worker_wait: Duration,
    /// Rays per shard, unless a job asks otherwise.
    pub shard_rays: u64,
    /// Failures of one task (on distinct workers) that fail its job.
    pub max_attempts: u32,
    /// Uploaded scenes and the jobs' journals.
    pub data_dir: PathBuf,
    /// Rays, results and outputs in flight (default: the data directory).
    pub tmp_dir: Option<PathBuf>,
    /// Share of every shard's rays re-traced on another worker (0: none).
    pub verify_fraction: f64,
    /// Fewest rays a verification sample has (when the shard has them).
    pub verify_min_rays: u64,
    /// A task running longer than this many times the median of its
    /// finished siblings gets a backup attempt on another worker ...
    pub deadline_factor: f64,
    /// ... but never before this long ...
    pub deadline_min: Duration,
    /// ... and, while no sibling has finished, after this long.
    pub task_timeout: Duration,
    /// Failures within this time that quarantine a worker, and how long.
    pub quarantine_after: u32,
    pub quarantine: Duration,
    /// How long a finished (or failed) job stays fetchable.
    pub job_retention: Duration,
    /// Bytes of uploaded scenes kept; least recently used go first.
    pub scene_store_max: u64,
    /// Workers with a smaller `--memory` are refused at registration.
    pub min_worker_memory: u64,
    /// Memory of the coordinator's own tracer (arbitration of mismatches).
    pub arbiter_memory: u64,
    /// Memory for the records in flight (rounds' rays, tasks' outputs);
    /// beyond it they go to spill files.
    pub records_memory: u64,
    /// Journal each round's rays and frame, so that a restarted
    /// coordinator resumes its jobs where they were. Off where the data
    /// directory does not outlive the process (a `--local-workers` render),
    /// for whom a checkpoint is work no one reads.
    pub checkpoints: bool,
    /// Records stay at the workers that made them (`Task.keep_output`):
    /// an intersection's results, a shading's spawned rays. The
    /// coordinator receives only their counts and the contributions, so
    /// tasks run where their input is and nowhere else, and a job whose
    /// worker is lost starts again from its eye rays. For workers that
    /// live and die with the render (`--local-workers`), where sending
    /// every record to the coordinator and back cost more than the
    /// tracing; it needs `checkpoints` and verification off.
    pub records_at_workers: bool,
    pub limits: Limits,
}

/// The smallest worker memory accepted by default: below it the tracer
/// runs tens of passes for a handful of rays.
pub const MIN_WORKER_MEMORY: u64 = 16 << 20;

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
            verify_fraction: 0.02,
            verify_min_rays: 8,
            deadline_factor: 4.0,
            deadline_min: Duration::from_secs(30),
            task_timeout: Duration::from_secs(900),
            quarantine_after: 3,
            quarantine: Duration::from_secs(600),
            job_retention: Duration::from_secs(3600),
            scene_store_max: 50 << 30,
            min_worker_memory: MIN_WORKER_MEMORY,
            arbiter_memory: 256 << 20,
            records_memory: 256 << 20,
            checkpoints: true,
            records_at_workers: false,
            limits: Limits::default(),
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

/// Counters for `/metrics` and `sray status`: bumped once per job or
/// task (never per ray), so they cost nothing on the hot paths.
#[derive(Default, Debug)]
pub struct Counters {
    pub jobs_submitted: AtomicU64,
    pub jobs_done: AtomicU64,
    pub jobs_failed: AtomicU64,
    /// Tasks completed (the winning attempt), by stage, and verification
    /// samples among them.
    pub tasks_intersect: AtomicU64,
    pub tasks_shade: AtomicU64,
    pub tasks_verification: AtomicU64,
    /// Attempts a worker reported failed.
    pub tasks_failed: AtomicU64,
    /// Rays of completed tasks, by stage.
    pub rays_intersected: AtomicU64,
    pub rays_shaded: AtomicU64,
    /// Verification samples that disagreed with the shard's output.
    pub mismatches: AtomicU64,
    pub workers_registered: AtomicU64,
}

/// A task's input, as `TaskInput` serves it, and the bounds its output
/// must respect.
#[derive(Default)]
pub struct TaskInput {
    /// The round's rays (absent for eye rays, which workers make).
    pub rays: Option<Arc<Records<RayRec>>>,
    /// The shard's results (shading), from record `results_offset` on.
    pub results: Option<Arc<Records<ResultRec>>>,
    pub results_offset: u64,
    pub objects: u64,
    /// The most triangles of any model (the bound of an instance hit's
    /// triangle; the shading checks it against the instance's own model).
    pub model_triangles: u64,
    /// Frame slots (pixel corners, or pixels): the bound of contributions.
    pub corners: u64,
    /// Where workers may hold this input already.
    pub held: Held,
}

/// Which workers hold which records of a stage's input, by the tasks
/// that left them there: what a worker holds is named, not sent.
#[derive(Clone, Default)]
pub struct Held {
    /// The round's rays as the shadings of the previous round spawned
    /// them, in order (the round's ray file is their concatenation).
    pub rays: Arc<Vec<Segment>>,
    /// Shading: the intersection of this shard (its task and the worker
    /// whose output was taken), which holds the shard's rays and results
    /// from the shard's first ray, `shard_first`, on.
    pub intersect: Option<(u64, String)>,
    pub shard_first: u64,
    /// The input is nowhere but at the worker holding it (records at the
    /// workers): the task runs there or, once that worker is gone, fails
    /// as [`TaskEvent::Lost`].
    pub pinned: bool,
}

/// Rays `start .. start + len` of a round: the output of task `task`,
/// taken from the worker `session`.
#[derive(Clone, Debug)]
pub struct Segment {
    pub start: u64,
    pub len: u64,
    pub task: u64,
    pub session: String,
}

impl Held {
    /// The worker most of the rays `first .. first + count` are with.
    pub fn preferred(&self, first: u64, count: u64) -> Option<String> {
        if let Some((_, s)) = &self.intersect {
            return Some(s.clone());
        }
        let mut best: Option<(u64, &str)> = None;
        let mut by: HashMap<&str, u64> = HashMap::new();
        for g in self.rays.iter() {
            let lo = g.start.max(first);
            let hi = (g.start + g.len).min(first + count);
            if lo < hi {
                let n = by.entry(&g.session).or_default();
                *n += hi - lo;
                if best.is_none_or(|(b, _)| *n > b) {
                    best = Some((*n, &g.session));
                }
            }
        }
        best.map(|(_, s)| s.to_string())
    }
}

/// A task's output, as received.
#[derive(Default)]
pub struct TaskOutput {
    pub results: Option<Records<ResultRec>>,
    pub contributions: Option<Records<Contribution>>,
    pub rays: Option<Records<RayRec>>,
    /// Results that hit something (intersection).
    pub hits: u64,
    /// Spawned rays the worker kept instead of sending (shading, with
    /// `Task.keep_output`).
    pub kept_rays: u64,
    pub summary: v1::TaskSummary,
}

/// Who did a piece of work.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct WorkerTag {
    pub session: String,
    pub name: String,
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
        worker: WorkerTag,
    },
    Failed {
        task: u64,
        error: String,
    },
    /// A pinned task's input is gone with its worker.
    Lost {
        task: u64,
        error: String,
    },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TaskState {
    Queued,
    Running,
    Done,
}

struct Attempt {
    worker: WorkerTag,
    since: Instant,
}

pub struct TaskEntry {
    pub task: v1::Task,
    pub shard: usize,
    pub state: TaskState,
    pub failures: Vec<String>,
    pub input: Arc<TaskInput>,
    events: mpsc::UnboundedSender<TaskEvent>,
    live: HashMap<u32, Attempt>,
    next_attempt: u32,
    /// Sessions and names of workers this task must not go to.
    excluded: HashSet<String>,
    /// How long the winning attempt took.
    took: Option<Duration>,
    backup: bool,
    /// When it was last queued with no attempt live.
    queued_at: Instant,
    /// The worker that holds (most of) its input, if any: it gets the
    /// task first.
    prefer: Option<String>,
    /// Only `prefer` may run it (see [`Held::pinned`]).
    pinned: bool,
}

impl TaskEntry {
    fn excludes(&self, w: &WorkerTag) -> bool {
        self.excluded.contains(&w.session)
            || self.excluded.contains(&w.name)
            || (self.pinned && self.prefer.as_deref() != Some(w.session.as_str()))
    }
}

/// Loses every task pinned to the worker `session` (its records can no
/// longer be had).
fn lose_pinned_to(g: &mut Inner, session: &str, why: &str) {
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
fn lose(g: &mut Inner, id: u64, why: &str) {
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
    last_beat: Instant,
    running: HashSet<(u64, u32)>,
}

struct Quarantine {
    until: Instant,
}

#[derive(Default)]
struct Inner {
    workers: HashMap<String, Worker>,
    /// By session and by name.
    quarantined: HashMap<String, Quarantine>,
    /// Recent failures by worker name.
    failures: HashMap<String, Vec<Instant>>,
    queue: VecDeque<u64>,
    tasks: HashMap<u64, TaskEntry>,
    requeued: HashMap<String, u64>,
    backups: HashMap<String, u64>,
    workers_ever: u64,
    /// Tasks queued again (worker lost, failed, output redone), ever.
    requeued_total: u64,
}

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
    pub jobs: crate::jobs::Jobs,
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
        let (spill, spill_parent) = crate::jobs::spill_dir(&cfg)?;
        let jobs = crate::jobs::Jobs::new(&cfg.data_dir)?;
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
                let tag = WorkerTag {
                    session: session.clone(),
                    name: w.name.clone(),
                };
                let quarantined = Self::quarantined_now(&g, &tag, now);
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

    pub fn worker_count(&self) -> usize {
        self.lock().workers.len()
    }

    fn quarantined_now(g: &Inner, tag: &WorkerTag, now: Instant) -> bool {
        [&tag.session, &tag.name]
            .iter()
            .any(|k| g.quarantined.get(*k).is_some_and(|q| q.until > now))
    }

    /// Workers that may take a task that excludes `excluded` (sessions
    /// or names), not counting quarantined ones.
    pub fn eligible_workers(&self, excluded: &[WorkerTag]) -> usize {
        let g = self.lock();
        let now = Instant::now();
        g.workers
            .iter()
            .filter(|(s, w)| {
                let tag = WorkerTag {
                    session: (*s).clone(),
                    name: w.name.clone(),
                };
                !Self::quarantined_now(&g, &tag, now)
                    && !excluded
                        .iter()
                        .any(|e| e.session == tag.session || e.name == tag.name)
            })
            .count()
    }

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
                if !Self::quarantined_now(&g, &tag, now) {
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

    fn live_attempt<'a>(g: &'a Inner, r: &v1::TaskRef) -> Option<&'a TaskEntry> {
        let t = g.tasks.get(&r.task_id)?;
        let a = t.live.get(&r.attempt)?;
        (t.state != TaskState::Done
            && sray_proto::ids::same(a.worker.session.as_bytes(), r.session.as_bytes()))
        .then_some(t)
    }

    /// The input of a task the worker is running.
    pub fn task_input(&self, r: &v1::TaskRef) -> Result<(v1::Task, Arc<TaskInput>), Refusal> {
        let g = self.lock();
        let t = Self::live_attempt(&g, r).ok_or(Refusal::NotYours)?;
        let mut task = t.task.clone();
        task.attempt = r.attempt;
        Ok((task, t.input.clone()))
    }

    /// Removes a live attempt; returns its worker.
    fn drop_attempt(g: &mut Inner, id: u64, attempt: u32) -> Option<WorkerTag> {
        let t = g.tasks.get_mut(&id)?;
        let a = t.live.remove(&attempt)?;
        if let Some(w) = g.workers.get_mut(&a.worker.session) {
            w.running.remove(&(id, attempt));
        }
        Some(a.worker)
    }

    /// A complete output arrived: the task is done, if `r` is a live
    /// attempt of it (else the output is dropped and false returned). The
    /// first output wins; other live attempts are dropped.
    pub fn complete(&self, r: &v1::TaskRef, output: TaskOutput) -> bool {
        let mut g = self.lock();
        if Self::live_attempt(&g, r).is_none() {
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
            Self::drop_attempt(&mut g, r.task_id, a);
        }
        true
    }

    /// The output stream of `r` broke: the attempt is dropped, and the
    /// task queued again if no other attempt is live.
    pub fn abandon(&self, r: &v1::TaskRef, why: &str) {
        let mut g = self.lock();
        if Self::live_attempt(&g, r).is_none() {
            return;
        }
        tracing::warn!(task = r.task_id, why, "attempt abandoned");
        Self::drop_attempt(&mut g, r.task_id, r.attempt);
        requeue_if_idle(&mut g, r.task_id);
        drop(g);
        self.task_ready.notify_waiters();
    }

    /// The worker says the task failed (or its output was refused): never
    /// again on that worker; the job fails after `max_attempts` failures.
    pub fn fail(&self, r: &v1::TaskRef, error: String) {
        let mut g = self.lock();
        if Self::live_attempt(&g, r).is_none() {
            return;
        }
        let max = self.cfg.max_attempts as usize;
        let worker = Self::drop_attempt(&mut g, r.task_id, r.attempt).expect("live");
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

    /// Gives `worker` no task for `cfg.quarantine`; its live attempts are
    /// dropped and their tasks queued again elsewhere.
    pub fn quarantine(&self, worker: &WorkerTag, why: &str) {
        let mut g = self.lock();
        let until = Instant::now() + self.cfg.quarantine;
        tracing::warn!(worker = %worker.name, why, seconds = self.cfg.quarantine.as_secs(), "worker quarantined");
        g.quarantined
            .insert(worker.session.clone(), Quarantine { until });
        g.quarantined
            .insert(worker.name.clone(), Quarantine { until });
        let mine: Vec<(u64, u32)> = g
            .tasks
            .iter()
            .flat_map(|(id, t)| {
                t.live
                    .iter()
                    .filter(|(_, a)| a.worker.session == worker.session)
                    .map(move |(a, _)| (*id, *a))
            })
            .collect();
        for (id, a) in mine {
            Self::drop_attempt(&mut g, id, a);
            if let Some(t) = g.tasks.get_mut(&id) {
                t.excluded.insert(worker.session.clone());
                t.excluded.insert(worker.name.clone());
            }
            requeue_if_idle(&mut g, id);
        }
        lose_pinned_to(
            &mut g,
            &worker.session,
            "the worker holding its input is quarantined",
        );
        drop(g);
        self.task_ready.notify_waiters();
    }

    /// Whether the worker is quarantined now.
    pub fn is_quarantined(&self, worker: &WorkerTag) -> bool {
        Self::quarantined_now(&self.lock(), worker, Instant::now())
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

    /// Backup attempts for the tasks among `ids` that run far longer than
    /// their finished siblings (or than `task_timeout` while none has
    /// finished). Returns the ids given a backup, with how long they ran.
    pub fn issue_backups(&self, ids: &[u64]) -> Vec<(u64, Duration)> {
        let mut g = self.lock();
        let mut took: Vec<Duration> = ids
            .iter()
            .filter_map(|id| g.tasks.get(id).and_then(|t| t.took))
            .collect();
        took.sort();
        let deadline = match took.get(took.len() / 2) {
            Some(median) => median
                .mul_f64(self.cfg.deadline_factor)
                .max(self.cfg.deadline_min),
            None => self.cfg.task_timeout,
        };
        let now = Instant::now();
        let mut backed = Vec::new();
        let mut stuck = Vec::new();
        for id in ids {
            let Some(t) = g.tasks.get_mut(id) else {
                continue;
            };
            if t.state != TaskState::Running || t.backup {
                continue;
            }
            let Some(oldest) = t.live.values().map(|a| a.since).min() else {
                continue;
            };
            let ran = now.duration_since(oldest);
            // A pinned task can run nowhere else: past the task timeout,
            // its worker is taken to be stuck and the job starts again.
            if t.pinned {
                if ran > self.cfg.task_timeout {
                    stuck.push(*id);
                }
                continue;
            }
            if ran > deadline {
                t.backup = true;
                let job = t.task.job_id.clone();
                *g.backups.entry(job).or_default() += 1;
                g.queue.push_front(*id);
                backed.push((*id, ran));
            }
        }
        for id in stuck {
            lose(&mut g, id, "it ran past --task-timeout where its input is");
        }
        drop(g);
        if !backed.is_empty() {
            self.task_ready.notify_waiters();
        }
        backed
    }

    /// Tasks among `ids` queued, with no attempt live, for longer than
    /// `wait` (every worker that may take them is busy or stuck).
    pub fn waiting(&self, ids: &[u64], wait: Duration) -> Vec<u64> {
        let g = self.lock();
        ids.iter()
            .copied()
            .filter(|id| {
                g.tasks
                    .get(id)
                    .is_some_and(|t| t.state == TaskState::Queued && t.queued_at.elapsed() > wait)
            })
            .collect()
    }

    /// Queued tasks among `ids` that no registered worker may take.
    pub fn stranded(&self, ids: &[u64]) -> Vec<(u64, String)> {
        let g = self.lock();
        let now = Instant::now();
        ids.iter()
            .filter_map(|id| {
                let t = g.tasks.get(id)?;
                if t.state != TaskState::Queued {
                    return None;
                }
                let any = g.workers.iter().any(|(s, w)| {
                    let tag = WorkerTag {
                        session: s.clone(),
                        name: w.name.clone(),
                    };
                    !t.excludes(&tag) && !Self::quarantined_now(&g, &tag, now)
                });
                (!any).then(|| (*id, t.failures.join("; ")))
            })
            .collect()
    }

    /// Declares silent workers dead and queues their tasks again.
    pub fn reap(&self) {
        let mut g = self.lock();
        let now = Instant::now();
        let dead: Vec<String> = g
            .workers
            .iter()
            .filter(|(_, w)| now.duration_since(w.last_beat) > self.cfg.worker_timeout)
            .map(|(s, _)| s.clone())
            .collect();
        g.quarantined.retain(|_, q| q.until > now);
        if dead.is_empty() {
            return;
        }
        for s in dead {
            let w = g.workers.remove(&s).expect("listed above");
            tracing::warn!(name = %w.name, "worker missed its heartbeats: declared dead");
            for (id, a) in w.running {
                if let Some(t) = g.tasks.get_mut(&id) {
                    t.live.remove(&a);
                }
                requeue_if_idle(&mut g, id);
            }
            lose_pinned_to(&mut g, &s, "the worker holding its input is gone");
        }
        drop(g);
        self.task_ready.notify_waiters();
    }

    pub fn uptime(&self) -> Duration {
        self.started.elapsed()
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

/// Queues a task again if it is not done and no attempt of it is live
/// (a pinned task is lost instead: it could only go back where it was).
fn requeue_if_idle(g: &mut Inner, id: u64) {
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
        g.queue.push_front(id);
    }
}

/// Runs until the process ends: declares silent workers dead, expires
/// finished jobs and evicts scenes over the store's cap.
pub async fn monitor(shared: Arc<Shared>) {
    let mut tick = tokio::time::interval(shared.cfg.heartbeat);
    let mut last_expiry = Instant::now();
    loop {
        tick.tick().await;
        shared.reap();
        if last_expiry.elapsed() >= Duration::from_secs(1) {
            last_expiry = Instant::now();
            let sh = shared.clone();
            let _ = tokio::task::spawn_blocking(move || crate::jobs::housekeeping(&sh)).await;
        }
    }
}

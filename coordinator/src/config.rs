//! The coordinator's settings (`sray coordinator`'s flags) and the limits
//! it holds clients' requests to.

use std::path::PathBuf;
use std::time::Duration;

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
    /// Rays per shard, unless a job asks otherwise; 0: sized for the
    /// cluster (the round's rays, the workers, the database's size).
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
    /// A worker that lacked room (disk) for a task is given that task
    /// again only after this long.
    pub room_retry: Duration,
    /// Failures (and timeouts) within this time that quarantine a worker,
    /// and how long.
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
    /// tasks run where their input is and nowhere else, and the records
    /// of a worker that is lost (or stuck on such a task past a backup's
    /// deadline) are recomputed elsewhere from the rounds that led to
    /// them (`driver/recover.rs`). For workers that
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
            shard_rays: 0,
            max_attempts: 3,
            data_dir: PathBuf::from("sray-data"),
            tmp_dir: None,
            verify_fraction: 0.02,
            verify_min_rays: 8,
            deadline_factor: 4.0,
            deadline_min: Duration::from_secs(30),
            task_timeout: Duration::from_secs(900),
            room_retry: Duration::from_secs(10),
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

//! A job's executor: one thread that owns the job's database and its
//! breadth-first [`Tracer`] (grids built once per job), and runs the job's
//! tasks one after another. The engine is synchronous and uses its own
//! thread pool; the thread talks to the async side through channels, so
//! the network never waits on the tracer nor the tracer on the network,
//! beyond the few chunks the channels hold.

pub use crate::inputs::Inputs;
use crate::inputs::read_inputs;
pub use crate::kept::{KEPT_MEMORY_PART, Kept, ResultSlice, Slice};
use crate::kept::{KeptStore, Pin};
use crate::output::{Encoder, Output};
use sray_engine::bf::{
    BfOptions, Contribution, Outcome, RayRec, RaySource, ResultReader, ResultRec, Tracer, eye_ray,
};
use sray_engine::progress::NoProgress;
use sray_engine::render::{Camera, EyeRays, Precision, RayCounts, RenderOptions};
use sray_engine::sdb::Database;
use sray_engine::simd::Elem;
use sray_engine::spill::{MemoryShare, RecordWriter, Records, SpillDir};
use sray_proto::v1::{self, RecordKind, task_output::Part};
use sray_proto::wire::records_per_chunk;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;
use tokio::sync::{mpsc, oneshot};

/// What a job's tasks share. `key` names the setup by content (the
/// scene's hash and a hash of the render settings), never by job id: two
/// jobs with the same key may share an executor, and a job id that a
/// restarted coordinator might issue again can never select another
/// scene's executor.
pub struct JobSetup {
    pub key: String,
    /// The scene's content hash.
    pub scene: String,
    pub db_path: PathBuf,
    pub opts: RenderOptions,
    pub bf: BfOptions,
    /// Keep what tasks received and made (their rays and results) for
    /// later tasks, which then need not receive them again.
    pub keep: bool,
    /// What kept and received records may take of memory (shared by a
    /// node's executors); beyond it they go to spill files.
    pub kept_memory: MemoryShare,
    /// Send records as they lie in memory, not encoded (the coordinator
    /// is on this machine).
    pub raw_records: bool,
}

/// What an executor's thread is asked to do.
enum Msg {
    Run(Box<Work>),
    /// Give back the tracer's reusable buffers (see [`Executor::trim`]).
    Trim,
    /// The jobs running (see [`Executor::jobs_running`]).
    JobsRunning {
        jobs: Vec<String>,
        asked: Instant,
    },
}

/// One task for the executor, with its input stream (if it has input), the
/// channel its output goes to, and where to say how it ended.
pub struct Work {
    pub task: v1::Task,
    pub input: Input,
    pub out: mpsc::Sender<v1::TaskOutput>,
    pub done: oneshot::Sender<Result<(), String>>,
    /// The executor was started for this task (its grids were built for
    /// it): said in the task's summary.
    pub fresh: bool,
    /// Asks for the next task at the end of the output (the records this
    /// executor keeps added to those named): the coordinator answers it
    /// with the output's reply, and the worker makes no NextTask call.
    pub next: Option<v1::NextTaskRequest>,
}

/// A task's input records.
pub enum Input {
    /// None (eye rays, intersection).
    None,
    /// From the coordinator.
    Stream(tonic::Streaming<v1::RecordChunk>),
    /// Sent with the task (`NextTaskReply.input`): records kept here,
    /// named.
    Chunks(Vec<v1::RecordChunk>),
    /// Files already here (the coordinator tracing a sample itself).
    Files(Inputs),
}

pub struct Executor {
    pub key: String,
    pub scene: String,
    pub db_path: PathBuf,
    /// The jobs it has run tasks of (each job's first task checks the
    /// scene, as a new setup's does).
    pub jobs: std::collections::HashSet<String>,
    tx: Option<std::sync::mpsc::Sender<Msg>>,
    thread: Option<std::thread::JoinHandle<()>>,
    /// What the executor keeps.
    held: Arc<Mutex<Holding>>,
}

/// The ids of the tasks whose records an executor keeps, and whether any
/// are pinned (kept nowhere else).
#[derive(Default)]
struct Holding {
    ids: Vec<u64>,
    pinned: bool,
}

fn publish(held: &Mutex<Holding>, kept: &KeptStore) {
    *held.lock().unwrap_or_else(|p| p.into_inner()) = Holding {
        ids: kept.ids(),
        pinned: kept.has_pins(),
    };
}

/// Dropping an executor ends its thread and waits for it, so that the
/// job's memory and spill files are gone when the drop returns.
impl Drop for Executor {
    fn drop(&mut self) {
        self.tx = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Executor {
    /// Starts the job's thread; the database is opened and the grids built
    /// there, before the first task runs.
    pub fn start(setup: JobSetup, rt: tokio::runtime::Handle) -> Executor {
        let (tx, rx) = std::sync::mpsc::channel::<Msg>();
        let key = setup.key.clone();
        let (scene, db_path) = (setup.scene.clone(), setup.db_path.clone());
        let held = Arc::new(Mutex::new(Holding::default()));
        let h2 = held.clone();
        let thread = std::thread::Builder::new()
            .name(format!("setup-{}", &key[..key.len().min(8)]))
            .spawn(move || match setup.opts.precision {
                Precision::Double => job_thread::<f64>(setup, rt, rx, h2),
                Precision::Single => job_thread::<f32>(setup, rt, rx, h2),
            })
            .expect("cannot start a thread");
        Executor {
            key,
            scene,
            db_path,
            jobs: Default::default(),
            tx: Some(tx),
            thread: Some(thread),
            held,
        }
    }

    /// The tasks whose records this executor keeps (for a TaskInput
    /// request: the coordinator sends only what is not among them).
    /// Between this call and the task's input being read nothing is
    /// dropped: a task drops kept records only after it has read its
    /// input, and the list is brought up to date when it ends.
    pub fn held(&self) -> Vec<u64> {
        self.held
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .ids
            .clone()
    }

    /// Whether it keeps records that are nowhere else (records at the
    /// workers): dropping it would cost their job a restart.
    pub fn holds_pins(&self) -> bool {
        self.held.lock().unwrap_or_else(|p| p.into_inner()).pinned
    }

    /// Queues a task; false if the thread has ended.
    pub fn submit(&self, w: Work) -> bool {
        self.tx
            .as_ref()
            .is_some_and(|tx| tx.send(Msg::Run(Box::new(w))).is_ok())
    }

    /// Tells the executor which jobs run (as the coordinator answered a
    /// question asked at `asked`): it drops the records it keeps for
    /// jobs that have ended.
    pub fn jobs_running(&self, jobs: Vec<String>, asked: Instant) {
        if let Some(tx) = &self.tx {
            let _ = tx.send(Msg::JobsRunning { jobs, asked });
        }
    }

    /// Asks the (idle) executor to give back the buffers its tracer keeps
    /// between tasks, keeping its grids: another setup's tasks run now,
    /// with the worker's whole budget.
    pub fn trim(&self) {
        if let Some(tx) = &self.tx {
            let _ = tx.send(Msg::Trim);
        }
    }
}

fn job_thread<R: Elem>(
    setup: JobSetup,
    rt: tokio::runtime::Handle,
    rx: std::sync::mpsc::Receiver<Msg>,
    held: Arc<Mutex<Holding>>,
) {
    let db = match Database::open(&setup.db_path) {
        Ok(db) => db,
        Err(e) => return fail_all(rx, &format!("cannot open the scene: {e}")),
    };
    let eye = match Camera::new(&db.scene().view, setup.opts.width, setup.opts.height) {
        Ok(camera) => EyeRays {
            camera,
            sampling: setup.opts.sampling(),
        },
        Err(e) => return fail_all(rx, &e.to_string()),
    };
    let t0 = Instant::now();
    let mut tracer = match Tracer::<R>::new(&db, &setup.opts, &setup.bf, 0, &NoProgress) {
        Ok(t) => t,
        Err(e) => return fail_all(rx, &e.to_string()),
    };
    tracing::info!(
        setup = %setup.key,
        seconds = t0.elapsed().as_secs_f64(),
        "grids built"
    );
    let eye_rays = eye.count();
    let mut kept = KeptStore::default();
    let encoder = Encoder::start(setup.raw_records);
    for m in rx {
        let w = match m {
            Msg::Run(w) => *w,
            Msg::Trim => {
                tracer.trim();
                continue;
            }
            Msg::JobsRunning { jobs, asked } => {
                kept.release_ended(&jobs, asked);
                publish(&held, &kept);
                continue;
            }
        };
        let Work {
            task,
            input,
            out,
            done,
            fresh,
            next,
        } = w;
        let run = std::panic::AssertUnwindSafe(|| {
            let mut ctx = TaskCtx {
                eye: &eye,
                eye_rays,
                rt: &rt,
                kept: &mut kept,
                share: &setup.kept_memory,
                keep: setup.keep || task.keep_output,
                fresh,
            };
            run_task(
                &mut tracer,
                &mut ctx,
                &task,
                input,
                &encoder.output(out.clone()),
            )
        });
        let r = std::panic::catch_unwind(run).unwrap_or_else(|p| {
            Err(format!(
                "the tracer panicked: {}",
                p.downcast_ref::<String>()
                    .map(String::as_str)
                    .or_else(|| p.downcast_ref::<&str>().copied())
                    .unwrap_or("unknown cause")
            ))
        });
        let r = r.map(|k| {
            if let Some(k) = k {
                kept.insert(task.task_id, k);
            }
        });
        // After every task, failed or not: a task may have dropped kept
        // records to make room before it failed.
        publish(&held, &kept);
        // The request for the next task goes after the summary, through
        // the same queue, naming what is kept here now.
        // (A stream already closed drops it, as it drops the output.)
        if let (Ok(()), Some(mut req)) = (&r, next) {
            req.held.extend(kept.ids());
            let _ = encoder.output(out).part(Part::Next(req));
        }
        let _ = done.send(r);
    }
}

/// What a task runs with, besides the tracer.
struct TaskCtx<'a> {
    eye: &'a EyeRays,
    eye_rays: u64,
    rt: &'a tokio::runtime::Handle,
    kept: &'a mut KeptStore,
    share: &'a MemoryShare,
    keep: bool,
    fresh: bool,
}

fn fail_all(rx: std::sync::mpsc::Receiver<Msg>, e: &str) {
    for m in rx {
        if let Msg::Run(w) = m {
            let _ = w.done.send(Err(e.to_string()));
        }
    }
}

/// Runs a task; returns what to keep of it (when the setup keeps
/// records).
fn run_task<R: Elem>(
    tracer: &mut Tracer<R>,
    ctx: &mut TaskCtx<'_>,
    task: &v1::Task,
    input: Input,
    out: &Output<'_>,
) -> Result<Option<Kept>, String> {
    let (eye, eye_rays, rt) = (ctx.eye, ctx.eye_rays, ctx.rt);
    let t0 = Instant::now();
    let (first, n) = (task.first_ray, task.ray_count);
    if task.eye_rays && first.checked_add(n).is_none_or(|end| end > eye_rays) {
        return Err(format!(
            "eye rays {first}..{} are beyond the image's {eye_rays}",
            first.saturating_add(n)
        ));
    }
    let mut inputs = read_inputs(tracer, rt, ctx.kept, ctx.share, input)?;
    if task.keep_output {
        // Its input read, what this job's later tasks cannot ask for goes,
        // its buffers back to the tracer (fresh memory for every round's
        // results and spawned rays cost a page fault per 4 KiB).
        for k in ctx.kept.release(&task.job_id, task.round) {
            if let Some(Ok(v)) = k.rays.map(Slice::whole_vec) {
                tracer.recycle_rays(v);
            }
            if let Some(ResultSlice::Carried(s)) = k.results
                && let Ok(v) = s.whole_vec()
            {
                tracer.recycle(ResultReader::Dense { v, next: 0 });
            }
        }
    }
    let t_in = t0.elapsed().as_secs_f64();
    let io = |e: sray_engine::Error| e.to_string();
    // The shard's rays: made here for the eye rays, else as received.
    let ray_slice = if task.eye_rays {
        None
    } else {
        let f = inputs.rays.as_ref().ok_or("task input: no rays")?;
        if f.len() != n {
            return Err(format!("task input: {} rays for a shard of {n}", f.len()));
        }
        Some(f)
    };
    let mut summary = v1::TaskSummary {
        built_grids: ctx.fresh,
        ..Default::default()
    };
    let mut kept = None;
    // Records the coordinator does not take are pinned here.
    let pin = task.keep_output.then(|| Pin {
        job: task.job_id.clone(),
        round: task.round,
        at: Instant::now(),
    });
    match v1::Stage::try_from(task.stage) {
        Ok(v1::Stage::Intersect) => {
            let (results, ist) = with_rays(eye, first, n, ray_slice, |src| {
                tracer
                    .intersect(first, src, n, false, &NoProgress)
                    .map_err(io)
            })?;
            let send = !task.keep_output;
            let mut digest = blake3::Hasher::new();
            let (kept_results, hits) = send_results(tracer, ctx, results, out, send, &mut digest)?;
            if !send {
                summary.kept_records = n;
                summary.kept_hits = hits;
                summary.kept_digest = digest.finalize().as_bytes().to_vec();
            }
            if let Some(r) = kept_results {
                kept = Some(Kept {
                    rays: inputs.rays.take(),
                    results: Some(r),
                    pin: pin.clone(),
                });
            }
            let t = ist.intersection_tests;
            summary.tests_by_kind = t.named().map(|(k, n)| (k.to_string(), n)).collect();
            summary.stats_json = serde_json::to_string(&ist).unwrap_or_default();
        }
        Ok(v1::Stage::Shade) => {
            let results_in = inputs.results.as_ref().ok_or("task input: no results")?;
            if results_in.len() != n {
                return Err(format!(
                    "task input: {} results for a shard of {n}",
                    results_in.len()
                ));
            }
            let results_in = inputs.results.take().expect("checked above");
            let mut results = result_reader(tracer, results_in)?;
            let per = records_per_chunk::<Contribution>();
            let mut buf: Vec<Contribution> = Vec::with_capacity(per);
            let mut send_err = None;
            let mut counts = RayCounts::default();
            // With records kept here, verification compares what the
            // contributions add to each frame slot, not the contributions
            // one by one (see the coordinator's `driver/held.rs`): a
            // contribution to the
            // same frame slot as the one before (a hit's shadow rays, one
            // per light) is added to it instead of sent on its own, and
            // one of the same colour to the next slot (a row of eye rays
            // that missed) lengthens its run. Sums of integers far from
            // the frame's saturation are exact in any order; colours
            // beyond 2^30 (in fixed point, 2^62) are sent apart, as the
            // frame adds them saturating. Each chunk of them then
            // travels packed per slot (`sray_proto::colour`: sorted by
            // slot, a slot's colours added, nothing to decompress), which
            // the coordinator adds at a fraction of the cost of
            // contributions.
            let merge = task.keep_output;
            let small = |c: &[i64; 3]| c.iter().all(|x| x.unsigned_abs() < 1 << 62);
            let (next, _count, sst) = {
                let mut contribute = |corner: u32, rgb: [i64; 3]| {
                    if send_err.is_some() {
                        return;
                    }
                    if merge && let Some(last) = buf.last_mut() {
                        if last.run == 0 && last.corner == corner && small(&rgb) && small(&last.rgb)
                        {
                            // Both below 2^62: the sum fits.
                            for (a, b) in last.rgb.iter_mut().zip(rgb) {
                                *a += b;
                            }
                            return;
                        }
                        if last.rgb == rgb && last.end() == corner as u64 {
                            last.run += 1;
                            return;
                        }
                    }
                    buf.push(Contribution {
                        corner,
                        run: 0,
                        rgb,
                    });
                    if buf.len() == per {
                        if let Err(e) = send_colour(out, merge, &buf) {
                            send_err = Some(e);
                        }
                        buf.clear();
                    }
                };
                with_rays(eye, first, n, ray_slice, |src| {
                    tracer
                        .shade(first, src, &mut results, &mut contribute, &mut counts)
                        .map_err(io)
                })?
            };
            tracer.recycle(results);
            if let Some(e) = send_err {
                return Err(e);
            }
            if !buf.is_empty() {
                send_colour(out, merge, &buf)?;
            }
            let per = records_per_chunk::<RayRec>();
            let send = !task.keep_output;
            let mut keys = KeyRange::default();
            // What is kept instead of sent is hashed, for verification
            // to compare (see `TaskSummary.kept_digest`).
            let mut digest = blake3::Hasher::new();
            let kept_rays = match next.into_vec() {
                // Sorted in memory: sent from where they lie, and kept
                // there if the share allows (else the buffer goes back to
                // the tracer for the next task's sort).
                Ok(v) => {
                    for chunk in v.chunks(per).filter(|_| send) {
                        out.records(RecordKind::Rays, chunk)?;
                    }
                    if !send {
                        digest.update(bytemuck::cast_slice(&v));
                    }
                    // Sorted: the first and last keys are the range.
                    keys = KeyRange {
                        count: v.len() as u64,
                        first: v.first().map_or(0, |r| r.key),
                        last: v.last().map_or(0, |r| r.key),
                    };
                    if ctx.keep {
                        Some(keep_vec(tracer, ctx, v, "kept-rays", |t, v| {
                            t.recycle_rays(v)
                        })?)
                    } else {
                        tracer.recycle_rays(v);
                        None
                    }
                }
                Err(mut sorted) => stream_and_keep(
                    out.filter(send),
                    RecordKind::Rays,
                    ctx.keep.then_some((&tracer.spill, "kept-rays")),
                    || {
                        let r = sorted.next()?;
                        if let Some(r) = &r {
                            keys.add(r.key);
                            if !send {
                                digest.update(bytemuck::bytes_of(r));
                            }
                        }
                        Ok(r)
                    },
                )?
                .map(|f| Slice::whole(Records::File(f))),
            };
            if !send {
                summary.kept_records = keys.count;
                summary.kept_first_key = keys.first;
                summary.kept_last_key = keys.last;
                summary.kept_digest = digest.finalize().as_bytes().to_vec();
            }
            if let Some(r) = kept_rays {
                kept = Some(Kept {
                    rays: Some(r),
                    results: None,
                    pin: pin.clone(),
                });
            }
            summary.eye_hit_rays = counts.eye_hit_rays;
            summary.reflect_rays = counts.reflect_rays;
            summary.refract_rays = counts.refract_rays;
            summary.shadow_rays = counts.shadow_rays;
            summary.stats_json = serde_json::to_string(&sst).unwrap_or_default();
        }
        _ => return Err(format!("unknown stage {}", task.stage)),
    }
    summary.seconds = t0.elapsed().as_secs_f64();
    tracing::debug!(
        task = task.task_id,
        stage = task.stage,
        rays = n,
        input_seconds = t_in,
        seconds = summary.seconds,
        "task run"
    );
    out.part(Part::Summary(summary))?;
    Ok(kept)
}

/// Calls `f` with the shard's `n` rays (ids from `first`): by id where
/// that is possible (eye rays made here, rays in memory), so that every
/// thread of the tracer takes its own; else read in order from their file.
fn with_rays<T>(
    eye: &EyeRays,
    first: u64,
    n: u64,
    rays: Option<&Slice<RayRec>>,
    f: impl FnOnce(RaySource<'_>) -> Result<T, String>,
) -> Result<T, String> {
    match rays {
        None => f(RaySource::Indexed {
            len: n,
            ray: &|i| eye_ray(eye, first + i),
        }),
        Some(s) => match s.as_slice() {
            Some(v) => f(RaySource::Indexed {
                len: v.len() as u64,
                ray: &|i| v[i as usize],
            }),
            None => {
                let mut rd = s.reader().map_err(|e| e.to_string())?;
                let mut it = std::iter::from_fn(move || rd.next().transpose());
                f(RaySource::Stream(&mut it))
            }
        },
    }
}

/// Sends an intersection's results as they travel (ray, object, distance)
/// and returns what the executor keeps of them: in memory with their
/// surfaces while the share allows, else bare in a file. Results not sent
/// are hashed into `digest` as they would have travelled.
fn send_results<R: Elem>(
    tracer: &mut Tracer<R>,
    ctx: &mut TaskCtx<'_>,
    mut results: ResultReader,
    out: &Output<'_>,
    send: bool,
    digest: &mut blake3::Hasher,
) -> Result<(Option<ResultSlice>, u64), String> {
    let per = records_per_chunk::<ResultRec>();
    let mut buf = Vec::with_capacity(per);
    if let ResultReader::Dense { v, .. } = results {
        for chunk in v.chunks(per).filter(|_| send) {
            buf.clear();
            buf.extend(chunk.iter().map(|o| o.res));
            out.records(RecordKind::Results, &buf)?;
        }
        // Counted (and hashed) for the coordinator only when it does not
        // see them.
        let hits = if send {
            0
        } else {
            for o in &v {
                digest.update(bytemuck::bytes_of(&o.res));
            }
            v.iter().filter(|o| !o.res.prim.is_none()).count() as u64
        };
        if !ctx.keep {
            tracer.recycle(ResultReader::Dense { v, next: 0 });
            return Ok((None, hits));
        }
        let s = keep_vec(tracer, ctx, v, "kept-results", |t, v| {
            t.recycle(ResultReader::Dense { v, next: 0 })
        })?;
        return Ok((Some(ResultSlice::Carried(s)), hits));
    }
    let mut hits = 0;
    let kept = stream_and_keep(
        out.filter(send),
        RecordKind::Results,
        ctx.keep.then_some((&tracer.spill, "kept-results")),
        || {
            let r = results.next_result()?;
            hits += r.is_some_and(|r| !r.prim.is_none()) as u64;
            if let (Some(r), false) = (&r, send) {
                digest.update(bytemuck::bytes_of(r));
            }
            Ok(r)
        },
    )?;
    tracer.recycle(results);
    Ok((
        kept.map(|f| ResultSlice::Bare(Slice::whole(Records::File(f)))),
        hits,
    ))
}

/// The count and the first and last keys of spawned rays, in key order.
#[derive(Default)]
struct KeyRange {
    count: u64,
    first: u64,
    last: u64,
}

impl KeyRange {
    fn add(&mut self, key: u64) {
        if self.count == 0 {
            self.first = key;
        }
        self.last = key;
        self.count += 1;
    }
}

/// Sends the records `next` yields, in chunks, and writes them to a file
/// too if `keep` names one (the spill directory and what for).
fn stream_and_keep<T: bytemuck::Pod>(
    out: Option<&Output<'_>>,
    kind: RecordKind,
    keep: Option<(&SpillDir, &str)>,
    mut next: impl FnMut() -> Result<Option<T>, sray_engine::Error>,
) -> Result<Option<sray_engine::spill::RecordFile<T>>, String> {
    let io = |e: sray_engine::Error| e.to_string();
    let per = records_per_chunk::<T>();
    let mut w = keep
        .map(|(spill, what)| RecordWriter::<T>::create(spill, what))
        .transpose()
        .map_err(io)?;
    let mut buf = Vec::with_capacity(per);
    loop {
        let r = next().map_err(io)?;
        if let Some(r) = r {
            buf.push(r);
        }
        if buf.len() == per || (r.is_none() && !buf.is_empty()) {
            if let Some(out) = out {
                out.records(kind, &buf)?;
            }
            if let Some(w) = &mut w {
                w.extend(&buf).map_err(io)?;
            }
            buf.clear();
        }
        if r.is_none() {
            return w.map(|w| w.finish()).transpose().map_err(io);
        }
    }
}

/// Keeps a task's output vector: in memory if the share can pay for it
/// (after dropping older records held in memory), else written to a file
/// and the vector handed back to the tracer (`give_back`).
fn keep_vec<R: Elem, T: bytemuck::Pod>(
    tracer: &mut Tracer<R>,
    ctx: &mut TaskCtx<'_>,
    v: Vec<T>,
    what: &str,
    give_back: impl FnOnce(&mut Tracer<R>, Vec<T>),
) -> Result<Slice<T>, String> {
    let bytes = (v.capacity() * std::mem::size_of::<T>()) as u64;
    ctx.kept.make_room(ctx.share, bytes);
    if let Some(lease) = ctx.share.try_lease(bytes) {
        return Ok(Slice::whole(Records::memory(v, lease)));
    }
    let io = |e: sray_engine::Error| e.to_string();
    let mut w = RecordWriter::<T>::create(&tracer.spill, what).map_err(io)?;
    w.extend(&v).map_err(io)?;
    give_back(tracer, v);
    Ok(Slice::whole(Records::File(w.finish().map_err(io)?)))
}

/// A reader of a shading task's results. Kept ones carry their surfaces
/// (no pass over the objects); bare ones are joined with the objects.
/// They are copied into the tracer's result buffer when its budget holds
/// them all, and else read from a file as they are needed.
fn result_reader<R: Elem>(
    tracer: &mut Tracer<R>,
    results: ResultSlice,
) -> Result<ResultReader, String> {
    let io = |e: sray_engine::Error| e.to_string();
    let fits = tracer.budget.results_resident(results.len());
    Ok(match results {
        // Kept with their surfaces only when the intersection's results
        // were in memory, which the same budget allows now.
        ResultSlice::Carried(s) => match s.whole_vec() {
            // Held by this task alone: shaded from where they lie, and
            // the buffer goes back to the tracer (no copy, no fresh
            // memory for the next intersection).
            Ok(v) => ResultReader::Dense { v, next: 0 },
            Err(s) => match s.as_slice() {
                Some(v) => tracer.dense_results(v.iter().copied()),
                None => {
                    let mut rd = s.reader().map_err(io)?;
                    let mut err = None;
                    let r = tracer.dense_results(std::iter::from_fn(|| {
                        rd.next().unwrap_or_else(|e| {
                            err = Some(e);
                            None
                        })
                    }));
                    if let Some(e) = err {
                        return Err(io(e));
                    }
                    r
                }
            },
        },
        ResultSlice::Bare(s) => match (s.as_slice(), &*s.records, fits) {
            (Some(v), _, true) => tracer.dense_results(v.iter().map(|&r| Outcome::bare(r))),
            (Some(v), _, false) => {
                // Too many to widen in memory: to a file, read as needed
                // (the reader keeps the file open after its name is gone).
                let mut w =
                    RecordWriter::<ResultRec>::create(&tracer.spill, "in-results").map_err(io)?;
                w.extend(v).map_err(io)?;
                ResultReader::File(w.finish().map_err(io)?.reader().map_err(io)?)
            }
            (None, Records::File(f), _) => {
                ResultReader::File(f.reader_range(s.start, s.count).map_err(io)?)
            }
            (None, _, _) => {
                // In parts (a chain): to a file, read as needed.
                let mut w =
                    RecordWriter::<ResultRec>::create(&tracer.spill, "in-results").map_err(io)?;
                let mut rd = s.reader().map_err(io)?;
                while let Some(r) = rd.next().map_err(io)? {
                    w.push(&r).map_err(io)?;
                }
                ResultReader::File(w.finish().map_err(io)?.reader().map_err(io)?)
            }
        },
    })
}

/// Sends a chunk of a shading's contributions: packed per slot where the
/// records stay here (`keep`), else as they are (verification compares
/// them one by one).
fn send_colour(out: &Output<'_>, keep: bool, buf: &[Contribution]) -> Result<(), String> {
    if !keep {
        return out.records(RecordKind::Contributions, buf);
    }
    // Encoded as bytes, as records are (or raw).
    out.records(RecordKind::Colour, &pack_colour(buf))
}

/// A chunk of contributions packed per slot
/// ([`sray_proto::colour::pack`]), as a worker that keeps its records
/// sends them.
pub fn pack_colour(buf: &[Contribution]) -> Vec<u8> {
    use sray_proto::colour::{SlotColour, pack};
    let mut v: Vec<SlotColour> = buf
        .iter()
        .map(|x| SlotColour {
            slot: x.corner,
            run: x.run,
            rgb: x.rgb,
        })
        .collect();
    pack(&mut v)
}

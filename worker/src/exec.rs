//! A job's executor: one thread that owns the job's database and its
//! breadth-first [`Tracer`] (grids built once per job), and runs the job's
//! tasks one after another. The engine is synchronous and uses its own
//! thread pool; the thread talks to the async side through channels, so
//! the network never waits on the tracer nor the tracer on the network,
//! beyond the few chunks the channels hold.

use sray_engine::bf::{BfOptions, Contribution, RayRec, ResultReader, ResultRec, Tracer, eye_ray};
use sray_engine::math::Real;
use sray_engine::progress::NoProgress;
use sray_engine::render::{Camera, EyeRays, Precision, RayCounts, RenderOptions};
use sray_engine::sdb::Database;
use sray_engine::spill::RecordWriter;
use sray_proto::v1::{self, RecordKind, task_output::Part};
use sray_proto::wire::{pack, records_per_chunk, unpack};
use std::path::PathBuf;
use std::time::Instant;
use tokio::sync::{mpsc, oneshot};

/// What a job's tasks share. `key` names the setup by content (the
/// scene's hash and a hash of the render settings), never by job id: two
/// jobs with the same key may share an executor, and a job id that a
/// restarted coordinator might issue again can never select another
/// scene's executor.
pub struct JobSetup {
    pub key: String,
    pub db_path: PathBuf,
    pub opts: RenderOptions,
    pub bf: BfOptions,
}

/// One task for the executor, with its input stream (if it has input), the
/// channel its output goes to, and where to say how it ended.
pub struct Work {
    pub task: v1::Task,
    pub input: Input,
    pub out: mpsc::Sender<v1::TaskOutput>,
    pub done: oneshot::Sender<Result<(), String>>,
}

/// A task's input records.
pub enum Input {
    /// None (eye rays, intersection).
    None,
    /// From the coordinator.
    Stream(tonic::Streaming<v1::RecordChunk>),
    /// Files already here (the coordinator tracing a sample itself).
    Files(Inputs),
}

pub struct Executor {
    pub key: String,
    tx: Option<std::sync::mpsc::Sender<Work>>,
    thread: Option<std::thread::JoinHandle<()>>,
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
        let (tx, rx) = std::sync::mpsc::channel::<Work>();
        let key = setup.key.clone();
        let thread = std::thread::Builder::new()
            .name(format!("setup-{}", &key[..key.len().min(8)]))
            .spawn(move || match setup.opts.precision {
                Precision::Double => job_thread::<f64>(setup, rt, rx),
                Precision::Single => job_thread::<f32>(setup, rt, rx),
            })
            .expect("cannot start a thread");
        Executor {
            key,
            tx: Some(tx),
            thread: Some(thread),
        }
    }

    /// Queues a task; false if the thread has ended.
    pub fn submit(&self, w: Work) -> bool {
        self.tx.as_ref().is_some_and(|tx| tx.send(w).is_ok())
    }
}

fn job_thread<R: Real>(
    setup: JobSetup,
    rt: tokio::runtime::Handle,
    rx: std::sync::mpsc::Receiver<Work>,
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
    for w in rx {
        let Work {
            task,
            input,
            out,
            done,
        } = w;
        let run = std::panic::AssertUnwindSafe(|| {
            run_task(&mut tracer, &eye, eye_rays, &rt, &task, input, &out)
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
        let _ = done.send(r);
    }
}

fn fail_all(rx: std::sync::mpsc::Receiver<Work>, e: &str) {
    for w in rx {
        let _ = w.done.send(Err(e.to_string()));
    }
}

/// Sends one output message from the executor thread.
fn send(out: &mpsc::Sender<v1::TaskOutput>, part: Part) -> Result<(), String> {
    out.blocking_send(v1::TaskOutput { part: Some(part) })
        .map_err(|_| "the output stream to the coordinator closed".to_string())
}

fn send_records<T: bytemuck::Pod>(
    out: &mpsc::Sender<v1::TaskOutput>,
    kind: RecordKind,
    recs: &[T],
) -> Result<(), String> {
    send(
        out,
        Part::Records(v1::RecordChunk {
            kind: kind as i32,
            data: pack(recs),
        }),
    )
}

/// A task's input records, in local files.
#[derive(Default)]
pub struct Inputs {
    pub rays: Option<sray_engine::spill::RecordFile<RayRec>>,
    pub results: Option<sray_engine::spill::RecordFile<ResultRec>>,
}

fn read_inputs<R: Real>(
    tracer: &Tracer<R>,
    rt: &tokio::runtime::Handle,
    input: Input,
) -> Result<Inputs, String> {
    let mut inputs = Inputs::default();
    let mut stream = match input {
        Input::None => return Ok(inputs),
        Input::Files(f) => return Ok(f),
        Input::Stream(s) => s,
    };
    let io = |e: sray_engine::Error| e.to_string();
    let mut rays: Option<RecordWriter<RayRec>> = None;
    let mut results: Option<RecordWriter<ResultRec>> = None;
    loop {
        let msg = rt
            .block_on(stream.message())
            .map_err(|s| format!("task input: {}", s.message()))?;
        let Some(chunk) = msg else { break };
        match RecordKind::try_from(chunk.kind) {
            Ok(RecordKind::Rays) => {
                let v = unpack::<RayRec>(&chunk.data).map_err(|e| e.to_string())?;
                if rays.is_none() {
                    rays = Some(RecordWriter::create(&tracer.spill, "in-rays").map_err(io)?);
                }
                rays.as_mut().expect("made").extend(&v).map_err(io)?;
            }
            Ok(RecordKind::Results) => {
                let v = unpack::<ResultRec>(&chunk.data).map_err(|e| e.to_string())?;
                if results.is_none() {
                    results = Some(RecordWriter::create(&tracer.spill, "in-results").map_err(io)?);
                }
                results.as_mut().expect("made").extend(&v).map_err(io)?;
            }
            _ => return Err(format!("task input: unexpected record kind {}", chunk.kind)),
        }
    }
    inputs.rays = rays.map(|w| w.finish()).transpose().map_err(io)?;
    inputs.results = results.map(|w| w.finish()).transpose().map_err(io)?;
    Ok(inputs)
}

fn run_task<R: Real>(
    tracer: &mut Tracer<R>,
    eye: &EyeRays,
    eye_rays: u64,
    rt: &tokio::runtime::Handle,
    task: &v1::Task,
    input: Input,
    out: &mpsc::Sender<v1::TaskOutput>,
) -> Result<(), String> {
    let t0 = Instant::now();
    let (first, n) = (task.first_ray, task.ray_count);
    if task.eye_rays && first.checked_add(n).is_none_or(|end| end > eye_rays) {
        return Err(format!(
            "eye rays {first}..{} are beyond the image's {eye_rays}",
            first.saturating_add(n)
        ));
    }
    let inputs = read_inputs(tracer, rt, input)?;
    let t_in = t0.elapsed().as_secs_f64();
    let io = |e: sray_engine::Error| e.to_string();
    // The shard's rays: made here for the eye rays, else as received.
    let ray_file = if task.eye_rays {
        None
    } else {
        let f = inputs.rays.as_ref().ok_or("task input: no rays")?;
        if f.len() != n {
            return Err(format!("task input: {} rays for a shard of {n}", f.len()));
        }
        Some(f)
    };
    let rays =
        || -> Result<Box<dyn Iterator<Item = Result<RayRec, sray_engine::Error>> + '_>, String> {
            Ok(match ray_file {
                None => Box::new((first..first + n).map(|i| Ok(eye_ray(eye, i)))),
                Some(f) => {
                    let mut rd = f.reader().map_err(io)?;
                    Box::new(std::iter::from_fn(move || rd.next().transpose()))
                }
            })
        };
    let mut summary = v1::TaskSummary::default();
    match v1::Stage::try_from(task.stage) {
        Ok(v1::Stage::Intersect) => {
            let (mut results, ist) = tracer
                .intersect(first, &mut *rays()?, n, false, &NoProgress)
                .map_err(io)?;
            let per = records_per_chunk::<ResultRec>();
            let mut buf = Vec::with_capacity(per);
            while let Some(r) = results.next_result().map_err(io)? {
                buf.push(r);
                if buf.len() == per {
                    send_records(out, RecordKind::Results, &buf)?;
                    buf.clear();
                }
            }
            if !buf.is_empty() {
                send_records(out, RecordKind::Results, &buf)?;
            }
            tracer.recycle(results);
            let t = ist.intersection_tests;
            summary.tests_by_kind = t.named().map(|(k, n)| (k.to_string(), n)).collect();
            summary.stats_json = serde_json::to_string(&ist).unwrap_or_default();
        }
        Ok(v1::Stage::Shade) => {
            let results_file = inputs.results.as_ref().ok_or("task input: no results")?;
            if results_file.len() != n {
                return Err(format!(
                    "task input: {} results for a shard of {n}",
                    results_file.len()
                ));
            }
            let mut results = ResultReader::File(results_file.reader().map_err(io)?);
            let per = records_per_chunk::<Contribution>();
            let mut buf: Vec<Contribution> = Vec::with_capacity(per);
            let mut send_err = None;
            let mut counts = RayCounts::default();
            let (mut next, _count, sst) = {
                let mut contribute = |corner: u32, rgb: [i64; 3]| {
                    if send_err.is_some() {
                        return;
                    }
                    buf.push(Contribution {
                        corner,
                        _pad: 0,
                        rgb,
                    });
                    if buf.len() == per {
                        if let Err(e) = send_records(out, RecordKind::Contributions, &buf) {
                            send_err = Some(e);
                        }
                        buf.clear();
                    }
                };
                tracer
                    .shade(
                        first,
                        &mut *rays()?,
                        &mut results,
                        &mut contribute,
                        &mut counts,
                    )
                    .map_err(io)?
            };
            if let Some(e) = send_err {
                return Err(e);
            }
            if !buf.is_empty() {
                send_records(out, RecordKind::Contributions, &buf)?;
            }
            let per = records_per_chunk::<RayRec>();
            let mut rbuf = Vec::with_capacity(per);
            while let Some(r) = next.next().map_err(io)? {
                rbuf.push(r);
                if rbuf.len() == per {
                    send_records(out, RecordKind::Rays, &rbuf)?;
                    rbuf.clear();
                }
            }
            if !rbuf.is_empty() {
                send_records(out, RecordKind::Rays, &rbuf)?;
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
    send(out, Part::Summary(summary))
}

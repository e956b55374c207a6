//! The worker's life: register with the coordinator, beat, take tasks one
//! at a time, fetch the scene when a job needs it, run the task on the
//! job's executor and stream the output back.

use crate::cache::SceneCache;
use crate::exec::{Executor, JobSetup, Work};
use crate::params::from_proto;
use anyhow::Context;
use sray_engine::bf::BfOptions;
use sray_proto::net::{Client, Target};
use sray_proto::v1::{self, task_output::Part};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;
use tokio::sync::{mpsc, oneshot};
use tokio_stream::wrappers::ReceiverStream;
use tonic::Code;

/// A worker's settings.
#[derive(Clone, Debug)]
pub struct WorkerConfig {
    pub target: Target,
    pub name: String,
    /// Tracer threads (0: all cores).
    pub threads: usize,
    /// Memory budget of the tracer, bytes.
    pub memory: u64,
    pub cache_dir: PathBuf,
    /// Where spilled rays go (default: the system's temp dir).
    pub tmp_dir: Option<PathBuf>,
}

/// Runs a worker until `shutdown` completes, or a fatal error (a refused
/// token, an unusable cache directory). A coordinator that is down or
/// restarts is waited for.
pub async fn run(
    cfg: WorkerConfig,
    shutdown: impl std::future::Future<Output = ()>,
) -> anyhow::Result<()> {
    let client = cfg.target.connect_lazy().map_err(anyhow::Error::msg)?;
    let cache = Arc::new(SceneCache::new(&cfg.cache_dir)?);
    let mut node = Node {
        cfg,
        client,
        cache,
        exec: None,
        running: Arc::new(AtomicU64::new(0)),
    };
    tokio::select! {
        r = node.serve() => r,
        _ = shutdown => {
            tracing::info!("worker stopping");
            Ok(())
        }
    }
}

struct Node {
    cfg: WorkerConfig,
    client: Client,
    cache: Arc<SceneCache>,
    exec: Option<Executor>,
    /// The task being run (0: none), for heartbeats.
    running: Arc<AtomicU64>,
}

/// How long to wait between attempts to reach the coordinator.
const RETRY: Duration = Duration::from_secs(1);

impl Node {
    async fn serve(&mut self) -> anyhow::Result<()> {
        loop {
            let (id, beat) = self.register().await?;
            let lost = Arc::new(AtomicBool::new(false));
            let hb = tokio::spawn(heartbeat(
                self.client.clone(),
                id,
                beat,
                self.running.clone(),
                lost.clone(),
            ));
            let r = self.take_tasks(id, &lost).await;
            hb.abort();
            r?;
            tracing::warn!(
                worker = id,
                "the coordinator no longer knows this worker: registering again"
            );
        }
    }

    /// Registers, waiting for the coordinator as long as it takes.
    async fn register(&mut self) -> anyhow::Result<(u64, Duration)> {
        let mut waited = false;
        loop {
            let req = v1::RegisterRequest {
                name: self.cfg.name.clone(),
                threads: self.cfg.threads as u32,
                memory_bytes: self.cfg.memory,
                protocol_version: sray_proto::PROTOCOL_VERSION,
            };
            match self.client.register(req).await {
                Ok(r) => {
                    let r = r.into_inner();
                    tracing::info!(worker = r.worker_id, url = %self.cfg.target.url, "registered");
                    return Ok((
                        r.worker_id,
                        Duration::from_millis(r.heartbeat_ms.clamp(100, 60_000) as u64),
                    ));
                }
                Err(s) if fatal(&s) => {
                    anyhow::bail!("the coordinator refused this worker: {}", s.message())
                }
                Err(s) => {
                    if !waited {
                        tracing::info!(url = %self.cfg.target.url, error = %s.message(), "waiting for the coordinator");
                        waited = true;
                    }
                    tokio::time::sleep(RETRY).await;
                }
            }
        }
    }

    async fn take_tasks(&mut self, id: u64, lost: &AtomicBool) -> anyhow::Result<()> {
        loop {
            if lost.load(Ordering::Relaxed) {
                return Ok(());
            }
            match self
                .client
                .next_task(v1::NextTaskRequest { worker_id: id })
                .await
            {
                Ok(r) => {
                    if let Some(task) = r.into_inner().task {
                        self.serve_task(id, task).await?;
                    }
                }
                Err(s) if s.code() == Code::NotFound => return Ok(()),
                Err(s) if fatal(&s) => {
                    anyhow::bail!("the coordinator refused this worker: {}", s.message())
                }
                Err(_) => tokio::time::sleep(RETRY).await,
            }
        }
    }

    /// Runs one task. Task failures are reported to the coordinator (which
    /// gives the task to another worker); only local faults that would
    /// fail every task end the worker.
    async fn serve_task(&mut self, worker: u64, task: v1::Task) -> anyhow::Result<()> {
        let tref = v1::TaskRef {
            worker_id: worker,
            task_id: task.task_id,
            attempt: task.attempt,
        };
        self.running.store(task.task_id, Ordering::Relaxed);
        let r = self.try_task(&tref, task).await;
        self.running.store(0, Ordering::Relaxed);
        if let Err(e) = r {
            let msg = format!("{e:#}");
            tracing::warn!(task = tref.task_id, error = %msg, "task failed");
            let _ = self
                .client
                .fail_task(v1::FailTaskRequest {
                    task: Some(tref),
                    error: msg,
                })
                .await;
        }
        Ok(())
    }

    async fn try_task(&mut self, tref: &v1::TaskRef, task: v1::Task) -> anyhow::Result<()> {
        if self.exec.as_ref().map(|e| e.job_id) != Some(task.job_id) {
            // A new job: check (and repair) the cached scene once, then
            // build the job's grids on its own executor.
            self.exec = None;
            let hash = task
                .scene
                .as_ref()
                .map(|s| s.hash.clone())
                .unwrap_or_default();
            let path = self.cache.ensure(&mut self.client, &hash).await?;
            let params = task
                .params
                .as_ref()
                .context("task without render settings")?;
            let (opts, store) = from_proto(params, self.cfg.threads).map_err(anyhow::Error::msg)?;
            self.exec = Some(Executor::start(
                JobSetup {
                    job_id: task.job_id,
                    db_path: path,
                    opts,
                    bf: BfOptions {
                        // Results travel to the coordinator without the
                        // surfaces the carry mode would work out.
                        shading: sray_engine::bf::Shading::Join,
                        memory: self.cfg.memory,
                        store,
                        spill_dir: self.cfg.tmp_dir.clone(),
                    },
                },
                tokio::runtime::Handle::current(),
            ));
        }
        let shade = task.stage == v1::Stage::Shade as i32;
        let input = if shade || !task.eye_rays {
            Some(self.client.task_input(*tref).await?.into_inner())
        } else {
            None
        };
        // The output stream: our sender stays alive until the outcome is
        // known, so that a failure is reported before the stream ends.
        let (out, rx) = mpsc::channel::<v1::TaskOutput>(4);
        out.send(v1::TaskOutput {
            part: Some(Part::Header(*tref)),
        })
        .await
        .ok();
        let mut client = self.client.clone();
        let call = tokio::spawn(async move { client.complete_task(ReceiverStream::new(rx)).await });
        let (done, outcome) = oneshot::channel();
        let work = Work {
            task,
            input,
            out: out.clone(),
            done,
        };
        if !self.exec.as_ref().context("no executor")?.submit(work) {
            self.exec = None;
            anyhow::bail!("the job's executor has stopped");
        }
        let r = outcome
            .await
            .unwrap_or_else(|_| Err("the job's executor stopped".into()));
        match r {
            Ok(()) => {
                drop(out);
                let reply = call.await.context("output stream")?;
                let accepted = reply
                    .map(|r| r.into_inner().accepted)
                    .map_err(|s| anyhow::anyhow!("output stream: {}", s.message()))?;
                if !accepted {
                    tracing::info!(
                        task = tref.task_id,
                        "output not needed any more (the task was done elsewhere)"
                    );
                }
                Ok(())
            }
            Err(e) => {
                // Report first; then end the output stream unfinished.
                let _ = self
                    .client
                    .fail_task(v1::FailTaskRequest {
                        task: Some(*tref),
                        error: e.clone(),
                    })
                    .await;
                drop(out);
                call.abort();
                tracing::warn!(task = tref.task_id, error = %e, "task failed");
                Ok(())
            }
        }
    }
}

/// Errors no retry will cure.
fn fatal(s: &tonic::Status) -> bool {
    matches!(
        s.code(),
        Code::Unauthenticated | Code::PermissionDenied | Code::FailedPrecondition
    )
}

async fn heartbeat(
    mut client: Client,
    id: u64,
    every: Duration,
    running: Arc<AtomicU64>,
    lost: Arc<AtomicBool>,
) {
    let mut tick = tokio::time::interval(every);
    loop {
        tick.tick().await;
        let t = running.load(Ordering::Relaxed);
        let req = v1::HeartbeatRequest {
            worker_id: id,
            running_tasks: if t == 0 { vec![] } else { vec![t] },
        };
        if let Ok(r) = client.heartbeat(req).await
            && !r.into_inner().known
        {
            lost.store(true, Ordering::Relaxed);
            return;
        }
    }
}

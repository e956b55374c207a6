//! The worker's life: register with the coordinator, beat, take tasks one
//! at a time, fetch the scene when a job needs it, run the task on the
//! job's executor and stream the output back.

use crate::cache::SceneCache;
use crate::exec::{Executor, Input, JobSetup, KEPT_MEMORY_PART, Work};
use crate::params::from_proto;
use crate::tmp::TmpDir;
use anyhow::Context;
use sray_engine::bf::BfOptions;
use sray_engine::spill::MemoryShare;
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
    /// Bytes of scenes kept in the cache; least recently used go first.
    pub cache_max: u64,
    /// Directories shared with others that hold databases as `HASH.sdb`
    /// (a mount of the coordinator's data directory): chunks are read
    /// from there, verified, before the coordinator is asked.
    pub scene_dirs: Vec<PathBuf>,
    /// Where spilled rays go (default: the system's temp dir).
    pub tmp_dir: Option<PathBuf>,
    /// Send records as they lie in memory, not encoded (a coordinator on
    /// this machine).
    pub raw_records: bool,
    /// A fault to play, for the tests of the coordinator's defences
    /// (`sray worker --fault`, hidden): never set in use.
    pub fault: Option<Fault>,
}

/// A fault a worker plays for the tests (see [`WorkerConfig::fault`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// Sends plausible wrong colours: every shading contribution's
    /// channels rotated and its red halved. Its records (results and
    /// spawned rays) are right.
    Lie,
    /// Reports a wrong digest of the records it keeps (as a worker
    /// whose kept records went bad would); what it sends is right.
    WrongDigest,
    /// Takes the tasks of round `N` on (of a job, not of a
    /// recomputation or a verification, whose ids have a dot) and never
    /// answers them, beating all the while.
    StallFromRound(u32),
}

impl std::str::FromStr for Fault {
    type Err = String;
    fn from_str(s: &str) -> Result<Fault, String> {
        match s.split_once('=') {
            None if s == "lie" => Ok(Fault::Lie),
            None if s == "wrong-digest" => Ok(Fault::WrongDigest),
            Some(("stall-from-round", n)) => n
                .parse()
                .map(Fault::StallFromRound)
                .map_err(|e| format!("{s}: {e}")),
            _ => Err(format!(
                "{s}: a fault is `lie`, `wrong-digest` or `stall-from-round=N`"
            )),
        }
    }
}

/// An output made wrong as `fault` says: a shading's contributions
/// ([`Fault::Lie`]), or the digest of what it keeps
/// ([`Fault::WrongDigest`]).
fn lie(fault: Option<Fault>, m: v1::TaskOutput) -> v1::TaskOutput {
    use sray_engine::bf::Contribution;
    use sray_proto::wire::{decode_chunk, encode, records_per_chunk};
    if fault == Some(Fault::WrongDigest)
        && let Some(Part::Summary(mut s)) = m.part
    {
        if let Some(b) = s.kept_digest.first_mut() {
            *b ^= 1;
        }
        return v1::TaskOutput {
            part: Some(Part::Summary(s)),
        };
    }
    if fault != Some(Fault::Lie) {
        return m;
    }
    let Some(Part::Records(mut c)) = m.part else {
        return m;
    };
    if c.kind == v1::RecordKind::Contributions as i32
        && let Ok(mut v) =
            decode_chunk::<Contribution>(&c.data, c.raw, records_per_chunk::<Contribution>())
    {
        for x in &mut v {
            x.rgb = [x.rgb[1] / 2, x.rgb[2], x.rgb[0]];
        }
        c.data = encode(&v);
        c.raw = false;
    }
    if c.kind == v1::RecordKind::Colour as i32
        && let Ok(bytes) =
            sray_proto::wire::decode_bytes(&c.data, c.raw, sray_proto::colour::MAX_CHUNK_BYTES)
        && let Ok(mut v) = sray_proto::colour::unpack(&bytes, usize::MAX)
    {
        for x in &mut v {
            x.rgb = [x.rgb[1] / 2, x.rgb[2], x.rgb[0]];
        }
        c.data = encode(&sray_proto::colour::pack(&mut v));
        c.raw = false;
    }
    v1::TaskOutput {
        part: Some(Part::Records(c)),
    }
}

/// Runs a worker until `shutdown` completes, or a fatal error (a refused
/// token, an unusable cache directory). A coordinator that is down or
/// restarts is waited for.
pub async fn run(
    cfg: WorkerConfig,
    shutdown: impl std::future::Future<Output = ()>,
) -> anyhow::Result<()> {
    let client = cfg.target.connect_lazy().map_err(anyhow::Error::msg)?;
    let cfg_memory = cfg.memory;
    let cache = Arc::new(SceneCache::with_shared(
        &cfg.cache_dir,
        cfg.cache_max,
        cfg.scene_dirs.clone(),
    )?);
    // This worker's spill directory (a killed predecessor's are removed).
    let tmp = TmpDir::claim(cfg.tmp_dir.as_deref())?;
    let now = Now::default();
    let mut node = Node {
        cfg,
        client: client.clone(),
        cache,
        execs: Vec::new(),
        running: Arc::new(AtomicU64::new(0)),
        jobs_running: JobsRunning::default(),
        kept_memory: MemoryShare::new(cfg_memory / KEPT_MEMORY_PART),
        spill: tmp.path().to_path_buf(),
        now: now.clone(),
    };
    let r = tokio::select! {
        r = node.serve() => r,
        _ = shutdown => {
            tracing::info!("worker stopping: its task goes back to the coordinator");
            leave(client, &now).await;
            Ok(())
        }
    };
    // The executors end once their task does (a tracer cannot be stopped
    // midway): they are given a few seconds, then the process goes on
    // to exit (a spill file left is removed by the next worker here).
    let ended = tokio::task::spawn_blocking(move || drop(node));
    let _ = tokio::time::timeout(Duration::from_secs(5), ended).await;
    drop(tmp);
    r
}

/// The session and the task of a worker now, for leaving when it stops.
#[derive(Clone, Default)]
struct Now(Arc<std::sync::Mutex<(Option<String>, Option<v1::TaskRef>)>>);

impl Now {
    fn set_session(&self, s: Option<String>) {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).0 = s;
    }
    fn set_task(&self, t: Option<v1::TaskRef>) {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).1 = t;
    }
    fn get(&self) -> (Option<String>, Option<v1::TaskRef>) {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }
}

/// Hands the task at hand back and leaves the cluster, so that the
/// coordinator gives its work to others now rather than once its
/// heartbeats stop (each call given at most two seconds).
async fn leave(mut client: Client, now: &Now) {
    let (session, task) = now.get();
    let wait = Duration::from_secs(2);
    if let Some(t) = task {
        let req = v1::FailTaskRequest {
            task: Some(t),
            error: "the worker is stopping".into(),
            kind: v1::FailureKind::HandedBack as i32,
        };
        let _ = tokio::time::timeout(wait, client.fail_task(req)).await;
    }
    if let Some(session) = session {
        let _ = tokio::time::timeout(wait, client.leave(v1::LeaveRequest { session })).await;
    }
}

/// What a task's failure costs this worker: nothing when it lacked room
/// (a full disk or file-size limit), which freeing space cures.
fn failure_kind(error: &str) -> v1::FailureKind {
    if sray_engine::spill::is_no_room(error) {
        v1::FailureKind::NoRoom
    } else {
        v1::FailureKind::Task
    }
}

struct Node {
    cfg: WorkerConfig,
    client: Client,
    cache: Arc<SceneCache>,
    /// Executors of recent setups (scene and settings), least recently
    /// used first: a worker that alternates between the tasks of
    /// concurrent jobs keeps their grids instead of building them again.
    execs: Vec<Executor>,
    /// The task being run (0: none), for heartbeats.
    running: Arc<AtomicU64>,
    /// The jobs running, as the last heartbeat's answer said, and when it
    /// was asked (taken by the task loop to the executors).
    jobs_running: JobsRunning,
    /// The part of `--memory` that the executors' kept and received
    /// records may hold in memory (the tracers get the rest).
    kept_memory: MemoryShare,
    /// This worker's spill directory.
    spill: PathBuf,
    /// The session and task at hand (for leaving).
    now: Now,
}

/// Setups whose executors (grids, kept records) a worker keeps at once.
const SETUPS_KEPT: usize = 2;

/// How long to wait between attempts to reach the coordinator, about.
const RETRY: Duration = Duration::from_secs(1);

/// [`RETRY`] give or take half of it, so that a cluster's workers,
/// started together or lost together when the coordinator restarts, do
/// not all knock at once (a thousand at once overflow its accept queue).
fn retry_wait() -> Duration {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos() as u64)
        ^ std::process::id() as u64;
    RETRY / 2 + Duration::from_millis(nanos % RETRY.as_millis() as u64)
}

impl Node {
    async fn serve(&mut self) -> anyhow::Result<()> {
        loop {
            let (session, beat) = self.register().await?;
            self.now.set_session(Some(session.clone()));
            let lost = Arc::new(AtomicBool::new(false));
            let hb = tokio::spawn(heartbeat(
                self.client.clone(),
                session.clone(),
                beat,
                self.running.clone(),
                lost.clone(),
                self.jobs_running.clone(),
            ));
            let r = self.take_tasks(&session, &lost).await;
            hb.abort();
            r?;
            tracing::warn!("the coordinator no longer knows this worker: registering again");
        }
    }

    /// Registers, waiting for the coordinator as long as it takes.
    async fn register(&mut self) -> anyhow::Result<(String, Duration)> {
        let mut waited = false;
        loop {
            let req = v1::RegisterRequest {
                name: self.cfg.name.clone(),
                // The threads it traces with: "all cores" (0) as a number,
                // so that `sray status` and the dashboard show it.
                threads: reported_threads(self.cfg.threads),
                memory_bytes: self.cfg.memory,
                protocol_version: sray_proto::PROTOCOL_VERSION,
            };
            match self.client.register(req).await {
                Ok(r) => {
                    let r = r.into_inner();
                    tracing::info!(run = %r.run_id, url = %self.cfg.target.url, "registered");
                    return Ok((
                        r.session,
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
                    tokio::time::sleep(retry_wait()).await;
                }
            }
        }
    }

    async fn take_tasks(&mut self, session: &str, lost: &AtomicBool) -> anyhow::Result<()> {
        // The next task, when the last output's reply brought one.
        let mut given: Option<v1::NextTaskReply> = None;
        loop {
            if lost.load(Ordering::Relaxed) {
                return Ok(());
            }
            let answer = self
                .jobs_running
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .take();
            if let Some((asked, jobs)) = answer {
                for e in &self.execs {
                    e.jobs_running(jobs.clone(), asked);
                }
            }
            let reply = match given.take() {
                Some(r) => r,
                None => match self.client.next_task(self.next_request(session)).await {
                    Ok(r) => r.into_inner(),
                    Err(s) if s.code() == Code::NotFound => return Ok(()),
                    Err(s) if fatal(&s) => {
                        anyhow::bail!("the coordinator refused this worker: {}", s.message())
                    }
                    Err(_) => {
                        tokio::time::sleep(retry_wait()).await;
                        continue;
                    }
                },
            };
            if let Some(task) = reply.task {
                let input = reply.input_inline.then_some(reply.input);
                given = self
                    .serve_task(session, task, input)
                    .await?
                    .filter(|r| r.task.is_some());
            }
        }
    }

    /// A request for this worker's next task, naming the records its
    /// executors keep (a task whose input is all here comes with it).
    fn next_request(&self, session: &str) -> v1::NextTaskRequest {
        v1::NextTaskRequest {
            session: session.to_string(),
            held: self.execs.iter().flat_map(|e| e.held()).collect(),
        }
    }

    /// Runs one task (`input`: its input, when it came with it). Task
    /// failures are reported to the coordinator (which gives the task to
    /// another worker); only local faults that would fail every task end
    /// the worker. Returns the next task when the output's reply brought
    /// one.
    async fn serve_task(
        &mut self,
        session: &str,
        task: v1::Task,
        input: Option<Vec<v1::RecordChunk>>,
    ) -> anyhow::Result<Option<v1::NextTaskReply>> {
        let tref = v1::TaskRef {
            session: session.to_string(),
            task_id: task.task_id,
            attempt: task.attempt,
            held: Vec::new(),
        };
        self.running.store(task.task_id, Ordering::Relaxed);
        self.now.set_task(Some(tref.clone()));
        let r = self.try_task(&tref, task, input).await;
        self.now.set_task(None);
        self.running.store(0, Ordering::Relaxed);
        match r {
            Ok(next) => Ok(next),
            Err(e) => {
                let msg = format!("{e:#}");
                tracing::warn!(task = tref.task_id, error = %msg, "task failed");
                let _ = self
                    .client
                    .fail_task(v1::FailTaskRequest {
                        task: Some(tref.clone()),
                        kind: failure_kind(&msg) as i32,
                        error: msg,
                    })
                    .await;
                Ok(None)
            }
        }
    }

    async fn try_task(
        &mut self,
        tref: &v1::TaskRef,
        task: v1::Task,
        inline: Option<Vec<v1::RecordChunk>>,
    ) -> anyhow::Result<Option<v1::NextTaskReply>> {
        if let Some(Fault::StallFromRound(n)) = self.cfg.fault
            && task.round >= n
            && !task.job_id.contains('.')
        {
            tracing::warn!(
                task = tref.task_id,
                round = task.round,
                "fault: this task is never answered"
            );
            std::future::pending::<()>().await;
        }
        let hash = task
            .scene
            .as_ref()
            .map(|s| s.hash.clone())
            .unwrap_or_default();
        let params = task
            .params
            .as_ref()
            .context("task without render settings")?;
        let key = setup_key(&hash, params);
        let mut fresh = false;
        if let Some(i) = self.execs.iter().position(|e| e.key == key) {
            let e = self.execs.remove(i);
            let new_job = !e.jobs.contains(&task.job_id);
            self.execs.push(e);
            if new_job {
                // A job's first task checks (and repairs) the cached
                // scene, as a new setup's does; a repaired scene ends the
                // setups that have it open.
                let (_, written) = self.cache.check(&mut self.client, &hash, false).await?;
                if written {
                    self.execs.retain(|e| e.scene != hash);
                }
            }
        }
        if !self.execs.iter().any(|e| e.key == key) {
            // A new setup (scene or settings): check (and repair) the
            // cached scene once, then build the grids on an executor of
            // its own. The setup is named by content, never by job id.
            // The least recently used setup goes when too many are kept.
            while self.execs.len() >= SETUPS_KEPT {
                // The least recently used that keeps no records found
                // nowhere else, if there is one.
                let i = self.execs.iter().position(|e| !e.holds_pins()).unwrap_or(0);
                self.execs.remove(i);
            }
            fresh = true;
            // A scene another kept setup has open is checked without
            // marking it used (which an open database takes for a
            // change); if it had to be repaired, those setups end.
            let path = if self.execs.iter().any(|e| e.scene == hash) {
                let (path, written) = self.cache.check(&mut self.client, &hash, false).await?;
                if written {
                    self.execs.retain(|e| e.scene != hash);
                }
                path
            } else {
                self.cache.ensure(&mut self.client, &hash).await?
            };
            let (opts, store) = from_proto(params, self.cfg.threads).map_err(anyhow::Error::msg)?;
            self.execs.push(Executor::start(
                JobSetup {
                    key,
                    scene: hash.clone(),
                    db_path: path,
                    opts,
                    bf: BfOptions {
                        // The tracer finds each hit's surface with it: the
                        // results stay here with them, and a shading of
                        // kept results needs no pass over the objects.
                        // Results that come from elsewhere (bare, as they
                        // travel) are joined with the objects.
                        shading: sray_engine::bf::Shading::Carry,
                        models: Default::default(),
                        memory: self.cfg.memory - self.kept_memory.cap(),
                        store,
                        spill_dir: Some(self.spill.clone()),
                    },
                    keep: true,
                    kept_memory: self.kept_memory.clone(),
                    raw_records: self.cfg.raw_records,
                },
                tokio::runtime::Handle::current(),
            ));
        }
        let exec = self.execs.last_mut().context("no executor")?;
        exec.jobs.insert(task.job_id.clone());
        let exec = &*exec;
        let shade = task.stage == v1::Stage::Shade as i32;
        let input = match inline {
            _ if !shade && task.eye_rays => Input::None,
            Some(chunks) => Input::Chunks(chunks),
            None => {
                let mut r = tref.clone();
                r.held = exec.held();
                Input::Stream(self.client.task_input(r).await?.into_inner())
            }
        };
        // The output stream: our sender stays alive until the outcome is
        // known, so that a failure is reported before the stream ends.
        let (out, rx) = mpsc::channel::<v1::TaskOutput>(4);
        out.send(v1::TaskOutput {
            part: Some(Part::Header(tref.clone())),
        })
        .await
        .ok();
        let mut client = self.client.clone();
        let fault = self.cfg.fault;
        let call = tokio::spawn(async move {
            use tokio_stream::StreamExt;
            let stream = ReceiverStream::new(rx).map(move |m| lie(fault, m));
            client.complete_task(stream).await
        });
        let (done, outcome) = oneshot::channel();
        // The request for the next task, which the executor completes
        // with the records it keeps once this task's are among them.
        let (_, others) = self.execs.split_last().context("no executor")?;
        let next = Some(v1::NextTaskRequest {
            session: tref.session.clone(),
            held: others.iter().flat_map(|e| e.held()).collect(),
        });
        let work = Work {
            task,
            input,
            out: out.clone(),
            done,
            fresh,
            next,
        };
        // Only the setup at work holds more than its grids: the others give
        // their buffers back, so that kept setups stay within --memory
        // beside it (they keep their grids, a small part of a budget).
        if let Some((_, idle)) = self.execs.split_last() {
            for e in idle {
                e.trim();
            }
        }
        if !self.execs.last().context("no executor")?.submit(work) {
            self.execs.pop();
            anyhow::bail!("the job's executor has stopped");
        }
        let r = outcome
            .await
            .unwrap_or_else(|_| Err("the job's executor stopped".into()));
        match r {
            Ok(()) => {
                drop(out);
                let reply = call.await.context("output stream")?;
                let reply = reply
                    .map(|r| r.into_inner())
                    .map_err(|s| anyhow::anyhow!("output stream: {}", s.message()))?;
                if !reply.accepted {
                    tracing::info!(
                        task = tref.task_id,
                        "output not needed any more (the task was done elsewhere)"
                    );
                }
                Ok(reply.next)
            }
            Err(e) => {
                // Report first; then end the output stream unfinished.
                let _ = self
                    .client
                    .fail_task(v1::FailTaskRequest {
                        task: Some(tref.clone()),
                        kind: failure_kind(&e) as i32,
                        error: e.clone(),
                    })
                    .await;
                drop(out);
                call.abort();
                tracing::warn!(task = tref.task_id, error = %e, "task failed");
                Ok(None)
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

/// What a worker's executor is keyed by: the scene's content hash and a
/// hash of the render settings (their protobuf encoding, which is
/// deterministic for these scalar fields).
pub fn setup_key(scene: &str, params: &v1::RenderParams) -> String {
    use prost::Message;
    let mut h = blake3::Hasher::new();
    h.update(scene.as_bytes());
    h.update(b"\0");
    h.update(&params.encode_to_vec());
    h.finalize().to_hex().to_string()
}

/// The jobs running and when the coordinator was asked, once answered.
type JobsRunning = Arc<std::sync::Mutex<Option<(std::time::Instant, Vec<String>)>>>;

async fn heartbeat(
    mut client: Client,
    session: String,
    every: Duration,
    running: Arc<AtomicU64>,
    lost: Arc<AtomicBool>,
    jobs: JobsRunning,
) {
    let mut tick = tokio::time::interval(every);
    loop {
        tick.tick().await;
        let t = running.load(Ordering::Relaxed);
        let req = v1::HeartbeatRequest {
            session: session.clone(),
            running_tasks: if t == 0 { vec![] } else { vec![t] },
        };
        let asked = std::time::Instant::now();
        if let Ok(r) = client.heartbeat(req).await {
            let r = r.into_inner();
            if !r.known {
                lost.store(true, Ordering::Relaxed);
                return;
            }
            *jobs.lock().unwrap_or_else(|p| p.into_inner()) = Some((asked, r.running_jobs));
        }
    }
}

/// The tracer threads a worker configured with `threads` (0: all cores)
/// uses, as it reports them to the coordinator.
fn reported_threads(threads: usize) -> u32 {
    let n = if threads == 0 {
        sray_engine::sys::cpus()
    } else {
        threads
    };
    u32::try_from(n).unwrap_or(u32::MAX)
}

#[cfg(test)]
mod tests {
    use super::reported_threads;

    /// `sray status` shows the threads a worker traces with, never 0.
    #[test]
    fn all_cores_are_reported_as_their_number() {
        assert_eq!(reported_threads(0), sray_engine::sys::cpus() as u32);
        assert!(reported_threads(0) >= 1);
        assert_eq!(reported_threads(3), 3);
    }
}

//! The coordinator's gRPC service: the calls of `sray.proto`, on top of
//! [`Shared`]. Every call is checked for its role (worker or client);
//! workers act under their session secret, clients under their job's
//! secret. Every record a worker sends is checked before it is kept
//! ([`crate::task_output`]); a task's input is sent as
//! [`crate::task_input`] says.

use crate::driver;
use crate::jobs::{JobEntry, JobRefusal, JobState};
use crate::state::{Refusal, Shared};
use crate::task_input;
use crate::task_output::{OutputError, Receiver};
use sray_proto::auth::{Role, require};
use sray_proto::v1::{self, coordinator_server::Coordinator, task_output::Part};
use sray_proto::wire::SCENE_CHUNK_BYTES;
use std::io::Write;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tokio::sync::mpsc;
use tokio_stream::Stream;
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status, Streaming};

/// How long a worker's `NextTask` waits for work before answering "none".
const POLL: Duration = Duration::from_secs(10);

/// How long an output's stream is read past its summary for the
/// worker's request for its next task (sent right after it, or never by a
/// worker that calls `NextTask` instead).
const NEXT_ASKED: Duration = Duration::from_secs(5);

/// What clients are told while the coordinator stops.
pub const RESTARTING: &str = "coordinator restarting";

pub struct Service {
    pub shared: Arc<Shared>,
}

type Stream_<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send>>;

fn refused(r: Refusal) -> Status {
    match r {
        Refusal::UnknownWorker => Status::not_found("unknown worker session: register again"),
        Refusal::NotYours => Status::aborted("the task is not (or no longer) this worker's"),
        Refusal::Stopping => Status::unavailable(RESTARTING),
    }
}

fn internal(e: impl std::fmt::Display) -> Status {
    Status::internal(e.to_string())
}

impl Service {
    /// `NextTask`'s answer for the worker `session`, which keeps the
    /// outputs of the tasks `held`: its next task, waiting up to [`POLL`]
    /// for one, with the task's input when all of it is held there.
    /// `with_output`: asked at the end of the worker's previous output.
    async fn next_reply(
        &self,
        session: &str,
        held: &[u64],
        with_output: bool,
    ) -> Result<v1::NextTaskReply, Status> {
        let next = self
            .shared
            .next_task(session, POLL)
            .await
            .map_err(refused)?;
        let Some((task, input)) = next else {
            return Ok(v1::NextTaskReply::default());
        };
        tracing::debug!(
            worker = %self.shared.worker_name(session),
            job = %task.job_id,
            task = task.task_id,
            attempt = task.attempt,
            stage = task.stage,
            round = task.round,
            verification = task.verification,
            "task assigned"
        );
        let c = &self.shared.counters;
        let given = if with_output {
            &c.given_with_output
        } else {
            &c.given_on_request
        };
        given.fetch_add(1, Ordering::Relaxed);
        let inline = task_input::inline(&task, &input, session, held);
        let input_inline = inline.is_some();
        if input_inline {
            c.inputs_inline.fetch_add(1, Ordering::Relaxed);
        }
        let input = inline.unwrap_or_default();
        let bytes: usize = input.iter().map(prost::Message::encoded_len).sum();
        self.shared
            .traffic
            .to_workers
            .fetch_add(bytes as u64, Ordering::Relaxed);
        Ok(v1::NextTaskReply {
            task: Some(task),
            input,
            input_inline,
        })
    }

    /// An output not taken: a bad one fails the attempt (the worker's
    /// fault); one the coordinator could not keep (its own disk) ends it
    /// without blame, and the task waits a moment.
    fn refuse_output(&self, tref: &v1::TaskRef, e: OutputError) -> Status {
        match e {
            OutputError::Bad(e) => {
                self.shared
                    .fail(tref, format!("bad output: {e}"), v1::FailureKind::Task);
                Status::invalid_argument(e)
            }
            OutputError::Local(e) => {
                self.shared.local_fault(tref, &e);
                Status::unavailable(format!("the coordinator cannot keep the output: {e}"))
            }
        }
    }

    fn job(&self, r: &v1::JobRef, method: &str) -> Result<Arc<JobEntry>, Status> {
        match self.shared.jobs.get(&r.job_id, &r.job_secret) {
            Ok(e) => Ok(e),
            Err(JobRefusal::NoSuchJob) => Err(Status::not_found(format!(
                "no job {} here (finished jobs are kept {} s)",
                r.job_id.chars().take(64).collect::<String>(),
                self.shared.cfg.job_retention.as_secs()
            ))),
            Err(JobRefusal::WrongSecret) => {
                tracing::warn!(job = %r.job_id, method, "refused a call: wrong job secret");
                Err(Status::permission_denied(
                    "wrong job secret: only the job's submitter may do this",
                ))
            }
        }
    }
}

#[tonic::async_trait]
impl Coordinator for Service {
    async fn register(
        &self,
        req: Request<v1::RegisterRequest>,
    ) -> Result<Response<v1::RegisterReply>, Status> {
        require(&req, Role::Worker, "Register")?;
        if self.shared.is_stopping() {
            return Err(Status::unavailable(RESTARTING));
        }
        let address = req
            .remote_addr()
            .map_or_else(String::new, |a| a.to_string());
        let r = req.into_inner();
        if r.protocol_version != sray_proto::PROTOCOL_VERSION {
            return Err(Status::failed_precondition(format!(
                "protocol version {} (this coordinator speaks {}): run the same sray version everywhere",
                r.protocol_version,
                sray_proto::PROTOCOL_VERSION
            )));
        }
        let name: String = r.name.chars().take(128).collect();
        let floor = self.shared.cfg.min_worker_memory;
        if r.memory_bytes < floor {
            tracing::warn!(name = %name, memory = r.memory_bytes, "worker refused: too little memory");
            return Err(Status::failed_precondition(format!(
                "--memory {} is below this coordinator's floor of {} bytes ({} MiB): give the worker more memory",
                r.memory_bytes,
                floor,
                floor >> 20
            )));
        }
        let (session, id) =
            self.shared
                .register(name.clone(), address.clone(), r.threads, r.memory_bytes);
        tracing::info!(worker = %name, id = %id, address = %address, threads = r.threads, memory = r.memory_bytes, "worker registered");
        Ok(Response::new(v1::RegisterReply {
            session,
            run_id: self.shared.run_id.clone(),
            heartbeat_ms: self.shared.cfg.heartbeat.as_millis() as u32,
        }))
    }

    async fn heartbeat(
        &self,
        req: Request<v1::HeartbeatRequest>,
    ) -> Result<Response<v1::HeartbeatReply>, Status> {
        require(&req, Role::Worker, "Heartbeat")?;
        let known = self.shared.beat(&req.into_inner().session);
        let running_jobs = if known {
            let mut ids: Vec<String> = self
                .shared
                .jobs
                .running()
                .iter()
                .map(|e| e.id.clone())
                .collect();
            // A recomputation's records are kept under an id of its own.
            ids.extend(self.shared.aliases_of(&ids));
            ids
        } else {
            Vec::new()
        };
        Ok(Response::new(v1::HeartbeatReply {
            known,
            running_jobs,
        }))
    }

    async fn next_task(
        &self,
        req: Request<v1::NextTaskRequest>,
    ) -> Result<Response<v1::NextTaskReply>, Status> {
        require(&req, Role::Worker, "NextTask")?;
        let r = req.into_inner();
        Ok(Response::new(
            self.next_reply(&r.session, &r.held, false).await?,
        ))
    }

    type TaskInputStream = Stream_<v1::RecordChunk>;

    async fn task_input(
        &self,
        req: Request<v1::TaskRef>,
    ) -> Result<Response<Self::TaskInputStream>, Status> {
        require(&req, Role::Worker, "TaskInput")?;
        let (task, input) = self.shared.task_input(req.get_ref()).map_err(refused)?;
        self.shared
            .counters
            .inputs_streamed
            .fetch_add(1, Ordering::Relaxed);
        let r = req.into_inner();
        let (session, held) = (r.session, r.held);
        let (tx, rx) = mpsc::channel(4);
        let shared = self.shared.clone();
        tokio::task::spawn_blocking(move || {
            task_input::send(&shared, &task, &input, &session, &held, &tx)
        });
        Ok(Response::new(Box::pin(ReceiverStream::new(rx))))
    }

    async fn complete_task(
        &self,
        req: Request<Streaming<v1::TaskOutput>>,
    ) -> Result<Response<v1::CompleteTaskReply>, Status> {
        require(&req, Role::Worker, "CompleteTask")?;
        let mut stream = req.into_inner();
        let Some(Part::Header(tref)) = stream.message().await?.and_then(|m| m.part) else {
            return Err(Status::invalid_argument(
                "a task's output starts with its header",
            ));
        };
        let Ok((task, input)) = self.shared.task_input(&tref) else {
            return Ok(Response::new(v1::CompleteTaskReply {
                accepted: false,
                next: None,
            }));
        };
        let t0 = std::time::Instant::now();
        let mut rx = Receiver::new(&self.shared, &task, &input);
        loop {
            let msg = match stream.message().await {
                Ok(Some(m)) => m,
                Ok(None) => {
                    self.shared
                        .abandon(&tref, "the output ended without a summary");
                    return Err(Status::invalid_argument("output ended without a summary"));
                }
                Err(s) => {
                    self.shared.abandon(&tref, "the output stream broke");
                    return Err(s);
                }
            };
            match msg.part {
                Some(Part::Records(c)) => {
                    self.shared
                        .traffic
                        .from_workers
                        .fetch_add(prost::Message::encoded_len(&c) as u64, Ordering::Relaxed);
                    if let Err(e) = rx.take(c) {
                        return Err(self.refuse_output(&tref, e));
                    }
                }
                Some(Part::Summary(s)) => {
                    let out = match rx.finish(s) {
                        Ok(o) => o,
                        Err(e) => return Err(self.refuse_output(&tref, e)),
                    };
                    let accepted = self.shared.complete(&tref, out);
                    tracing::debug!(
                        task = tref.task_id,
                        accepted,
                        seconds = t0.elapsed().as_secs_f64(),
                        "output received"
                    );
                    // A worker that asks for its next task here (after the
                    // summary, as its last message) is answered with it; a
                    // refusal is left to its next NextTask call to say.
                    let next = match tokio::time::timeout(NEXT_ASKED, stream.message()).await {
                        Ok(Ok(Some(v1::TaskOutput {
                            part: Some(Part::Next(n)),
                        }))) => self.next_reply(&tref.session, &n.held, true).await.ok(),
                        _ => None,
                    };
                    return Ok(Response::new(v1::CompleteTaskReply { accepted, next }));
                }
                Some(Part::Next(_)) => {
                    return Err(Status::invalid_argument(
                        "a request for the next task before the output's summary",
                    ));
                }
                _ => return Err(Status::invalid_argument("a second header")),
            }
        }
    }

    async fn fail_task(
        &self,
        req: Request<v1::FailTaskRequest>,
    ) -> Result<Response<v1::Empty>, Status> {
        require(&req, Role::Worker, "FailTask")?;
        let r = req.into_inner();
        if let Some(t) = r.task {
            let error: String = r.error.chars().take(2000).collect();
            let kind = v1::FailureKind::try_from(r.kind).unwrap_or(v1::FailureKind::Task);
            self.shared.fail(&t, error, kind);
        }
        Ok(Response::new(v1::Empty {}))
    }

    async fn leave(&self, req: Request<v1::LeaveRequest>) -> Result<Response<v1::Empty>, Status> {
        require(&req, Role::Worker, "Leave")?;
        let session = req.into_inner().session;
        let name = self.shared.worker_name(&session);
        if self.shared.leave(&session) {
            tracing::info!(worker = %name, "worker left: its tasks go to others");
        }
        Ok(Response::new(v1::Empty {}))
    }

    async fn scene_manifest(
        &self,
        req: Request<v1::SceneRef>,
    ) -> Result<Response<v1::SceneManifestReply>, Status> {
        require(&req, Role::Worker, "SceneManifest")?;
        let hash = req.into_inner().hash;
        let shared = self.shared.clone();
        let s = tokio::task::spawn_blocking(move || shared.scenes.get(&hash))
            .await
            .map_err(internal)?
            .map_err(|e| Status::invalid_argument(e.to_string()))?
            .ok_or_else(|| Status::not_found("no such scene"))?;
        Ok(Response::new(v1::SceneManifestReply {
            size: s.size,
            chunk_size: SCENE_CHUNK_BYTES as u32,
            chunk_hashes: s.chunk_hashes.iter().map(|h| h.to_vec()).collect(),
        }))
    }

    async fn scene_chunk(
        &self,
        req: Request<v1::SceneChunkRequest>,
    ) -> Result<Response<v1::SceneChunkReply>, Status> {
        require(&req, Role::Worker, "SceneChunk")?;
        let r = req.into_inner();
        let shared = self.shared.clone();
        let data = tokio::task::spawn_blocking(move || -> Result<Vec<u8>, Status> {
            let s = shared
                .scenes
                .get(&r.hash)
                .map_err(|e| Status::invalid_argument(e.to_string()))?
                .ok_or_else(|| Status::not_found("no such scene"))?;
            s.chunk(r.index)
                .map_err(|e| Status::invalid_argument(e.to_string()))
        })
        .await
        .map_err(internal)??;
        let t = &self.shared.traffic;
        t.scene_bytes
            .fetch_add(data.len() as u64, Ordering::Relaxed);
        t.scene_chunks.fetch_add(1, Ordering::Relaxed);
        Ok(Response::new(v1::SceneChunkReply { data }))
    }

    async fn has_scene(
        &self,
        req: Request<v1::SceneRef>,
    ) -> Result<Response<v1::HasSceneReply>, Status> {
        require(&req, Role::Client, "HasScene")?;
        let hash = req.into_inner().hash;
        let shared = self.shared.clone();
        let present = tokio::task::spawn_blocking(move || shared.scenes.get(&hash))
            .await
            .map_err(internal)?
            .map_err(|e| Status::invalid_argument(e.to_string()))?
            .is_some();
        Ok(Response::new(v1::HasSceneReply { present }))
    }

    async fn upload_scene(
        &self,
        req: Request<Streaming<v1::SceneUpload>>,
    ) -> Result<Response<v1::SceneRef>, Status> {
        use v1::scene_upload::Part as Up;
        require(&req, Role::Client, "UploadScene")?;
        if self.shared.is_stopping() {
            return Err(Status::unavailable(RESTARTING));
        }
        let mut stream = req.into_inner();
        let Some(Up::Header(h)) = stream.message().await?.and_then(|m| m.part) else {
            return Err(Status::invalid_argument("an upload starts with its header"));
        };
        if !crate::scenes::valid_hash(&h.hash) {
            return Err(Status::invalid_argument("not a scene hash"));
        }
        let max = self.shared.cfg.limits.max_scene_bytes;
        if h.size > max {
            return Err(Status::invalid_argument(format!(
                "a scene of {} bytes: this coordinator takes at most {max} (--max-scene-bytes)",
                h.size
            )));
        }
        let mut file = self.shared.scenes.upload_file().map_err(internal)?;
        let mut got = 0u64;
        while let Some(m) = stream.message().await? {
            let Some(Up::Data(d)) = m.part else {
                return Err(Status::invalid_argument("a second header"));
            };
            got += d.len() as u64;
            if got > h.size {
                return Err(Status::invalid_argument("more bytes than announced"));
            }
            file.write_all(&d).map_err(internal)?;
        }
        if got != h.size {
            return Err(Status::invalid_argument(format!(
                "the upload ended after {got} of {} bytes",
                h.size
            )));
        }
        file.flush().map_err(internal)?;
        let shared = self.shared.clone();
        let hash = tokio::task::spawn_blocking(move || shared.scenes.add_upload(file, &h.hash))
            .await
            .map_err(internal)?
            .map_err(|e| Status::invalid_argument(format!("{e:#}")))?;
        tracing::info!(scene = %hash, bytes = got, "scene uploaded");
        Ok(Response::new(v1::SceneRef { hash }))
    }

    async fn submit_job(
        &self,
        req: Request<v1::JobSpec>,
    ) -> Result<Response<v1::JobAccepted>, Status> {
        require(&req, Role::Client, "SubmitJob")?;
        if self.shared.is_stopping() {
            return Err(Status::unavailable(RESTARTING));
        }
        let spec = req.into_inner();
        if spec.protocol_version != sray_proto::PROTOCOL_VERSION {
            return Err(Status::failed_precondition(format!(
                "protocol version {} (this coordinator speaks {}): use the same sray version as the cluster",
                spec.protocol_version,
                sray_proto::PROTOCOL_VERSION
            )));
        }
        let running = self.shared.jobs.running().len();
        if running >= self.shared.cfg.limits.max_jobs {
            return Err(Status::resource_exhausted(format!(
                "{running} jobs are running, the most this coordinator takes (--max-jobs): try again later"
            )));
        }
        let (job_id, job_secret) = driver::submit(&self.shared, spec)
            .await
            .map_err(|e| Status::invalid_argument(format!("{e:#}")))?;
        Ok(Response::new(v1::JobAccepted { job_id, job_secret }))
    }

    type WatchJobStream = Stream_<v1::JobEvent>;

    async fn watch_job(
        &self,
        req: Request<v1::JobRef>,
    ) -> Result<Response<Self::WatchJobStream>, Status> {
        require(&req, Role::Client, "WatchJob")?;
        if self.shared.is_stopping() {
            return Err(Status::unavailable(RESTARTING));
        }
        let entry = self.job(req.get_ref(), "WatchJob")?;
        let (tx, rx) = mpsc::channel(16);
        let shared = self.shared.clone();
        tokio::spawn(async move {
            watch(shared, entry, tx).await;
        });
        Ok(Response::new(Box::pin(ReceiverStream::new(rx))))
    }

    async fn status(
        &self,
        req: Request<v1::StatusRequest>,
    ) -> Result<Response<v1::StatusReply>, Status> {
        require(&req, Role::Client, "Status")?;
        Ok(Response::new(crate::status::snapshot(&self.shared)))
    }

    async fn cancel_job(&self, req: Request<v1::JobRef>) -> Result<Response<v1::Empty>, Status> {
        require(&req, Role::Client, "CancelJob")?;
        let entry = self.job(req.get_ref(), "CancelJob")?;
        entry.cancelled.store(true, Ordering::Relaxed);
        tracing::info!(job = %entry.id, "cancelled by its client");
        Ok(Response::new(v1::Empty {}))
    }
}

/// Follows a job for one watcher: its log and progress while it runs,
/// then the image and statistics (from the journal) or the error. Ends
/// with `unavailable("coordinator restarting")` when the coordinator stops,
/// so that the client reconnects.
async fn watch(
    shared: Arc<Shared>,
    entry: Arc<JobEntry>,
    tx: mpsc::Sender<Result<v1::JobEvent, Status>>,
) {
    let ev = |e: v1::job_event::Event| Ok(v1::JobEvent { event: Some(e) });
    let mut changed = entry.subscribe();
    let mut sent_log = 0;
    let mut last_progress: Option<v1::JobProgress> = None;
    loop {
        if shared.is_stopping() {
            let _ = tx.send(Err(Status::unavailable(RESTARTING))).await;
            return;
        }
        let (lines, progress, state) = {
            let v = entry.view();
            (
                v.log[sent_log.min(v.log.len())..].to_vec(),
                v.progress,
                v.state.clone(),
            )
        };
        sent_log += lines.len();
        for l in lines {
            if tx.send(ev(v1::job_event::Event::Notice(l))).await.is_err() {
                return;
            }
        }
        if let Some(p) = progress
            && progress != last_progress
        {
            last_progress = progress;
            if tx
                .send(ev(v1::job_event::Event::Progress(p)))
                .await
                .is_err()
            {
                return;
            }
        }
        match state {
            JobState::Running => {}
            JobState::Failed(e) => {
                let _ = tx.send(ev(v1::job_event::Event::Error(e))).await;
                return;
            }
            JobState::Done => {
                let e = entry.clone();
                match tokio::task::spawn_blocking(move || crate::jobs::result(&e)).await {
                    Ok(Ok((image, stats))) => {
                        for c in image.chunks(sray_proto::wire::RECORD_CHUNK_BYTES) {
                            if tx
                                .send(ev(v1::job_event::Event::ImageChunk(c.to_vec())))
                                .await
                                .is_err()
                            {
                                return;
                            }
                        }
                        let _ = tx.send(ev(v1::job_event::Event::StatsJson(stats))).await;
                    }
                    Ok(Err(e)) => {
                        let _ = tx
                            .send(ev(v1::job_event::Event::Error(format!("{e:#}"))))
                            .await;
                    }
                    Err(e) => {
                        let _ = tx.send(Err(internal(e))).await;
                    }
                }
                return;
            }
        }
        tokio::select! {
            r = changed.changed() => if r.is_err() { return },
            _ = shared.stop.notified() => {}
            _ = tx.closed() => return,
        }
    }
}

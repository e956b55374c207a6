//! Submitting a render to a coordinator: upload the scene unless the
//! coordinator has it (by content hash), submit the job, follow its
//! progress, and take the image and statistics. Ctrl-C cancels the job.
//!
//! The job is named by a random id and guarded by a secret that only this
//! client receives; both are kept in a ticket file (`SRAY_JOBS_DIR`, else
//! `~/.local/state/sray/jobs/ID`, mode 0600) so that `sray fetch ID` can
//! get the image again. Once the job is submitted, a dropped connection or
//! a coordinator restart does not fail the render: the client reconnects
//! with backoff (0.2 s doubling to 5 s) for up to [`RECONNECT_FOR`] and
//! watches the job again; the coordinator resumes it from its journal.
//!
//! The coordinator encodes the image in the format the job asks for (PNG
//! or OpenEXR), from the same frame and with the same code as a render on
//! one machine, so the file is what `sray render` writes locally; this
//! client checks the file's signature.

use anyhow::{Context, bail};
use sray_coordinator::scenes::hash_file;
use sray_engine::progress::Progress;
use sray_engine::render::ImageFormat;
use sray_proto::net::{Client, Target};
use sray_proto::v1;
use sray_proto::wire::SCENE_CHUNK_BYTES;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use tokio::sync::mpsc;
use tokio_stream::wrappers::ReceiverStream;

/// How long a client keeps reconnecting to a coordinator it lost.
pub const RECONNECT_FOR: Duration = Duration::from_secs(300);

/// What the coordinator sends back.
pub struct JobResult {
    /// The image file's bytes, in the format asked for.
    pub image: Vec<u8>,
    pub stats: serde_json::Value,
}

/// A submitted job: what it takes to watch, fetch or cancel it.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Ticket {
    pub job_id: String,
    pub job_secret: String,
    pub coordinator: String,
    pub token_file: Option<PathBuf>,
    pub tls_ca: Option<PathBuf>,
    /// The client certificate and its key, if the coordinator requires one.
    #[serde(default)]
    pub tls_identity: Option<(PathBuf, PathBuf)>,
}

/// Where tickets are kept, if anywhere.
pub fn tickets_dir() -> Option<PathBuf> {
    if let Some(d) = std::env::var_os("SRAY_JOBS_DIR") {
        return Some(PathBuf::from(d));
    }
    if let Some(d) = std::env::var_os("XDG_STATE_HOME") {
        return Some(PathBuf::from(d).join("sray/jobs"));
    }
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/state/sray/jobs"))
}

fn save_ticket(t: &Ticket) -> Option<PathBuf> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let dir = tickets_dir()?;
    std::fs::create_dir_all(&dir).ok()?;
    // Tickets older than a week are of no use (jobs are kept far less).
    if let Ok(rd) = std::fs::read_dir(&dir) {
        for f in rd.flatten() {
            let old = f
                .metadata()
                .and_then(|m| m.modified())
                .ok()
                .and_then(|m| m.elapsed().ok())
                .is_some_and(|a| a > Duration::from_secs(7 * 86400));
            if old {
                let _ = std::fs::remove_file(f.path());
            }
        }
    }
    let path = dir.join(&t.job_id);
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(&path)
        .ok()?;
    f.write_all(serde_json::to_string(t).ok()?.as_bytes())
        .ok()?;
    Some(path)
}

/// The ticket of job `job` (`ID`, read from the tickets directory, or
/// `ID:SECRET`).
pub fn load_ticket(job: &str) -> anyhow::Result<Ticket> {
    if let Some((id, secret)) = job.split_once(':') {
        return Ok(Ticket {
            job_id: id.to_string(),
            job_secret: secret.to_string(),
            coordinator: String::new(),
            token_file: None,
            tls_ca: None,
            tls_identity: None,
        });
    }
    if !sray_proto::ids::is_hex_id(job, 32) {
        bail!("'{job}' is not a job id (32 hex digits, or ID:SECRET)");
    }
    let dir = tickets_dir().context("no tickets directory (set SRAY_JOBS_DIR or HOME)")?;
    let path = dir.join(job);
    let s = std::fs::read_to_string(&path).with_context(|| {
        format!(
            "no ticket for job {job} in {} (only the client that submitted it has one; give ID:SECRET)",
            dir.display()
        )
    })?;
    serde_json::from_str(&s).with_context(|| path.display().to_string())
}

fn absolute(p: &std::path::Path) -> PathBuf {
    std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf())
}

/// Renders the object database at `db` on the coordinator `target`.
pub async fn render(
    target: &Target,
    db: &Path,
    params: v1::RenderParams,
    shard_rays: u64,
    format: ImageFormat,
    progress: &dyn Progress,
) -> anyhow::Result<JobResult> {
    render_with(target, db, None, params, shard_rays, format, progress, true).await
}

/// As [`render`]; `hash`: the database's scene hash if known (else it is
/// computed here); `keep_ticket`: write the job's ticket for `sray fetch`.
pub async fn render_with(
    target: &Target,
    db: &Path,
    hash: Option<String>,
    params: v1::RenderParams,
    shard_rays: u64,
    format: ImageFormat,
    progress: &dyn Progress,
    keep_ticket: bool,
) -> anyhow::Result<JobResult> {
    let mut client = target.connect().await.map_err(anyhow::Error::msg)?;
    let hash = match hash {
        Some(h) => h,
        None => {
            progress.set_message("hashing the scene");
            let path = db.to_path_buf();
            tokio::task::spawn_blocking(move || hash_file(&path))
                .await??
                .0
        }
    };
    let present = client
        .has_scene(v1::SceneRef { hash: hash.clone() })
        .await
        .map_err(status)?
        .into_inner()
        .present;
    if !present {
        let size = std::fs::metadata(db)
            .with_context(|| db.display().to_string())?
            .len();
        progress.set_message(&format!("uploading the scene ({} MiB)", size >> 20));
        upload(&mut client, db, &hash, size).await?;
    }
    let accepted = client
        .submit_job(v1::JobSpec {
            scene: Some(v1::SceneRef { hash }),
            params: Some(params),
            shard_rays,
            image_format: match format {
                ImageFormat::Png => v1::ImageFormat::Png,
                ImageFormat::Exr => v1::ImageFormat::Exr,
            } as i32,
            protocol_version: sray_proto::PROTOCOL_VERSION,
        })
        .await
        .map_err(status)?
        .into_inner();
    let ticket = Ticket {
        job_id: accepted.job_id,
        job_secret: accepted.job_secret,
        coordinator: target.url.clone(),
        token_file: None,
        // Absolute, so that `sray fetch` finds them from anywhere.
        tls_ca: target.ca.as_deref().map(absolute),
        tls_identity: target
            .identity
            .as_ref()
            .map(|(c, k)| (absolute(c), absolute(k))),
    };
    if keep_ticket {
        match save_ticket(&ticket) {
            Some(p) => eprintln!(
                "sray: job {} submitted (ticket {}; `sray fetch {}` gets its image again)",
                ticket.job_id,
                p.display(),
                ticket.job_id
            ),
            None => eprintln!(
                "sray: job {} submitted (`sray fetch {}:{}` gets its image again)",
                ticket.job_id, ticket.job_id, ticket.job_secret
            ),
        }
    }
    let job = v1::JobRef {
        job_id: ticket.job_id.clone(),
        job_secret: ticket.job_secret.clone(),
    };
    let follow = follow(target, Some(client.clone()), &job, format, progress);
    tokio::select! {
        r = follow => r,
        _ = tokio::signal::ctrl_c() => {
            let _ = client.cancel_job(job).await;
            bail!("interrupted: the job was cancelled")
        }
    }
}

/// Watches job `job` to its end, reconnecting after dropped connections
/// and coordinator restarts for up to [`RECONNECT_FOR`].
pub async fn follow(
    target: &Target,
    mut client: Option<Client>,
    job: &v1::JobRef,
    format: ImageFormat,
    progress: &dyn Progress,
) -> anyhow::Result<JobResult> {
    let mut backoff = Duration::from_millis(200);
    let mut lost_since: Option<Instant> = None;
    loop {
        let c = match client.take() {
            Some(c) => Ok(c),
            None => target.connect().await,
        };
        let err = match c {
            Ok(mut c) => {
                let mut heard = false;
                match watch(&mut c, job, format, progress, &mut heard).await {
                    Ok(r) => return Ok(r),
                    Err(Watch::Fatal(e)) => return Err(e),
                    Err(Watch::Transient(msg)) => {
                        if heard {
                            lost_since = None;
                            backoff = Duration::from_millis(200);
                        }
                        msg
                    }
                }
            }
            Err(e) => e,
        };
        let since = *lost_since.get_or_insert_with(|| {
            eprintln!("sray: {err}; reconnecting");
            Instant::now()
        });
        if since.elapsed() > RECONNECT_FOR {
            bail!(
                "lost the coordinator for {} s ({err}); the job goes on: `sray fetch {}` gets its image",
                RECONNECT_FOR.as_secs(),
                job.job_id
            );
        }
        progress.set_message(&format!("{err}: reconnecting"));
        tokio::time::sleep(backoff).await;
        backoff = (backoff * 2).min(Duration::from_secs(5));
        // A fresh connection after a failure.
        client = None;
    }
}

fn status(s: tonic::Status) -> anyhow::Error {
    anyhow::anyhow!("the coordinator said: {}", s.message())
}

async fn upload(client: &mut Client, db: &Path, hash: &str, size: u64) -> anyhow::Result<()> {
    use v1::scene_upload::Part;
    let (tx, rx) = mpsc::channel(4);
    let header = v1::SceneUpload {
        part: Some(Part::Header(v1::SceneUploadHeader {
            size,
            hash: hash.to_string(),
        })),
    };
    tx.send(header).await.ok();
    let path = db.to_path_buf();
    let reader = tokio::task::spawn_blocking(move || -> anyhow::Result<()> {
        let mut f = std::fs::File::open(&path).with_context(|| path.display().to_string())?;
        loop {
            let mut buf = vec![0u8; SCENE_CHUNK_BYTES];
            let n = f
                .read(&mut buf)
                .with_context(|| path.display().to_string())?;
            if n == 0 {
                return Ok(());
            }
            buf.truncate(n);
            if tx
                .blocking_send(v1::SceneUpload {
                    part: Some(Part::Data(buf)),
                })
                .is_err()
            {
                return Ok(());
            }
        }
    });
    let r = client.upload_scene(ReceiverStream::new(rx)).await;
    reader.await??;
    r.map_err(status)?;
    Ok(())
}

enum Watch {
    /// Worth reconnecting for.
    Transient(String),
    Fatal(anyhow::Error),
}

fn classify(s: tonic::Status) -> Watch {
    use tonic::Code;
    match s.code() {
        Code::NotFound
        | Code::PermissionDenied
        | Code::Unauthenticated
        | Code::InvalidArgument
        | Code::FailedPrecondition => Watch::Fatal(status(s)),
        _ => Watch::Transient(format!("the coordinator said: {}", s.message())),
    }
}

async fn watch(
    client: &mut Client,
    job: &v1::JobRef,
    format: ImageFormat,
    progress: &dyn Progress,
    heard: &mut bool,
) -> Result<JobResult, Watch> {
    let mut events = client
        .watch_job(job.clone())
        .await
        .map_err(classify)?
        .into_inner();
    let mut image = Vec::new();
    // Each stage of each round counts its shards: (round, stage), done.
    let mut counting: Option<(u32, i32)> = None;
    let mut done = 0;
    while let Some(ev) = events.message().await.map_err(classify)? {
        *heard = true;
        match ev.event {
            Some(v1::job_event::Event::Progress(p)) => {
                let stage = if p.stage == v1::Stage::Shade as i32 {
                    "shading"
                } else {
                    "intersecting"
                };
                if counting != Some((p.round, p.stage)) {
                    counting = Some((p.round, p.stage));
                    done = 0;
                    progress.set_unit("shards");
                    progress.set_total(p.shards_total);
                }
                // Progress events may be skipped when the stream is busy.
                if p.shards_done > done {
                    progress.inc(p.shards_done - done);
                    done = p.shards_done;
                }
                progress.set_message(&format!(
                    "round {}: {stage} {} rays, {} worker(s)",
                    p.round, p.rays, p.workers
                ));
            }
            Some(v1::job_event::Event::Notice(n)) => eprintln!("sray: job: {n}"),
            Some(v1::job_event::Event::ImageChunk(c)) => image.extend_from_slice(&c),
            Some(v1::job_event::Event::StatsJson(s)) => {
                if image.is_empty() {
                    return Err(Watch::Fatal(anyhow::anyhow!(
                        "the coordinator sent no image"
                    )));
                }
                if !has_signature(&image, format) {
                    return Err(Watch::Fatal(anyhow::anyhow!(
                        "the coordinator sent an image that is not {format}"
                    )));
                }
                let stats = serde_json::from_str(&s)
                    .context("the job's statistics")
                    .map_err(Watch::Fatal)?;
                return Ok(JobResult { image, stats });
            }
            Some(v1::job_event::Event::Error(e)) => {
                return Err(Watch::Fatal(anyhow::anyhow!("the render failed: {e}")));
            }
            None => {}
        }
    }
    Err(Watch::Transient(
        "the coordinator closed the job's stream before the end".into(),
    ))
}

/// Whether `file` starts as a file of `format` does.
fn has_signature(file: &[u8], format: ImageFormat) -> bool {
    let magic: &[u8] = match format {
        ImageFormat::Png => b"\x89PNG\r\n\x1a\n",
        ImageFormat::Exr => &[0x76, 0x2f, 0x31, 0x01],
    };
    file.starts_with(magic)
}

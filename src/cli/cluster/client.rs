//! Submitting a render to a coordinator: upload the scene unless the
//! coordinator has it (by content hash), submit the job, follow its
//! progress, and take the image and statistics. Ctrl-C cancels the job.
//!
//! The coordinator encodes the image in the format the job asks for (PNG
//! or OpenEXR), from the same frame and with the same code as a render on
//! one machine, so the file is what `sray render` writes locally; this
//! client checks the file's signature, as a coordinator older than the
//! `image_format` field sends PNG whatever was asked.

use anyhow::{Context, bail};
use sray_coordinator::scenes::hash_file;
use sray_engine::progress::Progress;
use sray_engine::render::ImageFormat;
use sray_proto::net::{Client, Target};
use sray_proto::v1;
use sray_proto::wire::SCENE_CHUNK_BYTES;
use std::io::Read;
use std::path::Path;
use tokio::sync::mpsc;
use tokio_stream::wrappers::ReceiverStream;

/// What the coordinator sends back.
pub struct JobResult {
    /// The image file's bytes, in the format asked for.
    pub image: Vec<u8>,
    pub stats: serde_json::Value,
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
    let mut client = target.connect().await.map_err(anyhow::Error::msg)?;
    progress.set_message("hashing the scene");
    let path = db.to_path_buf();
    let (hash, size, _) = tokio::task::spawn_blocking(move || hash_file(&path)).await??;
    let present = client
        .has_scene(v1::SceneRef { hash: hash.clone() })
        .await
        .map_err(status)?
        .into_inner()
        .present;
    if !present {
        progress.set_message(&format!("uploading the scene ({} MiB)", size >> 20));
        upload(&mut client, db, &hash, size).await?;
    }
    let job = client
        .submit_job(v1::JobSpec {
            scene: Some(v1::SceneRef { hash }),
            params: Some(params),
            shard_rays,
            image_format: match format {
                ImageFormat::Png => v1::ImageFormat::Png,
                ImageFormat::Exr => v1::ImageFormat::Exr,
            } as i32,
        })
        .await
        .map_err(status)?
        .into_inner()
        .job_id;
    let watch = watch(&mut client, job, format, progress);
    tokio::select! {
        r = watch => r,
        _ = tokio::signal::ctrl_c() => {
            let _ = client.cancel_job(v1::JobRef { job_id: job }).await;
            bail!("interrupted: the job was cancelled")
        }
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

async fn watch(
    client: &mut Client,
    job: u64,
    format: ImageFormat,
    progress: &dyn Progress,
) -> anyhow::Result<JobResult> {
    let mut events = client
        .watch_job(v1::JobRef { job_id: job })
        .await
        .map_err(status)?
        .into_inner();
    let mut image = Vec::new();
    // Each stage of each round counts its shards: (round, stage), done.
    let mut counting: Option<(u32, i32)> = None;
    let mut done = 0;
    while let Some(ev) = events.message().await.map_err(status)? {
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
            Some(v1::job_event::Event::ImageChunk(c)) => image.extend_from_slice(&c),
            Some(v1::job_event::Event::StatsJson(s)) => {
                if image.is_empty() {
                    bail!("the coordinator sent no image");
                }
                if !has_signature(&image, format) {
                    // A coordinator older than JobSpec.image_format sends PNG.
                    bail!(
                        "the coordinator sent an image that is not {format}: it is perhaps too \
                         old to write {format} (write .png, or update it)"
                    );
                }
                return Ok(JobResult {
                    image,
                    stats: serde_json::from_str(&s).context("the job's statistics")?,
                });
            }
            Some(v1::job_event::Event::Error(e)) => bail!("the render failed: {e}"),
            None => {}
        }
    }
    bail!("the coordinator closed the job's stream before the end")
}

/// Whether `file` starts as a file of `format` does.
fn has_signature(file: &[u8], format: ImageFormat) -> bool {
    let magic: &[u8] = match format {
        ImageFormat::Png => b"\x89PNG\r\n\x1a\n",
        ImageFormat::Exr => &[0x76, 0x2f, 0x31, 0x01],
    };
    file.starts_with(magic)
}

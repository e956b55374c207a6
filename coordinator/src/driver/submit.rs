//! Jobs in: a new job checked, journaled and started; the journal's
//! unfinished jobs resumed at start; each job run to its end, its outcome
//! journaled and told to its watchers.

use super::job::Job;
use super::rounds::drive;
use crate::jobs::{self, JobEntry, JobState, Record, Resume};
use crate::state::Shared;
use sray_proto::v1;
use std::sync::Arc;
use std::time::Instant;

/// Takes a checked request: journals it and starts it. Returns the job's
/// id and secret.
pub async fn submit(shared: &Arc<Shared>, spec: v1::JobSpec) -> anyhow::Result<(String, String)> {
    let job = Job::check(shared, &spec).await?;
    let (entry, secret) = shared.jobs.create(&job.hash)?;
    entry.set_params(job.params);
    let mut rec = Record::new(&entry, &spec);
    let dir = entry.dir.clone();
    let r = rec_save(&mut rec, &dir).await;
    if let Err(e) = r {
        let _ = std::fs::remove_dir_all(&dir);
        return Err(e);
    }
    shared
        .counters
        .jobs_submitted
        .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    entry.log(format!(
        "job submitted: {}x{}, {} samples, depth {}, scene {}",
        job.opts.width,
        job.opts.height,
        job.opts.samples,
        job.opts.max_depth,
        &job.hash[..16]
    ));
    start(shared.clone(), entry.clone(), job, rec, None);
    Ok((entry.id.clone(), secret))
}

async fn rec_save(rec: &mut Record, dir: &std::path::Path) -> anyhow::Result<()> {
    let json = serde_json::to_vec_pretty(&*rec)?;
    let dir = dir.to_path_buf();
    tokio::task::spawn_blocking(move || {
        jobs::write_atomic(&dir, "job.json", |w| {
            use std::io::Write;
            Ok(w.write_all(&json)?)
        })
    })
    .await?
}

/// Resumes the unfinished jobs of the journal (at start).
pub async fn resume_all(shared: &Arc<Shared>) {
    let sh = shared.clone();
    let found = tokio::task::spawn_blocking(move || jobs::load_all(&sh.jobs, sh.cfg.job_retention))
        .await
        .unwrap_or_default();
    for (entry, rec) in found {
        let r: anyhow::Result<()> = async {
            let spec = rec.spec()?;
            let job = Job::check(shared, &spec).await?;
            entry.set_params(job.params);
            let slots = job.opts.frame_slots();
            let dir = entry.dir.clone();
            let spill = shared.spill.clone();
            let rec2 = serde_json::to_value(&rec)?;
            let resume = tokio::task::spawn_blocking(move || {
                let rec: Record = serde_json::from_value(rec2)?;
                jobs::load_checkpoint(&dir, &rec, slots, &spill)
            })
            .await??;
            entry.log(match &resume {
                Some(r) => format!("coordinator restarted: resuming at round {}", r.round),
                None => "coordinator restarted: starting again (no round had finished)".into(),
            });
            start(shared.clone(), entry.clone(), job, rec.clone(), resume);
            Ok(())
        }
        .await;
        if let Err(e) = r {
            let msg = format!("cannot resume the job: {e:#}");
            tracing::warn!(job = %entry.id, error = %msg, "job not resumed");
            let mut rec = rec;
            let _ = jobs::fail(&entry, &mut rec, &msg);
            entry.set_state(JobState::Failed(msg));
        }
    }
}

/// Runs a job to its end; the outcome is journaled and told to watchers.
fn start(shared: Arc<Shared>, entry: Arc<JobEntry>, job: Job, rec: Record, resume: Option<Resume>) {
    let e2 = entry.clone();
    entry.set_started();
    tracing::info!(
        job = %entry.id,
        width = job.opts.width,
        height = job.opts.height,
        samples = job.opts.samples,
        depth = job.opts.max_depth,
        shard_rays = job.shard_rays,
        resume_round = resume.as_ref().map_or(1, |r| r.round),
        "job started"
    );
    let h = tokio::spawn(async move {
        let t0 = Instant::now();
        let mut rec = rec;
        let r = drive(&shared, &entry, &job, &mut rec, resume).await;
        if shared.is_stopping() {
            // Resumed from its last checkpoint by the next run.
            return;
        }
        match r {
            Ok((image, stats)) => {
                let e = entry.clone();
                let saved =
                    tokio::task::spawn_blocking(move || jobs::finish(&e, &mut rec, &image, &stats))
                        .await;
                match saved {
                    Ok(Ok(())) => {
                        tracing::info!(job = %entry.id, seconds = t0.elapsed().as_secs_f64(), "job finished");
                        shared
                            .counters
                            .jobs_done
                            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        entry.set_state(JobState::Done);
                    }
                    Ok(Err(e)) => {
                        tracing::warn!(job = %entry.id, error = %format!("{e:#}"), "job failed: cannot keep the image");
                        shared
                            .counters
                            .jobs_failed
                            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        entry.set_state(JobState::Failed(format!("cannot keep the image: {e:#}")))
                    }
                    Err(e) => {
                        shared
                            .counters
                            .jobs_failed
                            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        entry.set_state(JobState::Failed(format!("internal: {e}")))
                    }
                }
            }
            Err(e) => {
                let msg = format!("{e:#}");
                tracing::warn!(job = %entry.id, error = %msg, seconds = t0.elapsed().as_secs_f64(), "job failed");
                shared
                    .counters
                    .jobs_failed
                    .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let _ = jobs::fail(&entry, &mut rec, &msg);
                entry.set_state(JobState::Failed(msg));
            }
        }
        shared.end_job(&entry.id);
    });
    *e2.driver.lock().unwrap_or_else(|p| p.into_inner()) = Some(h.abort_handle());
}

//! A job's driver: the breadth-first round loop of the embedded renderer,
//! with each stage cut into shards that workers run.
//!
//! Per round: the rays (eye rays, which workers make themselves, or the
//! previous round's spawned rays, kept in a file here) are split into
//! shards of at most `shard_rays`; each shard is intersected by some
//! worker, which returns its results in ray order. As the shards are
//! contiguous runs of ray ids, the sorted streams merge by concatenation.
//! Then each shard is shaded by some worker, given its rays and results;
//! the colour it contributes is added to the frame (in fixed point, so the
//! order of arrival does not matter) and the rays it spawns, sorted by key,
//! are merged by key into the next round's rays. The image and every count
//! are therefore those of the embedded render, whatever the workers, the
//! shard size or the order of completion.
//!
//! **Verification.** A ray's intersection result, and what shading it
//! contributes and spawns, depend only on the ray, never on the worker,
//! its grid or its memory. So every shard's output is checked, before the
//! stage may end, by re-tracing a random contiguous sample of its rays
//! (`verify_fraction` of them, at least `verify_min_rays`) on a *different*
//! worker and comparing bit for bit: results exactly; spawned rays in the
//! sample's key range exactly; the sample's contributions must all be
//! among the shard's (contributions carry no ray id). When no other worker
//! may take the sample, the coordinator traces it itself. On a mismatch the
//! coordinator re-traces the sample itself (it is the one party trusted),
//! quarantines whichever worker disagrees with it, redoes elsewhere every
//! output of this stage from a worker found lying, and says so in the
//! job's log.
//!
//! **Checkpoints.** At the end of every round the next round's rays, the
//! frame and the totals are journaled (see [`crate::jobs`]); a restarted
//! coordinator resumes the job from there.

use crate::jobs::{self, JobEntry, JobState, Record, Resume};
use crate::service::Receiver;
use crate::state::{Held, Segment, Shared, TaskEvent, TaskInput, TaskOutput, WorkerTag};
use anyhow::{Context, bail};
use sray_engine::bf::{BfOptions, Contribution, RayRec, ResultRec, SPAWN_SLOTS, StoreNumber};
use sray_engine::render::{
    Camera, Frame, GridRes, ImageFormat, KindCounts, RayCounts, RenderOptions, RenderStats, epsilon,
};
use sray_engine::sdb::Database;
use sray_engine::spill::{RecordWriter, Records};
use sray_proto::v1;
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;

/// A checked job, ready to run.
pub struct Job {
    pub scene: Arc<crate::scenes::Scene>,
    pub hash: String,
    pub params: v1::RenderParams,
    pub opts: RenderOptions,
    pub store: StoreNumber,
    pub shard_rays: u64,
    /// The job left the shard size to the coordinator (see [`shard_size`]).
    pub auto_shard: bool,
    /// The format of the image sent back.
    pub format: ImageFormat,
    pub objects: u64,
    /// The most triangles of any model the scene's instances place.
    pub model_triangles: u64,
    pub eps: f64,
    pub grids: Vec<sray_engine::grid::GridStat>,
}

/// Rays per shard in a round of `n` rays on `workers` workers: the job's
/// size, except when the job left it to the coordinator and one worker
/// does the work. No shard then waits for another worker, and fewer,
/// larger shards make fewer passes over the database (one local worker,
/// balls4 512x512: 1.34 s in shards of 65,536 rays, 1.18 s in two shards
/// per round). Where records travel, two per round keep the
/// coordinator's handling of one beside the worker's tracing of the
/// other; where the worker keeps them (`keep`), there is nothing to
/// overlap and the round is one shard (one local worker, balls4: 0.75 s
/// against 0.81 s in two shards per round, medians of 5; each shard's
/// passes end with a few that hold few rays).
fn shard_size(job: &Job, n: u64, workers: usize, keep: bool) -> u64 {
    if job.auto_shard && workers == 1 {
        auto_shard_size(job.shard_rays, n, keep)
    } else {
        job.shard_rays
    }
}

/// [`shard_size`] for one worker: at least `least` rays, and the round in
/// one shard (`keep`) or two, within [`AUTO_SHARD_MAX`].
fn auto_shard_size(least: u64, n: u64, keep: bool) -> u64 {
    let parts = if keep { 1 } else { 2 };
    least.max(n.div_ceil(parts).min(AUTO_SHARD_MAX))
}

/// Shards of at most `per` rays, each within the records of one worker
/// (records at the workers): a worker's consecutive segments joined, a
/// segment longer than `per` cut into equal parts.
fn held_shards(segments: &[Segment], per: u64) -> Vec<(u64, u64)> {
    let mut shards: Vec<(u64, u64)> = Vec::new();
    let mut open: Option<(&str, u64, u64)> = None;
    for g in segments {
        match &mut open {
            Some((s, _, len)) if *s == g.session && *len + g.len <= per => *len += g.len,
            _ => {
                if let Some((_, first, len)) = open.take() {
                    shards.push((first, len));
                }
                if g.len <= per {
                    open = Some((&g.session, g.start, g.len));
                } else {
                    let k = g.len.div_ceil(per);
                    let mut at = g.start;
                    for i in 0..k {
                        let len = g.len / k + u64::from(i < g.len % k);
                        shards.push((at, len));
                        at += len;
                    }
                }
            }
        }
    }
    if let Some((_, first, len)) = open {
        shards.push((first, len));
    }
    shards
}

/// A task's input was only at a worker that is gone (records at the
/// workers): the job starts again.
#[derive(Debug)]
struct RecordsLost(String);

impl std::fmt::Display for RecordsLost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for RecordsLost {}

/// How many times a job whose records were lost starts again.
const MAX_RESTARTS: u32 = 3;

/// The largest shard [`shard_size`] makes by itself.
const AUTO_SHARD_MAX: u64 = 1 << 20;

/// Fewest and most rays per shard a job may ask for.
const SHARD_RAYS: std::ops::RangeInclusive<u64> = 256..=(1 << 24);

/// The memory the grid statistics of a job are planned for: each worker
/// plans its own grid from its own `--memory` (results do not depend on
/// the grid), so the statistics name a nominal one.
const NOMINAL_MEMORY: u64 = 1 << 30;

impl Job {
    /// Checks a job request against the coordinator's limits (before
    /// anything is allocated for it): the scene is here, the settings are
    /// sane and within bounds.
    pub async fn check(shared: &Arc<Shared>, spec: &v1::JobSpec) -> anyhow::Result<Job> {
        let l = &shared.cfg.limits;
        let params = spec.params.context("a job needs render settings")?;
        let pixels = params.width as u64 * params.height as u64;
        if pixels > l.max_pixels {
            bail!(
                "{}x{} is {pixels} pixels: this coordinator renders at most {} (--max-pixels)",
                params.width,
                params.height,
                l.max_pixels
            );
        }
        if params.samples > l.max_samples {
            bail!(
                "{} samples per pixel: this coordinator takes at most {} (--max-samples)",
                params.samples,
                l.max_samples
            );
        }
        if params.max_depth > l.max_depth {
            bail!(
                "depth {}: this coordinator takes at most {} (--max-depth)",
                params.max_depth,
                l.max_depth
            );
        }
        let voxels = params.grid_res_x as u64 * params.grid_res_y as u64 * params.grid_res_z as u64;
        if voxels > l.max_grid_voxels {
            bail!(
                "a {}x{}x{} grid: at most {} voxels here",
                params.grid_res_x,
                params.grid_res_y,
                params.grid_res_z,
                l.max_grid_voxels
            );
        }
        let hash = spec
            .scene
            .as_ref()
            .map(|s| s.hash.clone())
            .unwrap_or_default();
        let sh = shared.clone();
        let h = hash.clone();
        let scene = tokio::task::spawn_blocking(move || sh.scenes.get(&h))
            .await??
            .with_context(|| format!("no scene {hash} here: upload it first"))?;
        if scene.size > l.max_scene_bytes {
            bail!(
                "the scene has {} bytes: at most {} here (--max-scene-bytes)",
                scene.size,
                l.max_scene_bytes
            );
        }
        let (opts, store) =
            sray_worker::params::from_proto(&params, 0).map_err(anyhow::Error::msg)?;
        let shard_rays = match spec.shard_rays {
            0 => shared.cfg.shard_rays,
            n if SHARD_RAYS.contains(&n) => n,
            n => bail!("{n} rays per shard is out of range {SHARD_RAYS:?}"),
        };
        let format = match v1::ImageFormat::try_from(spec.image_format) {
            Ok(v1::ImageFormat::Png) => ImageFormat::Png,
            Ok(v1::ImageFormat::Exr) => ImageFormat::Exr,
            Err(_) => bail!(
                "image format {} is unknown here: this coordinator writes PNG or OpenEXR",
                spec.image_format
            ),
        };
        let path = scene.path.clone();
        let o = opts.clone();
        let ((objects, model_triangles), eps, grids) =
            tokio::task::spawn_blocking(move || -> anyhow::Result<_> {
                let db = Database::open(&path)?;
                Camera::new(&db.scene().view, o.width, o.height)?;
                let (specs, _) = sray_engine::bf::plan_grids(&db, &o, NOMINAL_MEMORY);
                let groups =
                    sray_engine::grid::plan_groups(db.sizes(), db.density(), o.multiple_grids);
                let grids: Vec<_> = specs
                    .iter()
                    .zip(&groups.counts)
                    .map(|(s, &n)| sray_engine::grid::GridStat {
                        objects: n,
                        resolution: s.res,
                        lo: s.lo,
                        hi: s.hi,
                        nested_voxels: 0,
                        nested_objects: 0,
                        aggregates: 0,
                    })
                    .collect();
                // The most triangles any model has: no instance hit can name
                // a triangle past it.
                let mut model_triangles = 0;
                for m in 0..db.models().len() {
                    model_triangles = model_triangles.max(db.open_model(m)?.object_count());
                }
                Ok((
                    (db.object_count(), model_triangles),
                    epsilon(&db.bbox(), o.precision),
                    grids,
                ))
            })
            .await??;
        let _ = GridRes::Auto;
        Ok(Job {
            objects,
            model_triangles,
            eps,
            scene,
            hash,
            params,
            opts,
            store,
            shard_rays,
            auto_shard: spec.shard_rays == 0,
            format,
            grids,
        })
    }
}

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

/// Drops a stage's tasks however the stage ends.
struct TaskGuard<'a> {
    shared: &'a Shared,
    ids: Vec<u64>,
}

impl Drop for TaskGuard<'_> {
    fn drop(&mut self) {
        self.shared.forget_tasks(&self.ids);
    }
}

/// Totals over a job (journaled with every checkpoint).
#[derive(Default, serde::Serialize, serde::Deserialize)]
struct Totals {
    eye_hit_rays: u64,
    reflect_rays: u64,
    refract_rays: u64,
    shadow_rays: u64,
    tests: BTreeMap<String, u64>,
    hits: u64,
    tasks: u64,
    worker_seconds: f64,
    intersect_seconds: f64,
    shade_seconds: f64,
    max_workers: usize,
    rays_per_round: Vec<u64>,
    shards_per_round: Vec<u64>,
    passes: Vec<Vec<u64>>,
    /// Verification: samples checked, their rays, samples traced by the
    /// coordinator itself, mismatches, workers quarantined for lying,
    /// outputs redone.
    samples: u64,
    sample_rays: u64,
    shard_rays: u64,
    local_samples: u64,
    mismatches: u64,
    quarantined: Vec<String>,
    redone: u64,
    backups: u64,
    /// Seconds workers (and the coordinator) spent tracing samples.
    #[serde(default)]
    verify_seconds: f64,
    /// Passes over the objects made by shading tasks: none when every
    /// shard's results stayed, with their surfaces, on the worker that
    /// found them.
    #[serde(default)]
    shading_scans: u64,
    /// Tasks for which a worker had to build its grids.
    #[serde(default)]
    grid_builds: u64,
    /// Times the job started again from its eye rays (records lost with
    /// a worker).
    #[serde(default)]
    restarts: u32,
}

impl Totals {
    fn add(&mut self, o: &TaskOutput) {
        let s = &o.summary;
        self.eye_hit_rays += s.eye_hit_rays;
        self.reflect_rays += s.reflect_rays;
        self.refract_rays += s.refract_rays;
        self.shadow_rays += s.shadow_rays;
        for (k, n) in &s.tests_by_kind {
            *self.tests.entry(k.clone()).or_default() += n;
        }
        self.hits += o.hits;
        self.tasks += 1;
        self.grid_builds += s.built_grids as u64;
        self.worker_seconds += s.seconds;
    }
}

type Outcome = anyhow::Result<(Vec<u8>, String)>;

async fn drive(
    shared: &Arc<Shared>,
    entry: &Arc<JobEntry>,
    job: &Job,
    rec: &mut Record,
    resume: Option<Resume>,
) -> Outcome {
    let t0 = Instant::now();
    let mut traffic0 = shared.traffic.snapshot();
    let opts = &job.opts;
    let corners = opts.frame_slots();
    let mut frame = Frame::with_sampling(opts.width, opts.height, opts.sampling());
    let mut tot = Totals::default();
    let mut rays: Option<Arc<Records<RayRec>>> = None;
    let mut n = opts.eye_rays();
    let mut round = 1u32;
    if let Some(r) = resume {
        frame.slots = r.frame;
        tot = serde_json::from_value(r.totals).unwrap_or_default();
        round = r.round;
        n = r.rays.as_ref().map_or(0, |f| f.len());
        rays = r.rays.map(|f| Arc::new(Records::File(f)));
    }
    let mut arbiter = Arbiter::new(shared, job);
    // The checkpoint being written.
    let mut checkpointing: Option<tokio::task::JoinHandle<anyhow::Result<Record>>> = None;
    // Which workers hold the round's rays (none after a restart).
    let mut segments: Arc<Vec<Segment>> = Arc::default();
    // (Checkpoints and verification need the records here.)
    let keep = shared.cfg.records_at_workers
        && !shared.cfg.checkpoints
        && shared.cfg.verify_fraction == 0.0;
    let mut restarts = 0;
    // A stage's result; with records at the workers, a lost input starts
    // the job again from its eye rays (a few times at most).
    macro_rules! or_restart {
        ($r:expr, $frame:ident) => {
            match $r {
                Err(e) if e.is::<RecordsLost>() && restarts < MAX_RESTARTS => {
                    restarts += 1;
                    entry.log(format!(
                        "{e:#}: the job starts again from its eye rays ({restarts} of at most {MAX_RESTARTS} times)"
                    ));
                    $frame = Frame::with_sampling(opts.width, opts.height, opts.sampling());
                    tot = Totals {
                        restarts,
                        ..Totals::default()
                    };
                    traffic0 = shared.traffic.snapshot();
                    rays = None;
                    n = opts.eye_rays();
                    round = 1;
                    segments = Arc::default();
                    continue;
                }
                r => r?,
            }
        };
    }
    // The rounds, in a block of their own: however they end (an error,
    // a cancellation), the checkpoint being written is waited for before
    // the job's outcome is journaled, so that it cannot overwrite it.
    let rounds: anyhow::Result<Frame> = async {
        let mut frame = frame;
        while n > 0 {
            tot.rays_per_round.push(n);
            let per = shard_size(job, n, shared.worker_count(), keep);
            // The eye rays are made by the workers; later rounds' rays are
            // at the coordinator, or only at the workers that spawned them.
            let eye = rays.is_none() && segments.is_empty();
            // Rays only at the workers (not a round resumed from a
            // checkpoint of a run that kept them here).
            let held_only = keep && rays.is_none() && !segments.is_empty();
            let shards: Vec<(u64, u64)> = if held_only {
                // A shard size of the coordinator's choosing stretches to
                // the longest segment (within its cap): cutting a segment
                // only a little too long makes a small shard, and a pass
                // more.
                let longest = segments.iter().map(|g| g.len).max().unwrap_or(0);
                let per = if job.auto_shard {
                    per.max(longest.min(AUTO_SHARD_MAX))
                } else {
                    per
                };
                let shards = held_shards(&segments, per);
                anyhow::ensure!(
                    shards.iter().map(|s| s.1).sum::<u64>() == n,
                    "internal: the held segments do not make the round's {n} rays"
                );
                shards
            } else {
                (0..n.div_ceil(per))
                    .map(|i| {
                        let first = i * per;
                        (first, per.min(n - first))
                    })
                    .collect()
            };
            tot.shards_per_round.push(shards.len() as u64);
            let round_t0 = Instant::now();
            tracing::info!(job = %entry.id, round, rays = n, shards = shards.len(), "round started");

            // Intersect every shard.
            let ts = Instant::now();
            let inputs: Vec<Arc<TaskInput>> = shards
                .iter()
                .map(|&(first, _)| {
                    Arc::new(TaskInput {
                        rays: rays.clone(),
                        results: None,
                        results_offset: 0,
                        objects: job.objects,
                        model_triangles: job.model_triangles,
                        corners,
                        held: Held {
                            rays: segments.clone(),
                            intersect: None,
                            shard_first: first,
                            pinned: held_only,
                        },
                    })
                })
                .collect();
            let mut stage = Stage {
                shared,
                entry,
                job,
                round,
                stage: v1::Stage::Intersect,
                eye,
                shards: &shards,
                inputs,
                main_ids: Vec::new(),
                keep,
            };
            let outs = or_restart!(stage.run(&mut tot, &mut arbiter).await, frame);
            let intersect_ids = stage.main_ids.clone();
            let mut round_passes = Vec::new();
            let mut winners = Vec::new();
            let results: Vec<Option<Arc<Records<ResultRec>>>> = outs
                .into_iter()
                .map(|(o, w)| {
                    round_passes.push(passes_of(&o.summary.stats_json));
                    winners.push(w.session);
                    match (o.results, keep) {
                        (Some(r), _) => Ok(Some(Arc::new(r))),
                        // Kept by the worker (the receiver checked the count).
                        (None, true) => Ok(None),
                        (None, false) => bail!("an intersection task returned no results"),
                    }
                })
                .collect::<anyhow::Result<_>>()?;
            tot.passes
                .push(round_passes.into_iter().flatten().collect());
            tot.intersect_seconds += ts.elapsed().as_secs_f64();

            // Shade every shard.
            let ts = Instant::now();
            stage.stage = v1::Stage::Shade;
            stage.inputs = shards
                .iter()
                .enumerate()
                .map(|(i, &(first, _))| {
                    Arc::new(TaskInput {
                        rays: rays.clone(),
                        results: results[i].clone(),
                        results_offset: 0,
                        objects: job.objects,
                        model_triangles: job.model_triangles,
                        corners,
                        held: Held {
                            rays: Arc::default(),
                            intersect: Some((intersect_ids[i], winners[i].clone())),
                            shard_first: first,
                            pinned: keep,
                        },
                    })
                })
                .collect();
            let outs = or_restart!(stage.run(&mut tot, &mut arbiter).await, frame);
            // The next round's rays are the shards' spawned rays in shard
            // order (each shard's keys lie below the next one's), each run
            // held by the worker that spawned it.
            let mut segs = Vec::with_capacity(outs.len());
            let mut start = 0;
            let mut last_key: Option<u64> = None;
            for ((o, w), &id) in outs.iter().zip(&stage.main_ids) {
                tot.shading_scans += stat_of(&o.summary.stats_json, "db_scans").unwrap_or(0);
                let len = o.rays.as_ref().map_or(o.kept_rays, |r| r.len());
                if o.rays.is_none() && len > 0 {
                    // Kept at the worker: the keys as it reports them.
                    let (lo, hi) = (o.summary.kept_first_key, o.summary.kept_last_key);
                    anyhow::ensure!(
                        lo <= hi && last_key.is_none_or(|k| lo > k),
                        "spawned rays out of key order across shards"
                    );
                    last_key = Some(hi);
                }
                if len > 0 {
                    segs.push(Segment {
                        start,
                        len,
                        task: id,
                        session: w.session.clone(),
                    });
                }
                start += len;
            }
            let outs: Vec<TaskOutput> = outs.into_iter().map(|(o, _)| o).collect();
            drop(stage);
            drop(results);
            // Colour into the frame; spawned rays in key order.
            let (f, next) = tokio::task::spawn_blocking(move || merge_shade(frame, outs)).await??;
            frame = f;
            n = next.as_ref().map_or(0, |f| f.len());
            if keep {
                // The rays are the segments, at the workers alone.
                n = start;
            }
            segments = Arc::new(if start == n { segs } else { Vec::new() });
            rays = next.map(Arc::new);
            tot.shade_seconds += ts.elapsed().as_secs_f64();
            round += 1;

            // Checkpoint: a restart resumes here. It is written while the
            // next round runs (its rays are shared, its frame copied): a
            // restart before it is complete resumes from the one before, and
            // checkpoints are written one at a time, in order.
            if let Some(h) = checkpointing.take() {
                *rec = h.await??;
            }
            let done = round - 1;
            if shared.cfg.checkpoints {
                let e = entry.clone();
                let mut r2: Record = serde_json::from_value(serde_json::to_value(&*rec)?)?;
                let slots = frame.slots.clone();
                let rays2 = rays.clone();
                let totals = serde_json::to_value(&tot)?;
                checkpointing = Some(tokio::task::spawn_blocking(move || {
                    jobs::checkpoint(&e, &mut r2, round, &slots, rays2.as_deref(), totals)?;
                    tracing::info!(job = %e.id, round = done, "checkpoint written");
                    Ok(r2)
                }));
            }
            tracing::info!(
                job = %entry.id,
                round = done,
                seconds = round_t0.elapsed().as_secs_f64(),
                next_rays = n,
                "round done"
            );
        }
        Ok(frame)
    }
    .await;
    let last = match checkpointing.take() {
        Some(h) => Some(h.await),
        None => None,
    };
    let frame = rounds?;
    shared.traced.send_modify(|n| *n += 1);
    if let Some(r) = last {
        *rec = r??;
    }
    drop(arbiter);

    // The image, then the statistics.
    let format = job.format;
    let (image, preview) = tokio::task::spawn_blocking(move || -> anyhow::Result<_> {
        let image = frame.encode(format)?;
        // The dashboard shows PNG previews.
        let preview = match format {
            ImageFormat::Png => None,
            _ => Some(frame.encode(ImageFormat::Png)?),
        };
        Ok((image, preview))
    })
    .await??;
    if let Some(p) = preview {
        let dir = entry.dir.clone();
        tokio::task::spawn_blocking(move || {
            jobs::write_atomic(&dir, "preview.png", |w| {
                use std::io::Write;
                Ok(w.write_all(&p)?)
            })
        })
        .await??;
    }
    let stats = job_stats(
        shared,
        entry,
        job,
        &tot,
        traffic0,
        t0.elapsed().as_secs_f64(),
    );
    Ok((image, serde_json::to_string(&stats)?))
}

/// What a shard of a stage has come to.
#[derive(Default)]
struct ShardState {
    out: Option<(Arc<TaskOutput>, WorkerTag)>,
    verified: bool,
    /// The verification task out for it, and its sample.
    verify: Option<(u64, u64, u64)>,
}

enum Kind {
    Main(usize),
    Verify(usize),
}

/// What the coordinator's own trace of a sample is for.
enum Purpose {
    /// No other worker could check the shard.
    Verify,
    /// A worker's check disagreed with the shard's output.
    Arbitrate(WorkerTag, Arc<TaskOutput>),
}

struct Local {
    shard: usize,
    sample: (u64, u64),
    purpose: Purpose,
    result: anyhow::Result<TaskOutput>,
}

struct Stage<'a> {
    shared: &'a Arc<Shared>,
    entry: &'a Arc<JobEntry>,
    job: &'a Job,
    round: u32,
    stage: v1::Stage,
    eye: bool,
    shards: &'a [(u64, u64)],
    inputs: Vec<Arc<TaskInput>>,
    /// The shards' tasks in this stage.
    main_ids: Vec<u64>,
    /// Outputs stay at the workers ([`Config::records_at_workers`]).
    keep: bool,
}

impl Stage<'_> {
    fn task(&self, first: u64, count: u64, verification: bool) -> v1::Task {
        v1::Task {
            task_id: 0,
            job_id: self.entry.id.clone(),
            attempt: 0,
            stage: self.stage as i32,
            round: self.round,
            first_ray: first,
            ray_count: count,
            eye_rays: self.eye,
            params: Some(self.job.params),
            scene: Some(v1::SceneRef {
                hash: self.job.hash.clone(),
            }),
            verification,
            keep_output: self.keep,
        }
    }

    fn name(&self) -> &'static str {
        stage_name(self.stage)
    }

    /// The input of a sample of shard `i`'s rays.
    fn sample_input(&self, i: usize, s: u64) -> Arc<TaskInput> {
        let inp = &self.inputs[i];
        Arc::new(TaskInput {
            rays: inp.rays.clone(),
            results: inp.results.clone(),
            results_offset: s - self.shards[i].0,
            objects: inp.objects,
            model_triangles: inp.model_triangles,
            corners: inp.corners,
            held: inp.held.clone(),
        })
    }

    /// A random sample of shard `i`: its first ray and count.
    fn sample(&self, i: usize) -> (u64, u64) {
        let (first, count) = self.shards[i];
        let cfg = &self.shared.cfg;
        let k = ((count as f64 * cfg.verify_fraction).ceil() as u64)
            .max(cfg.verify_min_rays)
            .clamp(1, count);
        let off = sray_proto::ids::random_u64() % (count - k + 1);
        (first + off, k)
    }

    /// Queues the stage's tasks and waits until every shard is done and
    /// verified; fails on a task that failed too often, on cancellation,
    /// or when no worker may do the work for too long.
    async fn run(
        &mut self,
        tot: &mut Totals,
        arbiter: &mut Arbiter,
    ) -> anyhow::Result<Vec<(TaskOutput, WorkerTag)>> {
        let shared = self.shared;
        let cfg = &shared.cfg;
        let total = self.shards.len();
        let rays: u64 = self.shards.iter().map(|s| s.1).sum();
        let (ev_tx, mut ev_rx) = mpsc::unbounded_channel();
        let (local_tx, mut local_rx) = mpsc::unbounded_channel::<Local>();
        let tasks: Vec<_> = self
            .shards
            .iter()
            .enumerate()
            .map(|(i, &(first, count))| (self.task(first, count, false), i, self.inputs[i].clone()))
            .collect();
        let main_ids = shared.enqueue(tasks, &ev_tx, &[]);
        self.main_ids = main_ids.clone();
        let mut guard = TaskGuard {
            shared,
            ids: main_ids.clone(),
        };
        let mut kinds: HashMap<u64, Kind> = main_ids
            .iter()
            .enumerate()
            .map(|(i, &id)| (id, Kind::Main(i)))
            .collect();
        let mut st: Vec<ShardState> = (0..total).map(|_| ShardState::default()).collect();
        let verify = cfg.verify_fraction > 0.0;
        let mut stuck_since: Option<Instant> = None;
        let progress = |st: &[ShardState]| v1::JobProgress {
            round: self.round,
            stage: self.stage as i32,
            shards_done: st.iter().filter(|s| s.out.is_some() && s.verified).count() as u64,
            shards_total: total as u64,
            rays,
            workers: shared.worker_count() as u32,
        };
        self.entry.set_progress(progress(&st));
        let mut tick = tokio::time::interval(Duration::from_millis(250));
        while !st.iter().all(|s| s.out.is_some() && s.verified) {
            tokio::select! {
                ev = ev_rx.recv() => match ev {
                    Some(TaskEvent::Done { task, output, worker, .. }) => match kinds.get(&task) {
                        Some(&Kind::Main(i)) => {
                            if st[i].out.is_some() {
                                continue;
                            }
                            let out = Arc::new(output);
                            st[i].out = Some((out, worker.clone()));
                            st[i].verified = !verify;
                            if verify {
                                let (s, k) = self.sample(i);
                                if shared.eligible_workers(std::slice::from_ref(&worker)) > 0 {
                                    let t = self.task(s, k, true);
                                    let id = shared.enqueue(vec![(t, i, self.sample_input(i, s))], &ev_tx, &[worker])[0];
                                    guard.ids.push(id);
                                    kinds.insert(id, Kind::Verify(i));
                                    st[i].verify = Some((id, s, k));
                                } else {
                                    st[i].verify = Some((0, s, k));
                                    arbiter.trace(self, i, (s, k), Purpose::Verify, &local_tx);
                                }
                            }
                            self.entry.set_progress(progress(&st));
                        }
                        Some(&Kind::Verify(i)) => {
                            let Some((vid, s, k)) = st[i].verify else { continue };
                            if vid != task {
                                continue;
                            }
                            let Some((main, main_worker)) = st[i].out.clone() else { continue };
                            tot.verify_seconds += output.summary.seconds;
                            tot.grid_builds += output.summary.built_grids as u64;
                            let sample = Arc::new(output);
                            let first = self.shards[i].0;
                            let stage = self.stage;
                            let sm = sample.clone();
                            let same = tokio::task::spawn_blocking(move || same_sample(stage, &main, first, &sm, s, k)).await??;
                            tot.samples += 1;
                            tot.sample_rays += k;
                            if same {
                                st[i].verified = true;
                                self.entry.set_progress(progress(&st));
                            } else {
                                tot.mismatches += 1;
                                shared.counters.mismatches.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                                self.entry.log(format!(
                                    "verification mismatch: round {} {} shard {i} (rays {s}..{}): worker {} and worker {} disagree; the coordinator traces the sample itself to decide",
                                    self.round, self.name(), s + k, main_worker.name, worker.name
                                ));
                                arbiter.trace(self, i, (s, k), Purpose::Arbitrate(worker, sample), &local_tx);
                            }
                        }
                        None => {}
                    },
                    Some(TaskEvent::Lost { error, .. }) => {
                        return Err(anyhow::Error::new(RecordsLost(format!(
                            "round {} ({}): {error}",
                            self.round, self.name()
                        ))));
                    }
                    Some(TaskEvent::Failed { task, error }) => match kinds.get(&task) {
                        Some(Kind::Main(_)) => bail!(
                            "a {} task of round {} failed on {} workers: {error}",
                            self.name(), self.round, cfg.max_attempts
                        ),
                        Some(&Kind::Verify(i)) => {
                            // A sample that cannot be traced elsewhere is
                            // traced here.
                            if let Some((vid, s, k)) = st[i].verify && vid == task {
                                st[i].verify = Some((0, s, k));
                                arbiter.trace(self, i, (s, k), Purpose::Verify, &local_tx);
                            }
                        }
                        None => {}
                    },
                    None => bail!("internal: task events closed"),
                },
                Some(l) = local_rx.recv() => {
                    let i = l.shard;
                    let Some((main, main_worker)) = st[i].out.clone() else { continue };
                    let (s, k) = l.sample;
                    if st[i].verify.map(|v| (v.1, v.2)) != Some((s, k)) {
                        continue;
                    }
                    tot.local_samples += 1;
                    let local = match l.result {
                        Ok(o) => {
                            tot.verify_seconds += o.summary.seconds;
                            Arc::new(o)
                        }
                        Err(e) => {
                            self.entry.log(format!(
                                "the coordinator could not trace a sample of round {} {} shard {i}: {e:#}; the shard is redone on another worker",
                                self.round, self.name()
                            ));
                            self.redo(i, &main_worker, &mut st, tot);
                            continue;
                        }
                    };
                    let stage = self.stage;
                    let first = self.shards[i].0;
                    let (m, lo) = (main.clone(), local.clone());
                    let main_ok = tokio::task::spawn_blocking(move || same_sample(stage, &m, first, &lo, s, k)).await??;
                    if let Purpose::Arbitrate(verifier, vout) = &l.purpose {
                        let (v, lo) = (vout.clone(), local.clone());
                        let verifier_ok = tokio::task::spawn_blocking(move || {
                            anyhow::Ok(same_sample(stage, &v, s, &lo, s, k)? && same_sample(stage, &lo, s, &v, s, k)?)
                        }).await??;
                        if !verifier_ok {
                            self.distrust(verifier, &format!("its check of round {} {} shard {i} was wrong", self.round, self.name()), tot);
                        }
                    } else if main_ok {
                        tot.samples += 1;
                        tot.sample_rays += k;
                    }
                    if main_ok {
                        st[i].verified = true;
                        self.entry.set_progress(progress(&st));
                    } else {
                        let m = u64::from(matches!(l.purpose, Purpose::Verify));
                        tot.mismatches += m;
                        shared.counters.mismatches.fetch_add(m, std::sync::atomic::Ordering::Relaxed);
                        self.distrust(&main_worker, &format!("it returned wrong output for round {} {} shard {i} (rays {s}..{})", self.round, self.name(), s + k), tot);
                        // Every output of the stage from that worker is redone.
                        for j in 0..total {
                            if st[j].out.as_ref().is_some_and(|(_, w)| *w == main_worker) {
                                self.redo(j, &main_worker, &mut st, tot);
                            }
                        }
                    }
                }
                _ = tick.tick() => {
                    if self.entry.cancelled.load(std::sync::atomic::Ordering::Relaxed) {
                        bail!("cancelled by the client");
                    }
                    let workers = shared.worker_count();
                    tot.max_workers = tot.max_workers.max(workers);
                    // Backup attempts for stragglers.
                    for (id, ran) in shared.issue_backups(&guard.ids) {
                        tot.backups += 1;
                        if let Some(k) = kinds.get(&id) {
                            let (Kind::Main(i) | Kind::Verify(i)) = *k;
                            self.entry.log(format!(
                                "a {} task of round {} shard {i} has run {:.1} s, far longer than its siblings: a backup attempt goes to another worker (the first result wins)",
                                self.name(), self.round, ran.as_secs_f64()
                            ));
                        }
                    }
                    // A sample no other worker has taken in time (they are
                    // busy, or stuck) is traced here.
                    for id in shared.waiting(&guard.ids, cfg.deadline_min) {
                        if let Some(&Kind::Verify(i)) = kinds.get(&id)
                            && let Some((vid, s, k)) = st[i].verify
                            && vid == id
                        {
                            shared.forget_tasks(&[id]);
                            st[i].verify = Some((0, s, k));
                            arbiter.trace(self, i, (s, k), Purpose::Verify, &local_tx);
                        }
                    }
                    // Work that no worker may take.
                    let stranded = shared.stranded(&guard.ids);
                    let mut main_stranded = None;
                    for (id, errors) in stranded {
                        match kinds.get(&id) {
                            Some(&Kind::Verify(i)) => {
                                if let Some((vid, s, k)) = st[i].verify && vid == id {
                                    shared.forget_tasks(&[id]);
                                    st[i].verify = Some((0, s, k));
                                    arbiter.trace(self, i, (s, k), Purpose::Verify, &local_tx);
                                }
                            }
                            Some(Kind::Main(_)) => main_stranded = Some(errors),
                            None => {}
                        }
                    }
                    match main_stranded {
                        None => stuck_since = None,
                        Some(errors) => {
                            let since = *stuck_since.get_or_insert_with(Instant::now);
                            if since.elapsed() > cfg.worker_wait {
                                if workers == 0 {
                                    bail!(
                                        "no worker has been connected for {} s: start workers with `sray worker --coordinator URL`",
                                        cfg.worker_wait.as_secs()
                                    );
                                }
                                bail!(
                                    "no connected worker may run a {} task of round {} for {} s (it failed on, or was quarantined from, all of them): {errors}",
                                    self.name(), self.round, cfg.worker_wait.as_secs()
                                );
                            }
                        }
                    }
                }
            }
        }
        drop(guard);
        let outs: Vec<(TaskOutput, WorkerTag)> = st
            .into_iter()
            .map(|s| {
                let (o, w) = s.out.expect("every shard is done");
                Arc::try_unwrap(o)
                    .map(|o| (o, w))
                    .map_err(|_| anyhow::anyhow!("internal: an output is still shared"))
            })
            .collect::<anyhow::Result<_>>()?;
        for (o, _) in &outs {
            tot.add(o);
        }
        tot.shard_rays += rays;
        Ok(outs)
    }

    /// Quarantines a worker that returned wrong output.
    fn distrust(&self, w: &WorkerTag, why: &str, tot: &mut Totals) {
        if !self.shared.is_quarantined(w) {
            self.shared.quarantine(w, why);
        }
        if !tot.quarantined.contains(&w.name) {
            tot.quarantined.push(w.name.clone());
        }
        self.entry.log(format!(
            "worker {} quarantined for {} s: {why}; its outputs of this stage are redone on other workers",
            w.name,
            self.shared.cfg.quarantine.as_secs()
        ));
    }

    /// Throws shard `i`'s output away and runs it again elsewhere.
    fn redo(&self, i: usize, avoid: &WorkerTag, st: &mut [ShardState], tot: &mut Totals) {
        st[i] = ShardState::default();
        tot.redone += 1;
        self.shared.redo(self.main_ids[i], avoid);
    }
}

/// The coordinator's own tracer for a job, started the first time a
/// sample must be traced here (no other worker, or a mismatch to decide).
struct Arbiter {
    shared: Arc<Shared>,
    exec: Option<Arc<sray_worker::exec::Executor>>,
    db: std::path::PathBuf,
    opts: RenderOptions,
    store: StoreNumber,
    hash: String,
}

impl Arbiter {
    fn new(shared: &Arc<Shared>, job: &Job) -> Arbiter {
        let mut opts = job.opts.clone();
        opts.threads = 1;
        Arbiter {
            shared: shared.clone(),
            exec: None,
            db: job.scene.path.clone(),
            opts,
            store: job.store,
            hash: job.hash.clone(),
        }
    }

    /// Traces shard `i`'s sample here; the outcome goes to `tx`.
    fn trace(
        &mut self,
        stage: &Stage<'_>,
        i: usize,
        sample: (u64, u64),
        purpose: Purpose,
        tx: &mpsc::UnboundedSender<Local>,
    ) {
        let exec = self
            .exec
            .get_or_insert_with(|| {
                Arc::new(sray_worker::exec::Executor::start(
                    sray_worker::exec::JobSetup {
                        key: format!("arbiter-{}", &self.hash[..16]),
                        scene: self.hash.clone(),
                        db_path: self.db.clone(),
                        opts: self.opts.clone(),
                        bf: BfOptions {
                            memory: self.shared.cfg.arbiter_memory,
                            store: self.store,
                            spill_dir: Some(self.shared.spill.path().to_path_buf()),
                            shading: sray_engine::bf::Shading::Join,
                            models: Default::default(),
                        },
                        keep: false,
                        // Its inputs are files already.
                        kept_memory: sray_engine::spill::MemoryShare::new(0),
                        // Its output stays in this process: nothing to
                        // compress.
                        raw_records: true,
                    },
                    tokio::runtime::Handle::current(),
                ))
            })
            .clone();
        let (s, k) = sample;
        let task = stage.task(s, k, true);
        let input = stage.sample_input(i, s);
        let shared = self.shared.clone();
        let tx = tx.clone();
        tokio::spawn(async move {
            let result = trace_here(&shared, &exec, task, input).await;
            let _ = tx.send(Local {
                shard: i,
                sample,
                purpose,
                result,
            });
        });
    }
}

/// Runs one task on the coordinator's own executor, checking its output
/// as a worker's is checked.
async fn trace_here(
    shared: &Arc<Shared>,
    exec: &sray_worker::exec::Executor,
    task: v1::Task,
    input: Arc<TaskInput>,
) -> anyhow::Result<TaskOutput> {
    use sray_engine::spill::Records;
    use sray_worker::exec::{Input, Inputs, ResultSlice, Slice, Work};
    // The sample's input records, copied out of the round's files.
    let (t2, i2, spill) = (task.clone(), input.clone(), shared.spill.clone());
    let files = tokio::task::spawn_blocking(move || -> anyhow::Result<Inputs> {
        let mut inputs = Inputs::default();
        if let (Some(r), false) = (&i2.rays, t2.eye_rays) {
            let mut rd = r.reader_range(t2.first_ray, t2.ray_count)?;
            let mut w = RecordWriter::<RayRec>::create(&spill, "sample-rays")?;
            while let Some(x) = rd.next()? {
                w.push(&x)?;
            }
            inputs.rays = Some(Slice::whole(Records::File(w.finish()?)));
        }
        if let Some(r) = &i2.results {
            let mut rd = r.reader_range(i2.results_offset, t2.ray_count)?;
            let mut w = RecordWriter::<ResultRec>::create(&spill, "sample-results")?;
            while let Some(x) = rd.next()? {
                w.push(&x)?;
            }
            inputs.results = Some(ResultSlice::Bare(Slice::whole(Records::File(w.finish()?))));
        }
        Ok(inputs)
    })
    .await??;
    let (out_tx, mut out_rx) = mpsc::channel::<v1::TaskOutput>(4);
    let (done_tx, done_rx) = tokio::sync::oneshot::channel();
    let work = Work {
        task: task.clone(),
        input: Input::Files(files),
        out: out_tx,
        done: done_tx,
        fresh: false,
    };
    if !exec.submit(work) {
        bail!("the coordinator's tracer has stopped");
    }
    let mut rx = Receiver::new(shared, &task, &input);
    let mut summary = None;
    while let Some(m) = out_rx.recv().await {
        match m.part {
            Some(v1::task_output::Part::Records(c)) => rx.take(c).map_err(anyhow::Error::msg)?,
            Some(v1::task_output::Part::Summary(s)) => summary = Some(s),
            _ => {}
        }
    }
    done_rx
        .await
        .map_err(|_| anyhow::anyhow!("the coordinator's tracer stopped"))?
        .map_err(anyhow::Error::msg)?;
    rx.finish(summary.context("no summary")?)
        .map_err(anyhow::Error::msg)
}

/// Whether `sample` (rays `s .. s + k`) agrees bit for bit with what
/// `main` (a shard from ray `first`) says of those rays.
fn same_sample(
    stage: v1::Stage,
    main: &TaskOutput,
    first: u64,
    sample: &TaskOutput,
    s: u64,
    k: u64,
) -> anyhow::Result<bool> {
    if stage == v1::Stage::Intersect {
        let (Some(m), Some(x)) = (&main.results, &sample.results) else {
            return Ok(false);
        };
        if x.len() != k || m.len() < (s - first) + k {
            return Ok(false);
        }
        let mut a = m.reader_range(s - first, k)?;
        let mut b = x.reader()?;
        for _ in 0..k {
            let (p, q) = (a.next()?, b.next()?);
            match (p, q) {
                (Some(p), Some(q)) if bytemuck::bytes_of(&p) == bytemuck::bytes_of(&q) => {}
                _ => return Ok(false),
            }
        }
        return Ok(true);
    }
    // Spawned rays in the sample's key range: exactly the sample's.
    let (lo, hi) = (s * SPAWN_SLOTS, (s + k) * SPAWN_SLOTS);
    let mut want: Vec<RayRec> = Vec::new();
    if let Some(m) = &main.rays {
        let mut rd = m.reader()?;
        while let Some(r) = rd.next()? {
            if r.key >= hi {
                break;
            }
            if r.key >= lo {
                want.push(r);
            }
        }
    }
    let mut got: Vec<RayRec> = Vec::new();
    if let Some(x) = &sample.rays {
        let mut rd = x.reader()?;
        while let Some(r) = rd.next()? {
            got.push(r);
        }
    }
    if bytemuck::cast_slice::<RayRec, u8>(&want) != bytemuck::cast_slice::<RayRec, u8>(&got) {
        return Ok(false);
    }
    // The sample's contributions, each among the shard's.
    let mut need: HashMap<[u8; 32], u64> = HashMap::new();
    if let Some(x) = &sample.contributions {
        let mut rd = x.reader()?;
        while let Some(c) = rd.next()? {
            *need.entry(contribution_key(&c)).or_default() += 1;
        }
    }
    if need.is_empty() {
        return Ok(true);
    }
    if let Some(m) = &main.contributions {
        let mut rd = m.reader()?;
        while let Some(c) = rd.next()? {
            if let Some(n) = need.get_mut(&contribution_key(&c)) {
                *n -= 1;
                if *n == 0 {
                    need.remove(&contribution_key(&c));
                    if need.is_empty() {
                        return Ok(true);
                    }
                }
            }
        }
    }
    Ok(need.is_empty())
}

fn contribution_key(c: &Contribution) -> [u8; 32] {
    let mut k = [0u8; 32];
    k[..4].copy_from_slice(&c.corner.to_le_bytes());
    k[4..8].copy_from_slice(&c.run.to_le_bytes());
    for (j, v) in c.rgb.iter().enumerate() {
        k[8 + 8 * j..16 + 8 * j].copy_from_slice(&v.to_le_bytes());
    }
    k
}

fn stage_name(s: v1::Stage) -> &'static str {
    match s {
        v1::Stage::Intersect => "intersection",
        v1::Stage::Shade => "shading",
        v1::Stage::Unspecified => "unknown",
    }
}

/// Adds the shading outputs' colour to the frame and joins their spawned
/// rays into the next round's rays. The outputs come in shard order, and
/// each shard's keys lie below the next shard's (the receiver checked
/// each output's keys against its shard's range), so joining them in
/// order keeps the rays sorted by key; the join checks that it does. The
/// rays are joined as they lie (a chain of the outputs' records), not
/// copied.
fn merge_shade(
    mut frame: Frame,
    outs: Vec<TaskOutput>,
) -> anyhow::Result<(Frame, Option<Records<RayRec>>)> {
    let mut parts = Vec::with_capacity(outs.len());
    let mut last: Option<u64> = None;
    for o in outs {
        if let Some(c) = o.contributions {
            c.for_each_slice(&mut |s| {
                for x in s {
                    frame.add_contribution(x);
                }
                Ok(())
            })?;
        }
        let Some(r) = o.rays else { continue };
        if let (Some(first), Some(l)) = (r.get(0)?, last) {
            anyhow::ensure!(first.key > l, "spawned rays out of key order across shards");
        }
        if let Some(x) = r
            .len()
            .checked_sub(1)
            .map(|i| r.get(i))
            .transpose()?
            .flatten()
        {
            last = Some(x.key);
        }
        parts.push(r);
    }
    Ok((frame, Records::chain(parts)))
}

fn passes_of(stats_json: &str) -> Option<u64> {
    stat_of(stats_json, "passes")
}

/// A count from a task's statistics.
fn stat_of(stats_json: &str, key: &str) -> Option<u64> {
    serde_json::from_str::<serde_json::Value>(stats_json)
        .ok()
        .and_then(|v| v[key].as_u64())
}

fn job_stats(
    shared: &Shared,
    entry: &JobEntry,
    job: &Job,
    tot: &Totals,
    traffic0: [u64; 4],
    seconds: f64,
) -> RenderStats {
    let t = shared.traffic.snapshot();
    let d: Vec<u64> = t
        .iter()
        .zip(traffic0)
        .map(|(a, b)| a.saturating_sub(b))
        .collect();
    let counts = RayCounts {
        eye_rays: job.opts.eye_rays(),
        eye_hit_rays: tot.eye_hit_rays,
        reflect_rays: tot.reflect_rays,
        refract_rays: tot.refract_rays,
        shadow_rays: tot.shadow_rays,
    };
    let mut tests = KindCounts::default();
    // Kind names were checked when the outputs arrived.
    let _ = tests.add_named(tot.tests.iter().map(|(k, &n)| (k.as_str(), n)));
    let rays = counts.eye_rays + counts.reflect_rays + counts.refract_rays + counts.shadow_rays;
    let wire = d[0] + d[1];
    let (requeued, backups) = shared.requeued(&entry.id);
    let cluster = serde_json::json!({
        "job_id": entry.id,
        "workers": tot.max_workers,
        "shard_rays": job.shard_rays,
        "shards_per_round": tot.shards_per_round,
        "rays_per_round": tot.rays_per_round,
        "passes": tot.passes,
        "shading_scans": tot.shading_scans,
        "tasks": tot.tasks,
        "tasks_requeued": requeued,
        "job_restarts": tot.restarts,
        "backup_tasks": backups.max(tot.backups),
        "worker_seconds": tot.worker_seconds,
        "grid_builds": tot.grid_builds,
        "bytes_to_workers": d[0],
        "bytes_from_workers": d[1],
        "scene_bytes_served": d[2],
        "scene_chunks_served": d[3],
        "hits": tot.hits,
        "bytes_per_ray": wire as f64 / rays.max(1) as f64,
        "bytes_per_hit": wire as f64 / tot.hits.max(1) as f64,
        "verification": {
            "fraction": shared.cfg.verify_fraction,
            "samples": tot.samples,
            "sample_rays": tot.sample_rays,
            "shard_rays": tot.shard_rays,
            "traced_by_coordinator": tot.local_samples,
            "mismatches": tot.mismatches,
            "quarantined": tot.quarantined,
            "outputs_redone": tot.redone,
            "seconds": tot.verify_seconds,
        },
        "log": entry.view().log.clone(),
    });
    RenderStats {
        mode: "cluster".into(),
        mode_reason: "breadth-first on the cluster's workers".into(),
        objects: job.objects,
        width: job.opts.width,
        height: job.opts.height,
        depth: job.opts.max_depth,
        threads: 0,
        precision: format!("{:?}", job.opts.precision).to_lowercase(),
        epsilon: job.eps,
        rays: counts,
        intersection_tests: tests.total(),
        intersection_tests_by_kind: tests,
        grid_res: job.grids[0].resolution,
        grids: job.grids.clone(),
        trace_seconds: tot.intersect_seconds + tot.shade_seconds,
        intersect_seconds: Some(tot.intersect_seconds),
        shade_seconds: Some(tot.shade_seconds),
        total_seconds: seconds,
        peak_rss_bytes: sray_engine::sys::peak_rss_bytes(),
        details: Some(cluster),
        ..Default::default()
    }
}

#[cfg(test)]
mod tests {
    use super::{AUTO_SHARD_MAX, Segment, auto_shard_size, held_shards};

    #[test]
    fn one_worker_keeping_its_records_takes_a_round_in_one_shard() {
        // Records travel: two shards, so that the coordinator handles one
        // while the worker traces the other.
        assert_eq!(auto_shard_size(65_536, 797_659, false), 398_830);
        // Kept at the worker: the whole round, within the cap.
        assert_eq!(auto_shard_size(65_536, 797_659, true), 797_659);
        assert_eq!(auto_shard_size(65_536, 5 << 20, true), AUTO_SHARD_MAX);
        // Never below the job's size.
        assert_eq!(auto_shard_size(65_536, 1_000, true), 65_536);
    }

    #[test]
    fn held_shards_keep_to_one_worker_and_cover_every_ray() {
        let seg = |start, len, w: &str| Segment {
            start,
            len,
            task: 0,
            session: w.to_string(),
        };
        let segs = [
            seg(0, 30, "a"),
            seg(30, 40, "a"),
            seg(70, 50, "b"),
            seg(120, 250, "a"),
            seg(370, 10, "a"),
        ];
        assert_eq!(
            held_shards(&segs, 100),
            vec![
                (0, 70),
                (70, 50),
                (120, 84),
                (204, 83),
                (287, 83),
                (370, 10)
            ]
        );
    }
}

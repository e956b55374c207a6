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

use crate::state::{Shared, TaskEvent, TaskInput, TaskOutput};
use anyhow::{Context, bail};
use sray_engine::bf::{RayRec, plan_grids};
use sray_engine::render::{
    Camera, Frame, GridRes, ImageFormat, KindCounts, RayCounts, RenderOptions, RenderStats, epsilon,
};
use sray_engine::sdb::Database;
use sray_engine::spill::{ExternalSorter, RecordFile, RecordWriter};
use sray_proto::v1;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;

/// A checked job, ready to run.
pub struct Job {
    pub scene: Arc<crate::scenes::Scene>,
    pub hash: String,
    pub params: v1::RenderParams,
    pub opts: RenderOptions,
    pub shard_rays: u64,
    /// The format of the image sent back.
    pub format: ImageFormat,
    pub objects: u64,
    pub eps: f64,
    pub grids: Vec<sray_engine::grid::GridStat>,
}

/// Fewest and most rays per shard a job may ask for.
const SHARD_RAYS: std::ops::RangeInclusive<u64> = 256..=(1 << 24);

impl Job {
    /// Checks a job request: the scene is here, the settings are sane.
    /// Fixes the main grid's resolution so that every worker builds the
    /// same grid (planned for the smallest worker's memory).
    pub async fn check(shared: &Arc<Shared>, spec: v1::JobSpec) -> anyhow::Result<Job> {
        let hash = spec.scene.map(|s| s.hash).unwrap_or_default();
        let sh = shared.clone();
        let h = hash.clone();
        let scene = tokio::task::spawn_blocking(move || sh.scenes.get(&h))
            .await??
            .with_context(|| format!("no scene {hash} here: upload it first"))?;
        let mut params = spec.params.context("a job needs render settings")?;
        let (opts, _) = sray_worker::params::from_proto(&params, 0).map_err(anyhow::Error::msg)?;
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
        let db = Database::open(&scene.path)?;
        Camera::new(&db.scene().view, opts.width, opts.height)?;
        let memory = shared.min_worker_memory().unwrap_or(1 << 30);
        let (specs, _) = plan_grids(&db, &opts, memory);
        let groups = sray_engine::grid::plan_groups(db.sizes(), opts.multiple_grids);
        if opts.grid_res == GridRes::Auto {
            let [x, y, z] = specs[0].res;
            (params.grid_res_x, params.grid_res_y, params.grid_res_z) = (x, y, z);
        }
        let grids = specs
            .iter()
            .zip(&groups.counts)
            .map(|(s, &n)| sray_engine::grid::GridStat {
                objects: n,
                resolution: s.res,
                lo: s.lo,
                hi: s.hi,
            })
            .collect();
        Ok(Job {
            objects: db.object_count(),
            eps: epsilon(&db.bbox(), opts.precision),
            scene,
            hash,
            params,
            opts,
            shard_rays,
            format,
            grids,
        })
    }
}

/// Starts a job; its events go to whoever takes its watcher.
pub fn start(shared: Arc<Shared>, job: Job) -> u64 {
    let (id, events) = shared.new_job();
    tokio::spawn(async move {
        let t0 = Instant::now();
        let r = drive(&shared, id, &job, &events).await;
        match r {
            Ok(()) => tracing::info!(job = id, seconds = t0.elapsed().as_secs_f64(), "job done"),
            Err(e) => {
                tracing::warn!(job = id, error = %format!("{e:#}"), "job failed");
                let _ = events
                    .send(v1::JobEvent {
                        event: Some(v1::job_event::Event::Error(format!("{e:#}"))),
                    })
                    .await;
            }
        }
        shared.end_job(id);
    });
    id
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

/// Totals over a job.
#[derive(Default)]
struct Totals {
    counts: RayCounts,
    tests: KindCounts,
    hits: u64,
    tasks: u64,
    worker_seconds: f64,
    intersect_seconds: f64,
    shade_seconds: f64,
    max_workers: usize,
    rays_per_round: Vec<u64>,
    shards_per_round: Vec<u64>,
    passes: Vec<Vec<u64>>,
}

async fn drive(
    shared: &Arc<Shared>,
    id: u64,
    job: &Job,
    events: &mpsc::Sender<v1::JobEvent>,
) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let traffic0 = shared.traffic.snapshot();
    let opts = &job.opts;
    let corners = opts.frame_slots();
    let mut frame = Frame::with_sampling(opts.width, opts.height, opts.sampling());
    let mut tot = Totals {
        counts: RayCounts {
            eye_rays: opts.eye_rays(),
            ..Default::default()
        },
        ..Default::default()
    };
    let (ev_tx, mut ev_rx) = mpsc::unbounded_channel();
    let mut rays: Option<Arc<RecordFile<RayRec>>> = None;
    let mut n = opts.eye_rays();
    let mut round = 1u32;
    while n > 0 {
        tot.rays_per_round.push(n);
        let shards: Vec<(u64, u64)> = (0..n.div_ceil(job.shard_rays))
            .map(|i| {
                let first = i * job.shard_rays;
                (first, job.shard_rays.min(n - first))
            })
            .collect();
        tot.shards_per_round.push(shards.len() as u64);
        let task = |stage: v1::Stage, first: u64, count: u64| v1::Task {
            task_id: 0,
            job_id: id,
            attempt: 0,
            stage: stage as i32,
            round,
            first_ray: first,
            ray_count: count,
            eye_rays: rays.is_none(),
            params: Some(job.params),
            scene: Some(v1::SceneRef {
                hash: job.hash.clone(),
            }),
        };

        // Intersect every shard.
        let ts = Instant::now();
        let tasks = shards
            .iter()
            .enumerate()
            .map(|(i, &(first, count))| {
                let input = TaskInput {
                    rays: rays.clone(),
                    results: None,
                    objects: job.objects,
                    corners,
                };
                (task(v1::Stage::Intersect, first, count), i, Arc::new(input))
            })
            .collect();
        let outs = run_stage(
            shared,
            id,
            round,
            v1::Stage::Intersect,
            tasks,
            &ev_tx,
            &mut ev_rx,
            events,
            &mut tot,
        )
        .await?;
        let mut round_passes = Vec::new();
        let results: Vec<_> = outs
            .into_iter()
            .map(|o| {
                round_passes.push(passes_of(&o.summary.stats_json));
                o.results
                    .map(Arc::new)
                    .context("an intersection task returned no results")
            })
            .collect::<anyhow::Result<_>>()?;
        tot.passes
            .push(round_passes.into_iter().flatten().collect());
        tot.intersect_seconds += ts.elapsed().as_secs_f64();

        // Shade every shard.
        let ts = Instant::now();
        let tasks = shards
            .iter()
            .enumerate()
            .map(|(i, &(first, count))| {
                let input = TaskInput {
                    rays: rays.clone(),
                    results: Some(results[i].clone()),
                    objects: job.objects,
                    corners,
                };
                (task(v1::Stage::Shade, first, count), i, Arc::new(input))
            })
            .collect();
        let outs = run_stage(
            shared,
            id,
            round,
            v1::Stage::Shade,
            tasks,
            &ev_tx,
            &mut ev_rx,
            events,
            &mut tot,
        )
        .await?;
        drop(results);
        // Colour into the frame; spawned rays merged by key.
        let spill = shared.spill.clone();
        let (f, next) =
            tokio::task::spawn_blocking(move || merge_shade(frame, outs, &spill)).await??;
        frame = f;
        n = next.as_ref().map_or(0, |f| f.len());
        rays = next.map(Arc::new);
        tot.shade_seconds += ts.elapsed().as_secs_f64();
        round += 1;
    }

    // The image, then the statistics.
    let format = job.format;
    let image = tokio::task::spawn_blocking(move || frame.encode(format)).await??;
    for c in image.chunks(sray_proto::wire::RECORD_CHUNK_BYTES) {
        send(events, v1::job_event::Event::ImageChunk(c.to_vec())).await?;
    }
    let stats = job_stats(shared, id, job, &tot, traffic0, t0.elapsed().as_secs_f64());
    send(
        events,
        v1::job_event::Event::StatsJson(serde_json::to_string(&stats)?),
    )
    .await?;
    Ok(())
}

async fn send(events: &mpsc::Sender<v1::JobEvent>, e: v1::job_event::Event) -> anyhow::Result<()> {
    events
        .send(v1::JobEvent { event: Some(e) })
        .await
        .map_err(|_| anyhow::anyhow!("the client went away"))
}

/// Queues a stage's tasks and waits until every one is done, reporting
/// progress; fails on a task that failed too often, on cancellation, or
/// when no worker has been there for too long.
#[allow(clippy::too_many_arguments)]
async fn run_stage(
    shared: &Arc<Shared>,
    job: u64,
    round: u32,
    stage: v1::Stage,
    tasks: Vec<(v1::Task, usize, Arc<TaskInput>)>,
    ev_tx: &mpsc::UnboundedSender<TaskEvent>,
    ev_rx: &mut mpsc::UnboundedReceiver<TaskEvent>,
    events: &mpsc::Sender<v1::JobEvent>,
    tot: &mut Totals,
) -> anyhow::Result<Vec<TaskOutput>> {
    let total = tasks.len();
    let rays: u64 = tasks.iter().map(|t| t.0.ray_count).sum();
    let guard = TaskGuard {
        shared,
        ids: shared.enqueue(tasks, ev_tx),
    };
    let mut outs: Vec<Option<TaskOutput>> = (0..total).map(|_| None).collect();
    let mut done = 0;
    let mut alone_since: Option<Instant> = None;
    let progress = |done: usize| v1::JobEvent {
        event: Some(v1::job_event::Event::Progress(v1::JobProgress {
            round,
            stage: stage as i32,
            shards_done: done as u64,
            shards_total: total as u64,
            rays,
            workers: shared.worker_count() as u32,
        })),
    };
    let _ = events.try_send(progress(0));
    let mut tick = tokio::time::interval(Duration::from_millis(500));
    while done < total {
        tokio::select! {
            ev = ev_rx.recv() => match ev {
                Some(TaskEvent::Done { task, shard, output }) => {
                    if !guard.ids.contains(&task) || outs[shard].is_some() {
                        continue;
                    }
                    let s = &output.summary;
                    tot.counts.eye_hit_rays += s.eye_hit_rays;
                    tot.counts.reflect_rays += s.reflect_rays;
                    tot.counts.refract_rays += s.refract_rays;
                    tot.counts.shadow_rays += s.shadow_rays;
                    // Kind names were checked when the output arrived.
                    let _ = tot
                        .tests
                        .add_named(s.tests_by_kind.iter().map(|(k, &n)| (k.as_str(), n)));
                    tot.hits += output.hits;
                    tot.tasks += 1;
                    tot.worker_seconds += s.seconds;
                    outs[shard] = Some(output);
                    done += 1;
                    let _ = events.try_send(progress(done));
                }
                Some(TaskEvent::Failed { task, error }) => {
                    if guard.ids.contains(&task) {
                        bail!("a {} task of round {round} failed on every try: {error}", stage_name(stage));
                    }
                }
                None => bail!("internal: task events closed"),
            },
            _ = tick.tick() => {
                if events.is_closed() || shared.is_cancelled(job) {
                    bail!("cancelled by the client");
                }
                let workers = shared.worker_count();
                tot.max_workers = tot.max_workers.max(workers);
                if workers > 0 {
                    alone_since = None;
                } else {
                    let since = *alone_since.get_or_insert_with(Instant::now);
                    if since.elapsed() > shared.cfg.worker_wait {
                        bail!(
                            "no worker has been connected for {} s: start workers with `sray worker --coordinator URL`",
                            shared.cfg.worker_wait.as_secs()
                        );
                    }
                }
            }
        }
    }
    Ok(outs
        .into_iter()
        .map(|o| o.expect("every shard is done"))
        .collect())
}

fn stage_name(s: v1::Stage) -> &'static str {
    match s {
        v1::Stage::Intersect => "intersection",
        v1::Stage::Shade => "shading",
        v1::Stage::Unspecified => "unknown",
    }
}

/// Adds the shading outputs' colour to the frame and merges their spawned
/// rays (each sorted by key) into the next round's rays.
fn merge_shade(
    mut frame: Frame,
    outs: Vec<TaskOutput>,
    spill: &sray_engine::spill::SpillDir,
) -> anyhow::Result<(Frame, Option<RecordFile<RayRec>>)> {
    let key = (|r: &RayRec| r.key) as fn(&RayRec) -> u64;
    let mut sorter = ExternalSorter::new(spill, "next", 16, key);
    for o in outs {
        if let Some(c) = o.contributions {
            let mut rd = c.reader()?;
            while let Some(x) = rd.next()? {
                frame.add(x.corner, x.rgb);
            }
        }
        if let Some(r) = o.rays {
            sorter.add_sorted_run(r);
        }
    }
    if sorter.is_empty() {
        return Ok((frame, None));
    }
    let mut sorted = sorter.finish()?;
    let mut w = RecordWriter::<RayRec>::create(spill, "round")?;
    while let Some(r) = sorted.next()? {
        w.push(&r)?;
    }
    Ok((frame, Some(w.finish()?)))
}

fn passes_of(stats_json: &str) -> Option<u64> {
    serde_json::from_str::<serde_json::Value>(stats_json)
        .ok()
        .and_then(|v| v["passes"].as_u64())
}

fn job_stats(
    shared: &Shared,
    id: u64,
    job: &Job,
    tot: &Totals,
    traffic0: [u64; 4],
    seconds: f64,
) -> RenderStats {
    let t = shared.traffic.snapshot();
    let d: Vec<u64> = t.iter().zip(traffic0).map(|(a, b)| a - b).collect();
    let rays = tot.counts.eye_rays
        + tot.counts.reflect_rays
        + tot.counts.refract_rays
        + tot.counts.shadow_rays;
    let wire = d[0] + d[1];
    let cluster = serde_json::json!({
        "workers": tot.max_workers,
        "shard_rays": job.shard_rays,
        "shards_per_round": tot.shards_per_round,
        "rays_per_round": tot.rays_per_round,
        "passes": tot.passes,
        "tasks": tot.tasks,
        "tasks_requeued": shared.requeued(id),
        "worker_seconds": tot.worker_seconds,
        "bytes_to_workers": d[0],
        "bytes_from_workers": d[1],
        "scene_bytes_served": d[2],
        "scene_chunks_served": d[3],
        "hits": tot.hits,
        "bytes_per_ray": wire as f64 / rays.max(1) as f64,
        "bytes_per_hit": wire as f64 / tot.hits.max(1) as f64,
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
        rays: tot.counts,
        intersection_tests: tot.tests.total(),
        intersection_tests_by_kind: tot.tests,
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

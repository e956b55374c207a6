//! A job's round loop: each round's rays cut into shards, intersected,
//! shaded, merged into the frame and the next round's rays, and
//! checkpointed; then the image and the statistics.

use super::held;
use super::job::Job;
use super::prints;
use super::recover::{Lineage, RoundLog, run_stage};
use super::shards::{Fleet, cut, shard_size};
use super::stages::{RecordsLost, Stage};
use super::stats::{TaskCounts, Totals, job_stats};
use super::verify::Arbiter;
use crate::jobs::{self, JobEntry, Record, Resume};
use crate::state::Shared;
use crate::task::{Held, Segment, TaskInput, TaskOutput};
use anyhow::bail;
use sray_engine::bf::{RayRec, ResultRec};
use sray_engine::render::{Frame, ImageFormat};
use sray_engine::spill::Records;
use sray_proto::v1;
use std::sync::Arc;
use std::time::Instant;

/// How many times a job whose records were lost (and could not be
/// recomputed) starts again.
const MAX_RESTARTS: u32 = 3;

/// The image and the statistics (JSON) of a job that ended well.
type Outcome = anyhow::Result<(Vec<u8>, String)>;

/// Runs a job's rounds, from its eye rays or its checkpoint, to its image
/// and statistics; a checkpoint is journaled at the end of every round.
pub(super) async fn drive(
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
    // Which workers hold the round's rays (none after a restart).
    let mut segments: Arc<Vec<Segment>> = Arc::default();
    // (Checkpoints need the records here; verification does not, see
    // `held.rs`.)
    let keep = shared.cfg.records_at_workers && !shared.cfg.checkpoints;
    // Records at the workers: the workers one of whose shards has been
    // checked in this run of the job (see `held.rs`).
    let mut checked = std::collections::HashSet::new();
    let mut unchecked_said = false;
    let mut restarts = 0;
    // With records at the workers: each round's shards and what they
    // spawned, to recompute a lost worker's records.
    let mut lineage = Lineage::default();
    // A stage's result; with records at the workers, a lost input that
    // could not be recomputed starts the job again from its eye rays (a
    // few times at most).
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
                        recomputations: tot.recomputations,
                        recomputed_tasks: tot.recomputed_tasks,
                        // What verification found stays said.
                        samples: tot.samples,
                        sample_rays: tot.sample_rays,
                        local_samples: tot.local_samples,
                        mismatches: tot.mismatches,
                        quarantined: std::mem::take(&mut tot.quarantined),
                        verify_seconds: tot.verify_seconds,
                        ..Totals::default()
                    };
                    lineage = Lineage::default();
                    checked.clear();
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
    // The rounds, in a block of their own.
    let rounds: anyhow::Result<Frame> = async {
        let mut frame = frame;
        while n > 0 {
            tot.rays_per_round.push(n);
            let (workers, min_memory, worker_rate) = shared.fleet(&job.hash);
            let fleet = Fleet {
                workers,
                min_memory,
                worker_rate,
            };
            let per = shard_size(job, n, fleet, keep);
            // The eye rays are made by the workers; later rounds' rays are
            // at the coordinator, or only at the workers that spawned them.
            let eye = rays.is_none() && segments.is_empty();
            // Rays only at the workers (not a round resumed from a
            // checkpoint of a run that kept them here).
            let held_only = keep && rays.is_none() && !segments.is_empty();
            let shards = cut(job, n, per, &segments, held_only)?;
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
                            at: None,
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
                alias: None,
                lost_holders: Vec::new(),
            };
            let outs = or_restart!(
                run_stage(&mut stage, &mut lineage, &mut tot, &mut arbiter).await,
                frame
            );
            let intersect_ids = stage.main_ids.clone();
            let mut round_passes = Vec::new();
            let mut winners = Vec::new();
            // What verification compares of the intersections kept at
            // the workers.
            let mut iprints = Vec::new();
            let results: Vec<Option<Arc<Records<ResultRec>>>> = outs
                .into_iter()
                .map(|(o, w)| {
                    round_passes.push(TaskCounts::of(&o.summary.stats_json).passes);
                    winners.push(w.session);
                    if keep {
                        iprints.push(prints::print_of(v1::Stage::Intersect, &o, 0)?);
                    }
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
                            at: None,
                        },
                    })
                })
                .collect();
            let outs = or_restart!(
                run_stage(&mut stage, &mut lineage, &mut tot, &mut arbiter).await,
                frame
            );
            // The next round's rays are the shards' spawned rays in shard
            // order (each shard's keys lie below the next one's), each run
            // held by the worker that spawned it.
            let mut segs = Vec::with_capacity(outs.len());
            let mut spawned = Vec::with_capacity(outs.len());
            let mut start = 0;
            let mut last_key: Option<u64> = None;
            for ((o, w), &id) in outs.iter().zip(&stage.main_ids) {
                tot.shading_scans += TaskCounts::of(&o.summary.stats_json).db_scans.unwrap_or(0);
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
                spawned.push((len > 0).then_some((start, len)));
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
            // A check reruns a shard's lineage from the eye rays: not that
            // of a round resumed from a checkpoint (its earlier rounds
            // ran before the restart; said once in the job's log).
            let known = lineage.rounds.len() + 1 == round as usize;
            if keep && shared.cfg.verify_fraction > 0.0 && !known && !unchecked_said {
                unchecked_said = true;
                entry.log(format!(
                    "round {round}: this job was resumed from a checkpoint, and with records at the workers the shards of its rounds from there on are not verified (their checks would rerun the rounds before the checkpoint)"
                ));
            }
            if keep && shared.cfg.verify_fraction > 0.0 && known {
                // Shards checked before their colour goes to the frame.
                let by: Vec<_> = outs.iter().map(|(_, w)| w.clone()).collect();
                let picks = held::pick(shared.cfg.verify_fraction, &by, &mut checked);
                or_restart!(
                    held::check_round(
                        &stage,
                        &lineage,
                        &picks,
                        &iprints,
                        &winners,
                        &outs,
                        &mut tot,
                        &mut arbiter
                    )
                    .await,
                    frame
                );
            }
            if keep {
                lineage.rounds.push(RoundLog {
                    shards: shards.clone(),
                    spawned,
                    by: outs.iter().map(|(_, w)| w.clone()).collect(),
                });
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

            // Checkpoint: a restart resumes here. It is written before the
            // next round starts, so that a restart resumes from the last
            // round that finished (written during the next round, a kill
            // before it was complete cost a round). A checkpoint that
            // cannot be written (the coordinator's own disk) is said in
            // the job's log, and the job goes on: a restart would resume
            // from an earlier one.
            let done = round - 1;
            if shared.cfg.checkpoints {
                let e = entry.clone();
                let mut r2: Record = serde_json::from_value(serde_json::to_value(&*rec)?)?;
                let slots = frame.slots.clone();
                let rays2 = rays.clone();
                let totals = serde_json::to_value(&tot)?;
                let t_ck = Instant::now();
                let written = tokio::task::spawn_blocking(move || {
                    jobs::checkpoint(&e, &mut r2, round, &slots, rays2.as_deref(), totals)
                        .map(|()| r2)
                })
                .await?;
                match written {
                    Ok(r2) => {
                        *rec = r2;
                        tot.checkpoint_seconds += t_ck.elapsed().as_secs_f64();
                        tracing::info!(job = %entry.id, round = done, seconds = t_ck.elapsed().as_secs_f64(), "checkpoint written");
                    }
                    Err(err) => {
                        tracing::error!(job = %entry.id, round = done, error = %format!("{err:#}"), "checkpoint not written");
                        entry.log(format!(
                            "the coordinator could not write the checkpoint of round {done}: {err:#}; the job goes on (a restart would resume from an earlier round)"
                        ));
                    }
                }
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
    shared.drop_aliases(&entry.id);
    let frame = rounds?;
    shared.traced.send_modify(|n| *n += 1);
    drop(arbiter);

    // The image, then the statistics.
    let image = encode_image(entry, frame, job.format).await?;
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

/// The image in the job's format; when that is not PNG, a PNG preview
/// beside it in the journal, for the dashboard.
async fn encode_image(
    entry: &JobEntry,
    frame: Frame,
    format: ImageFormat,
) -> anyhow::Result<Vec<u8>> {
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
    Ok(image)
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
        o.for_each_contribution(|x| frame.add_contribution(x))?;
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

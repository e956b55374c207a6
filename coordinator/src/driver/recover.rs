//! Records at the workers, recovered: when a worker holding a round's
//! records is lost (gone, or stuck past `--task-timeout` on a task that
//! can run only there), only the shards whose records it held are
//! recomputed, not the whole job.
//!
//! With records at the workers, a shard of a later round is cut within
//! the rays one worker spawned, and its tasks run there: a worker's
//! records of round `r` descend from shards of the rounds before that,
//! down to eye rays. The driver keeps that lineage (each round's shards
//! and the run of next-round rays each one spawned). To recover lost
//! shards of round `r`, the shards of every earlier round that led to
//! them are run again, in the same shards (so their outputs are the same
//! records, bit for bit: a ray's outcome depends on the ray alone), all
//! on one other worker, under a job id of their own (the job's id and
//! `.recompute.N`), so that the worker keeps those records apart from the
//! job's and drops none of its own for them. Their colour is thrown away
//! (it is in the frame already); the rays they spawn must be as many as
//! the first time. Then the lost tasks run again on that worker, from the
//! recomputed records. A worker lost during the recomputation costs
//! another one elsewhere; after [`MAX_RECOMPUTATIONS`] in one stage the
//! job starts again from its eye rays, as it did before.

use super::stages::{RecordsLost, Stage};
use super::stats::Totals;
use super::verify::Arbiter;
use crate::task::{Held, Segment, TaskInput, TaskOutput, WorkerTag};
use sray_proto::v1;
use std::sync::Arc;

/// Recomputations a stage may ask for before the job starts again.
const MAX_RECOMPUTATIONS: u32 = 4;

/// A finished round, as a recomputation needs it: its shards, and the
/// next round's rays each one spawned (start and count; none if it
/// spawned none).
pub(super) struct RoundLog {
    pub(super) shards: Vec<(u64, u64)>,
    pub(super) spawned: Vec<Option<(u64, u64)>>,
    /// The worker whose shading of each shard was taken.
    pub(super) by: Vec<WorkerTag>,
}

/// A recomputed shard spawned another count of rays than the first
/// time: the worker that recomputed it, or the one whose output was
/// taken the first time, is wrong (verification decides which, see
/// `held.rs`).
#[derive(Debug)]
pub(super) struct LineageMismatch(pub(super) String);

impl std::fmt::Display for LineageMismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for LineageMismatch {}

/// A job's lineage: its rounds so far, and the workers whose records it
/// no longer counts on.
#[derive(Default)]
pub(super) struct Lineage {
    /// Rounds 1, 2, ... as they finished (records at the workers only).
    pub(super) rounds: Vec<RoundLog>,
    /// Workers (sessions) that lost records of the job or got stuck on a
    /// task that could run only there: what they hold is recomputed, not
    /// waited for.
    pub(super) gone: Vec<String>,
}

/// The records a recomputation left on its worker: the current round's
/// rays (as segments), and for a shading stage, the lost shards'
/// intersections (task ids, in the order of the shards asked for, and
/// their outputs).
pub(super) struct Recomputed {
    pub(super) segments: Vec<Segment>,
    pub(super) intersections: Vec<u64>,
    pub(super) intersect_outs: Vec<TaskOutput>,
}

/// Runs a stage to its end: its outputs, every one there (see
/// [`complete`]), added to `tot`.
pub(super) async fn run_stage(
    stage: &mut Stage<'_>,
    lineage: &mut Lineage,
    tot: &mut Totals,
    arbiter: &mut Arbiter,
) -> anyhow::Result<Vec<(TaskOutput, WorkerTag)>> {
    stage.lost_holders.clone_from(&lineage.gone);
    let outs = stage.run(tot, arbiter).await?;
    let outs = complete(stage, outs, lineage, tot, arbiter).await;
    for g in &stage.lost_holders {
        if !lineage.gone.contains(g) {
            lineage.gone.push(g.clone());
        }
    }
    let outs = outs?;
    for (o, _) in &outs {
        tot.add(o);
    }
    Ok(outs)
}

/// A stage's outputs, every one there: the shards it lost (their task's
/// input was only at a worker that is gone or stuck) and, for an
/// intersection, those whose output stayed at such a worker, are
/// recomputed (see the module's comment) and run again; the stage's
/// `main_ids` name the tasks whose outputs are taken. Fails with
/// [`RecordsLost`] when this cannot be done (no other worker, or too many
/// workers lost), for the job to start again.
async fn complete(
    stage: &mut Stage<'_>,
    mut outs: Vec<Option<(TaskOutput, WorkerTag)>>,
    lineage: &Lineage,
    tot: &mut Totals,
    arbiter: &mut Arbiter,
) -> anyhow::Result<Vec<(TaskOutput, WorkerTag)>> {
    let shared = stage.shared;
    let mut tries = 0;
    loop {
        // Workers whose records are not to be counted on (gone, or stuck).
        let gone = &stage.lost_holders;
        let intersect = stage.stage == v1::Stage::Intersect;
        let lost: Vec<usize> = outs
            .iter()
            .enumerate()
            .filter(|(_, o)| match o {
                None => true,
                // An intersection's results stay where it ran.
                Some((_, w)) => {
                    stage.keep
                        && intersect
                        && (gone.contains(&w.session) || !shared.is_connected(&w.session))
                }
            })
            .map(|(i, _)| i)
            .collect();
        if lost.is_empty() {
            return Ok(outs
                .into_iter()
                .map(|o| o.expect("every shard is done"))
                .collect());
        }
        let what = format!(
            "round {} ({}): the records of {} shard(s) were only at a worker that is gone or stuck",
            stage.round,
            super::stages::stage_name(stage.stage),
            lost.len()
        );
        if tries >= MAX_RECOMPUTATIONS {
            return Err(anyhow::Error::new(RecordsLost(format!(
                "{what}, and {tries} recomputations of them failed"
            ))));
        }
        tries += 1;
        let Some(at) = shared.recompute_worker(gone) else {
            return Err(anyhow::Error::new(RecordsLost(format!(
                "{what}, and no other worker may recompute them"
            ))));
        };
        tot.recomputations += 1;
        let alias = format!(
            "{}.recompute.{:x}",
            stage.entry.id,
            sray_proto::ids::random_u64()
        );
        shared.add_alias(&alias, &stage.entry.id);
        let ranges: Vec<(u64, u64)> = lost.iter().map(|&i| stage.shards[i]).collect();
        let at_name = shared.worker_name(&at);
        stage.entry.log(format!(
            "{what}: they are recomputed on worker {at_name} from the rounds that led to them (not the whole job)"
        ));
        tracing::warn!(job = %stage.entry.id, round = stage.round, shards = lost.len(), worker = %at_name, "records recomputed");
        let mut scratch = Totals::default();
        let shade = !intersect;
        let r = recompute(
            stage,
            lineage,
            &ranges,
            &at,
            &alias,
            shade,
            &mut scratch,
            arbiter,
        )
        .await;
        tot.recomputed_tasks += scratch.tasks;
        let done = match r {
            Ok(d) => d,
            Err(e) if e.is::<RecordsLost>() => {
                // The recomputing worker was lost too: another one.
                stage
                    .entry
                    .log(format!("the recomputation was lost: {e:#}"));
                stage.lost_holders.push(at);
                continue;
            }
            Err(e) => return Err(e),
        };
        // The lost shards again, from the recomputed records.
        let inputs = lost
            .iter()
            .enumerate()
            .map(|(k, &i)| {
                let first = stage.shards[i].0;
                let held = if shade {
                    Held {
                        intersect: Some((done.intersections[k], at.clone())),
                        shard_first: first,
                        pinned: true,
                        ..Held::default()
                    }
                } else if stage.eye {
                    // Eye rays: made wherever the task runs.
                    Held::default()
                } else {
                    Held {
                        rays: Arc::new(done.segments.clone()),
                        shard_first: first,
                        pinned: true,
                        ..Held::default()
                    }
                };
                Arc::new(TaskInput {
                    held,
                    ..input_like(&stage.inputs[i])
                })
            })
            .collect();
        let mut again = Stage {
            shared,
            entry: stage.entry,
            job: stage.job,
            round: stage.round,
            stage: stage.stage,
            eye: stage.eye,
            shards: &ranges,
            inputs,
            main_ids: Vec::new(),
            keep: stage.keep,
            alias: stage.alias.clone(),
            lost_holders: Vec::new(),
        };
        again.lost_holders.clone_from(&stage.lost_holders);
        let redone = again.run(tot, arbiter).await?;
        for g in again.lost_holders {
            if !stage.lost_holders.contains(&g) {
                stage.lost_holders.push(g);
            }
        }
        tot.recomputed_tasks += redone.iter().filter(|o| o.is_some()).count() as u64;
        for (k, o) in redone.into_iter().enumerate() {
            let i = lost[k];
            stage.main_ids[i] = again.main_ids[k];
            outs[i] = o;
        }
    }
}

/// A task input with `i`'s bounds and no records.
fn input_like(i: &TaskInput) -> TaskInput {
    TaskInput {
        rays: None,
        results: None,
        results_offset: 0,
        objects: i.objects,
        model_triangles: i.model_triangles,
        corners: i.corners,
        held: Held::default(),
    }
}

/// Runs again, on the worker `at` and under the job id `alias`, the
/// shards of the rounds before `stage`'s that led to its rays `ranges`
/// (and, for a shading stage, those rays' intersections).
#[allow(clippy::too_many_arguments)]
pub(super) async fn recompute(
    stage: &Stage<'_>,
    lineage: &Lineage,
    ranges: &[(u64, u64)],
    at: &str,
    alias: &str,
    shade: bool,
    tot: &mut Totals,
    arbiter: &mut Arbiter,
) -> anyhow::Result<Recomputed> {
    let need = ancestry(lineage, stage.round, ranges)?;
    let pinned = |rays: &Arc<Vec<Segment>>, round: u32, first: u64| Held {
        rays: rays.clone(),
        intersect: None,
        shard_first: first,
        pinned: true,
        // Eye rays are made where the task runs: there.
        at: (round == 1).then(|| at.to_string()),
    };
    let mut segs: Vec<Segment> = Vec::new();
    for (j, ks) in need.iter().enumerate() {
        let log = &lineage.rounds[j];
        let round = j as u32 + 1;
        let shards: Vec<(u64, u64)> = ks.iter().map(|&k| log.shards[k]).collect();
        let rays = Arc::new(std::mem::take(&mut segs));
        if shards.is_empty() {
            continue;
        }
        let (ids, _) = run_at(
            stage,
            round,
            v1::Stage::Intersect,
            &shards,
            |_, first| pinned(&rays, round, first),
            (at, alias),
            tot,
            arbiter,
        )
        .await?;
        let (shade_ids, outs) = run_at(
            stage,
            round,
            v1::Stage::Shade,
            &shards,
            |k, first| Held {
                intersect: Some((ids[k], at.to_string())),
                shard_first: first,
                pinned: true,
                ..Held::default()
            },
            (at, alias),
            tot,
            arbiter,
        )
        .await?;
        // The same rays as the first time, held at `at` now (their
        // colour is in the frame already).
        for (k, o) in outs.iter().enumerate() {
            let len = o.rays.as_ref().map_or(o.kept_rays, |r| r.len());
            let first = log.spawned[ks[k]];
            if len != first.map_or(0, |f| f.1) {
                return Err(anyhow::Error::new(LineageMismatch(format!(
                    "round {round} shard {} recomputed spawned {len} rays, not {} as the first time",
                    ks[k],
                    first.map_or(0, |f| f.1)
                ))));
            }
            if let Some((start, len)) = first {
                segs.push(Segment {
                    start,
                    len,
                    task: shade_ids[k],
                    session: at.to_string(),
                });
            }
        }
    }
    let mut intersections = Vec::new();
    let mut intersect_outs = Vec::new();
    if shade {
        let rays = Arc::new(segs.clone());
        let round = stage.round;
        (intersections, intersect_outs) = run_at(
            stage,
            round,
            v1::Stage::Intersect,
            ranges,
            |_, first| pinned(&rays, round, first),
            (at, alias),
            tot,
            arbiter,
        )
        .await?;
    }
    Ok(Recomputed {
        segments: segs,
        intersections,
        intersect_outs,
    })
}

/// The shards of each round before `round` that led to its rays
/// `ranges` (spawned rays wanted in the round after them), from the
/// last round back: `need[j]` are shards of round `j + 1`.
pub(super) fn ancestry(
    lineage: &Lineage,
    round: u32,
    ranges: &[(u64, u64)],
) -> anyhow::Result<Vec<Vec<usize>>> {
    let r = round as usize;
    anyhow::ensure!(
        lineage.rounds.len() + 1 >= r,
        "internal: the lineage of round {r} is not known"
    );
    let mut need: Vec<Vec<usize>> = vec![Vec::new(); r - 1];
    let mut want = ranges.to_vec();
    for j in (0..r - 1).rev() {
        let log = &lineage.rounds[j];
        let ks: Vec<usize> = (0..log.shards.len())
            .filter(|&k| {
                log.spawned[k]
                    .is_some_and(|(s, l)| want.iter().any(|&(a, n)| s < a + n && a < s + l))
            })
            .collect();
        want = ks.iter().map(|&k| log.shards[k]).collect();
        need[j] = ks;
    }
    Ok(need)
}

/// Runs a stage of `shards` of round `round` with the inputs `held`
/// names, pinned to the worker `at.0`, under the job id `at.1`; returns
/// its tasks and outputs. Fails with [`RecordsLost`] if that worker is
/// lost.
#[allow(clippy::too_many_arguments)]
pub(super) async fn run_at(
    like: &Stage<'_>,
    round: u32,
    which: v1::Stage,
    shards: &[(u64, u64)],
    held: impl Fn(usize, u64) -> Held,
    (at, alias): (&str, &str),
    tot: &mut Totals,
    arbiter: &mut Arbiter,
) -> anyhow::Result<(Vec<u64>, Vec<TaskOutput>)> {
    let inputs = shards
        .iter()
        .enumerate()
        .map(|(k, &(first, _))| {
            Arc::new(TaskInput {
                held: held(k, first),
                ..input_like(&like.inputs[0])
            })
        })
        .collect();
    let mut s = Stage {
        shared: like.shared,
        entry: like.entry,
        job: like.job,
        round,
        stage: which,
        eye: round == 1,
        shards,
        inputs,
        main_ids: Vec::new(),
        keep: true,
        alias: Some(alias.to_string()),
        lost_holders: Vec::new(),
    };
    let outs = s.run(tot, arbiter).await?;
    let mut got = Vec::with_capacity(outs.len());
    for o in outs {
        let Some((o, w)) = o else {
            return Err(anyhow::Error::new(RecordsLost(format!(
                "the worker recomputing round {round} is gone"
            ))));
        };
        anyhow::ensure!(
            w.session == at,
            "internal: a recomputed task ran elsewhere than its records"
        );
        tot.add(&o);
        got.push(o);
    }
    Ok((s.main_ids, got))
}

//! Verification where the records stay at the workers
//! (`--records-at-workers`).
//!
//! There, the coordinator sees of a task's output only its counts, the
//! colour it adds to the frame, and a digest (BLAKE3) of the records the
//! worker kept (`TaskSummary.kept_digest`: results in ray order, spawned
//! rays in key order, hashed as they would have travelled). A sample of
//! a shard's rays cannot be re-traced elsewhere, as the default mode does
//! (`stages.rs`), for no other party has its rays; so whole shards are
//! checked instead, and a checked shard brings its lineage with it:
//!
//! - **Which.** After a round's shading, each shard is checked with
//!   probability `--verify-fraction`, and so is every worker's first
//!   shard of the job (in round 1, where a check costs one intersection
//!   and one shading).
//! - **Second opinion.** The shard is run again on another worker (`V`),
//!   under a job id of its own (`JOB.verify.N`): the shards of the earlier
//!   rounds that led to its rays are recomputed there first, exactly as a
//!   lost worker's records are (`recover.rs`; each must spawn as many
//!   rays as the first time), then its intersection and shading. The two
//!   outputs must agree bit for bit: the counts (results, hits, rays by
//!   kind, spawned rays and their first and last keys), the digests of
//!   the results and of the spawned rays, and the colour added to each
//!   frame slot. The colour is compared by a fingerprint of the per-slot
//!   sums (a random linear form modulo 2^61 - 1, keyed anew for every
//!   check): workers that keep their records add a slot's contributions
//!   together before sending them, in an order that is theirs, and the
//!   sums are what reaches the frame. Two different sets of sums agree
//!   with probability below 2^-60 per channel.
//! - **Third opinion.** When they disagree (or no other worker may run
//!   the check, or the lineage does not recompute to the same counts),
//!   the coordinator traces the shard and its lineage itself, with the
//!   records here (it is the one party trusted), and quarantines every
//!   worker whose output disagrees with its own: the shard's, the
//!   checker's, or the one whose shading of an earlier shard spawned
//!   another count of rays.
//! - **Redone.** A worker found lying has added colour to the frame in
//!   earlier rounds, and holds records that later rounds descend from;
//!   neither can be told apart from honest work here. So the job starts
//!   again from its eye rays without it (`job_restarts`; at most three
//!   times, as for lost records), and says so in its log.
//!
//! The cost: a checked shard of round `r` makes about `2r` tasks on
//! another worker, run after the round's shading and before the next
//! round (a round's checks at once, each on a worker of its own while
//! there are enough; docs/cluster.md has a measure). A
//! worker that lies on few of its shards is caught with the probability
//! that one of them is checked; the default mode checks a sample of
//! every shard.

use super::prints::{TaskPrint, digest_of, print_of};
use super::recover::{Lineage, LineageMismatch, ancestry, recompute, run_at};
use super::stages::{RecordsLost, Stage, stage_name};
use super::stats::Totals;
use super::verify::Arbiter;
use crate::task::{Held, TaskInput, TaskOutput, WorkerTag};
use sray_engine::bf::RayRec;
use sray_engine::spill::{RecordWriter, Records};
use sray_proto::v1;
use std::collections::HashSet;

/// A shard's intersection and shading, as verification compares them.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Print {
    intersect: TaskPrint,
    shade: TaskPrint,
}

/// The shards of a round to check: each with probability
/// `fraction`, and those of a worker not checked yet in this job
/// (`checked` names them; the first of each).
pub(super) fn pick(fraction: f64, by: &[WorkerTag], checked: &mut HashSet<String>) -> Vec<usize> {
    let mut picks = Vec::new();
    for (i, w) in by.iter().enumerate() {
        let lucky = (sray_proto::ids::random_u64() >> 11) as f64 / (1u64 << 53) as f64;
        if checked.insert(w.session.clone()) || lucky < fraction {
            picks.push(i);
        }
    }
    picks
}

/// Checks shards `picks` of the round whose shading `stage` just ran (see
/// the module's comment): `iprints` are the prints of the shards'
/// intersections as taken, `by` the workers whose intersections were
/// taken, `outs` the shadings taken. Fails with [`RecordsLost`] when a
/// worker was found lying (the job starts again without it).
#[allow(clippy::too_many_arguments)]
pub(super) async fn check_round(
    stage: &Stage<'_>,
    lineage: &Lineage,
    picks: &[usize],
    iprints: &[TaskPrint],
    by: &[String],
    outs: &[(TaskOutput, WorkerTag)],
    tot: &mut Totals,
    arbiter: &mut Arbiter,
) -> anyhow::Result<()> {
    let shared = stage.shared;
    let round = stage.round;
    let mut liars: Vec<(WorkerTag, String)> = Vec::new();
    let avoid_for = |i: usize| {
        let mut avoid: Vec<String> = vec![outs[i].1.session.clone(), by[i].clone()];
        avoid.extend(lineage.gone.iter().cloned());
        avoid
    };
    // The second opinions, all at once, each on a worker of its own
    // while there are enough (each check's tasks run one stage after
    // another; checks on different workers overlap).
    struct Check {
        i: usize,
        key: u64,
        v: Option<String>,
        scratch: Totals,
        arbiter: Arbiter,
    }
    let mut taken: Vec<String> = Vec::new();
    let mut checks: Vec<Check> = picks
        .iter()
        .map(|&i| {
            let avoid = avoid_for(i);
            let spread: Vec<String> = avoid.iter().chain(&taken).cloned().collect();
            let v = shared
                .recompute_worker(&spread)
                .or_else(|| shared.recompute_worker(&avoid));
            taken.extend(v.clone());
            Check {
                i,
                key: sray_proto::ids::random_u64(),
                v,
                scratch: Totals::default(),
                arbiter: Arbiter::new(shared, stage.job),
            }
        })
        .collect();
    let firsts = join_all(
        checks
            .iter_mut()
            .map(|c| async move {
                match &c.v {
                    Some(v) => Some(
                        on_worker(
                            stage,
                            lineage,
                            c.i,
                            v,
                            c.key,
                            &mut c.scratch,
                            &mut c.arbiter,
                        )
                        .await,
                    ),
                    None => None,
                }
            })
            .collect(),
    )
    .await;
    for (c, first) in checks.into_iter().zip(firsts) {
        let i = c.i;
        let key = c.key;
        let shard = stage.shards[i];
        let (out, w) = &outs[i];
        let main = Print {
            intersect: iprints[i].clone(),
            shade: print_of(v1::Stage::Shade, out, key)?,
        };
        // A second opinion: another worker, which recomputes the shard's
        // lineage and runs it (again, on yet another one, if the first
        // was lost).
        let mut avoid = avoid_for(i);
        let mut second = None;
        let mut scratch = c.scratch;
        let mut first = c.v.zip(first);
        loop {
            let (v, r) = match first.take() {
                Some(f) => f,
                None => match shared.recompute_worker(&avoid) {
                    Some(v) => {
                        let r = on_worker(stage, lineage, i, &v, key, &mut scratch, arbiter).await;
                        (v, r)
                    }
                    None => break,
                },
            };
            match r {
                Ok(p) => {
                    second = Some((v, Ok(p)));
                    break;
                }
                // That worker was lost (or stuck): another one.
                Err(e) if e.is::<RecordsLost>() => {
                    avoid.push(v);
                }
                Err(e) if e.is::<LineageMismatch>() => {
                    second = Some((v, Err(format!("{e:#}"))));
                    break;
                }
                Err(e) => return Err(e),
            }
        }
        tot.recomputed_tasks += scratch.tasks;
        tot.verify_seconds += scratch.worker_seconds;
        tot.samples += 1;
        tot.sample_rays += shard.1;
        let what = format!(
            "round {round} shard {i} (rays {}..{})",
            shard.0,
            shard.0 + shard.1
        );
        match &second {
            Some((_, Ok(p))) if *p == main => continue,
            Some((v, r)) => {
                tot.mismatches += 1;
                shared
                    .counters
                    .mismatches
                    .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let how = match r {
                    Ok(_) => "their outputs differ".to_string(),
                    Err(e) => format!("its lineage did not recompute the same: {e}"),
                };
                stage.entry.log(format!(
                    "verification mismatch: {what}: worker {} and worker {} disagree ({how}); the coordinator traces the shard and the rounds that led to it itself to decide",
                    w.name,
                    shared.worker_name(v)
                ));
            }
            None => {}
        }
        // The coordinator's own trace decides.
        tot.local_samples += 1;
        let t1 = std::time::Instant::now();
        let here = here(stage, lineage, i, key, arbiter).await?;
        tot.verify_seconds += t1.elapsed().as_secs_f64();
        let v_tag = second.as_ref().map(|(v, _)| WorkerTag {
            session: v.clone(),
            name: shared.worker_name(v),
        });
        match here {
            Err((x, why)) => liars.push((x, why)),
            Ok(truth) => {
                if main.shade != truth.shade {
                    liars.push((w.clone(), format!("it returned wrong output for {what}")));
                } else if main.intersect != truth.intersect {
                    liars.push((
                        WorkerTag {
                            session: by[i].clone(),
                            name: shared.worker_name(&by[i]),
                        },
                        format!("it returned wrong intersections for {what}"),
                    ));
                }
                match (&second, v_tag) {
                    (Some((_, Ok(p))), Some(v)) if *p != truth => {
                        liars.push((v, format!("its check of {what} was wrong")))
                    }
                    (Some((_, Err(_))), Some(v)) => liars.push((
                        v,
                        format!("its recomputation of the rounds before {what} was wrong"),
                    )),
                    _ => {}
                }
            }
        }
        if !liars.is_empty() {
            if second.is_none() {
                // Found by the coordinator's own check.
                tot.mismatches += 1;
                shared
                    .counters
                    .mismatches
                    .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
            break;
        }
    }
    if liars.is_empty() {
        return Ok(());
    }
    let mut names = Vec::new();
    for (x, why) in &liars {
        if !shared.is_quarantined(x) {
            shared.quarantine(x, why);
        }
        if !tot.quarantined.contains(&x.name) {
            tot.quarantined.push(x.name.clone());
        }
        stage.entry.log(format!(
            "worker {} quarantined for {} s: {why}",
            x.name,
            shared.cfg.quarantine.as_secs()
        ));
        names.push(x.name.clone());
    }
    Err(anyhow::Error::new(RecordsLost(format!(
        "round {round} ({}): worker(s) {} returned wrong output, and with records at the workers the colour they added in earlier rounds and the records they hold cannot be told from honest ones",
        stage_name(stage.stage),
        names.join(", ")
    ))))
}

/// Runs `futs` at once, to the end of each: their outputs, in order.
async fn join_all<F: std::future::Future>(futs: Vec<F>) -> Vec<F::Output> {
    let mut futs: Vec<std::pin::Pin<Box<F>>> = futs.into_iter().map(Box::pin).collect();
    let mut outs: Vec<Option<F::Output>> = futs.iter().map(|_| None).collect();
    std::future::poll_fn(|cx| {
        let mut pending = false;
        for (f, o) in futs.iter_mut().zip(outs.iter_mut()) {
            if o.is_none() {
                match f.as_mut().poll(cx) {
                    std::task::Poll::Ready(v) => *o = Some(v),
                    std::task::Poll::Pending => pending = true,
                }
            }
        }
        if pending {
            std::task::Poll::Pending
        } else {
            std::task::Poll::Ready(())
        }
    })
    .await;
    outs.into_iter()
        .map(|o| o.expect("every future ended"))
        .collect()
}

/// Shard `i` of `stage`'s round run on worker `v`, with the rounds that
/// led to it recomputed there first: its print. The records `v` made
/// for it (under a job id of their own) are let go once it is done.
async fn on_worker(
    stage: &Stage<'_>,
    lineage: &Lineage,
    i: usize,
    v: &str,
    key: u64,
    tot: &mut Totals,
    arbiter: &mut Arbiter,
) -> anyhow::Result<Print> {
    let shared = stage.shared;
    let alias = format!(
        "{}.verify.{:x}",
        stage.entry.id,
        sray_proto::ids::random_u64()
    );
    shared.add_alias(&alias, &stage.entry.id);
    let r = run_on_worker(stage, lineage, i, v, &alias, key, tot, arbiter).await;
    shared.drop_alias(&alias);
    r
}

#[allow(clippy::too_many_arguments)]
async fn run_on_worker(
    stage: &Stage<'_>,
    lineage: &Lineage,
    i: usize,
    v: &str,
    alias: &str,
    key: u64,
    tot: &mut Totals,
    arbiter: &mut Arbiter,
) -> anyhow::Result<Print> {
    let shard = [stage.shards[i]];
    let rec = recompute(stage, lineage, &shard, v, alias, true, tot, arbiter).await?;
    let int_id = rec.intersections[0];
    let (_, shaded) = run_at(
        stage,
        stage.round,
        v1::Stage::Shade,
        &shard,
        |_, first| Held {
            intersect: Some((int_id, v.to_string())),
            shard_first: first,
            pinned: true,
            ..Held::default()
        },
        (v, alias),
        tot,
        arbiter,
    )
    .await?;
    Ok(Print {
        intersect: print_of(v1::Stage::Intersect, &rec.intersect_outs[0], key)?,
        shade: print_of(v1::Stage::Shade, &shaded[0], key)?,
    })
}

/// Shard `i` of `stage`'s round traced here, with the rounds that led to
/// it, from the records here: its print, or the worker whose shading of
/// an earlier shard spawned another count of rays than this trace (and
/// why).
async fn here(
    stage: &Stage<'_>,
    lineage: &Lineage,
    i: usize,
    key: u64,
    arbiter: &mut Arbiter,
) -> anyhow::Result<Result<Print, (WorkerTag, String)>> {
    let r = stage.round;
    let shard = stage.shards[i];
    let need = ancestry(lineage, r, &[shard])?;
    // The spawned rays of the previous round's shards traced here, each
    // from its first ray id in the round after it.
    let mut prev: Vec<(u64, Records<RayRec>)> = Vec::new();
    for (j, ks) in need.iter().enumerate() {
        let log = &lineage.rounds[j];
        let round = j as u32 + 1;
        let mut next = Vec::new();
        for &k in ks {
            let (first, count) = log.shards[k];
            let (_, out) = pair_here(stage, round, first, count, &prev, arbiter).await?;
            let n = out.rays.as_ref().map_or(0, |r| r.len());
            let want = log.spawned[k].map_or(0, |s| s.1);
            if n != want {
                return Ok(Err((
                    log.by[k].clone(),
                    format!(
                        "its shading of round {round} shard {k} spawned {want} rays where the coordinator's own trace spawns {n}"
                    ),
                )));
            }
            if let (Some((start, _)), Some(rays)) = (log.spawned[k], out.rays) {
                next.push((start, rays));
            }
        }
        prev = next;
    }
    let (int, out) = pair_here(stage, r, shard.0, shard.1, &prev, arbiter).await?;
    Ok(Ok(Print {
        intersect: print_of(v1::Stage::Intersect, &int, key)?,
        shade: print_of(v1::Stage::Shade, &out, key)?,
    }))
}

/// The intersection and shading of rays `first .. first + count` of
/// round `round`, traced here: eye rays, or the rays of `prev` (runs of
/// the round's rays, each from its first ray id).
async fn pair_here(
    stage: &Stage<'_>,
    round: u32,
    first: u64,
    count: u64,
    prev: &[(u64, Records<RayRec>)],
    arbiter: &mut Arbiter,
) -> anyhow::Result<(TaskOutput, TaskOutput)> {
    use sray_worker::exec::{Inputs, ResultSlice, Slice};
    let eye = round == 1;
    let rays = || -> anyhow::Result<Option<Slice<RayRec>>> {
        if eye {
            return Ok(None);
        }
        let mut w = RecordWriter::<RayRec>::create(&stage.shared.spill, "verify-rays")?;
        for (start, recs) in prev {
            let lo = first.max(*start);
            let hi = (first + count).min(start + recs.len());
            if lo < hi {
                let mut rd = recs.reader_range(lo - start, hi - lo)?;
                while let Some(x) = rd.next()? {
                    w.push(&x)?;
                }
            }
        }
        anyhow::ensure!(
            w.len() == count,
            "internal: {} of the {count} rays of a shard traced for verification",
            w.len()
        );
        Ok(Some(Slice::whole(Records::File(w.finish()?))))
    };
    let job = stage.job;
    let mut task = v1::Task {
        task_id: 0,
        job_id: stage.entry.id.clone(),
        attempt: 0,
        stage: v1::Stage::Intersect as i32,
        round,
        first_ray: first,
        ray_count: count,
        eye_rays: eye,
        params: Some(job.params),
        scene: Some(v1::SceneRef {
            hash: job.hash.clone(),
        }),
        verification: true,
        keep_output: false,
    };
    let bounds = TaskInput {
        objects: stage.inputs[0].objects,
        model_triangles: stage.inputs[0].model_triangles,
        corners: stage.inputs[0].corners,
        ..TaskInput::default()
    };
    let mut int = arbiter
        .run(
            task.clone(),
            &bounds,
            Inputs {
                rays: rays()?,
                results: None,
            },
        )
        .await?;
    let results = int
        .results
        .take()
        .ok_or_else(|| anyhow::anyhow!("the coordinator's trace made no results"))?;
    // Its print needs the results: hashed before they go to the shading.
    let digest = digest_of(&results)?;
    task.stage = v1::Stage::Shade as i32;
    let out = arbiter
        .run(
            task,
            &bounds,
            Inputs {
                rays: rays()?,
                results: Some(ResultSlice::Bare(Slice::whole(results))),
            },
        )
        .await?;
    int.summary.kept_records = count;
    int.summary.kept_digest = digest;
    Ok((int, out))
}

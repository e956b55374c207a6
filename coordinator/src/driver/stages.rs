//! One stage (intersection or shading) of a round: its shards queued as
//! tasks, each output verified on another worker (or here), stragglers
//! backed up, liars quarantined and their outputs redone, until every
//! shard is done and verified.

use super::job::Job;
use super::stats::Totals;
use super::verify::{Arbiter, Local, Purpose, same_sample};
use crate::jobs::JobEntry;
use crate::state::Shared;
use crate::task::{TaskEvent, TaskInput, TaskOutput, WorkerTag};
use anyhow::bail;
use sray_proto::v1;
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::mpsc;

/// A task's input was only at a worker that is gone (records at the
/// workers), and could not be recomputed: the job starts again.
#[derive(Debug)]
pub(super) struct RecordsLost(pub(super) String);

impl std::fmt::Display for RecordsLost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for RecordsLost {}

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

/// A stage of a round, as it runs.
pub(super) struct Stage<'a> {
    pub(super) shared: &'a Arc<Shared>,
    pub(super) entry: &'a Arc<JobEntry>,
    pub(super) job: &'a Job,
    pub(super) round: u32,
    pub(super) stage: v1::Stage,
    pub(super) eye: bool,
    pub(super) shards: &'a [(u64, u64)],
    pub(super) inputs: Vec<Arc<TaskInput>>,
    /// The shards' tasks in this stage.
    pub(super) main_ids: Vec<u64>,
    /// Outputs stay at the workers ([`crate::config::Config::records_at_workers`]).
    pub(super) keep: bool,
    /// The job id its tasks carry, if not the job's (a recomputation's,
    /// see [`super::recover`]).
    pub(super) alias: Option<String>,
    /// The workers that held the inputs of the tasks this stage lost.
    pub(super) lost_holders: Vec<String>,
}

impl Stage<'_> {
    fn task(&self, first: u64, count: u64, verification: bool) -> v1::Task {
        v1::Task {
            task_id: 0,
            job_id: self.alias.clone().unwrap_or_else(|| self.entry.id.clone()),
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

    /// Traces shard `i`'s sample on the coordinator's own tracer; the
    /// outcome goes to `tx`.
    fn trace_locally(
        &self,
        arbiter: &mut Arbiter,
        i: usize,
        sample: (u64, u64),
        purpose: Purpose,
        tx: &mpsc::UnboundedSender<Local>,
    ) {
        let (s, k) = sample;
        let task = self.task(s, k, true);
        arbiter.trace(task, self.sample_input(i, s), i, sample, purpose, tx);
    }

    /// Queues the stage's tasks and waits until every shard is done and
    /// verified, or lost (`None`: its task's input was only at a worker
    /// that is gone; [`super::recover::complete`] recomputes it); fails on
    /// a task that failed too often, on cancellation, or when no worker
    /// may do the work for too long. The outputs are not added to `tot`.
    pub(super) async fn run(
        &mut self,
        tot: &mut Totals,
        arbiter: &mut Arbiter,
    ) -> anyhow::Result<Vec<Option<(TaskOutput, WorkerTag)>>> {
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
        let mut lost = vec![false; total];
        // Pinned to a worker whose records are not counted on any more
        // (stuck on an earlier task): lost now, not waited for.
        for (i, inp) in self.inputs.iter().enumerate() {
            let (first, count) = self.shards[i];
            if inp.held.pinned
                && inp
                    .held
                    .preferred(first, count)
                    .is_some_and(|h| self.lost_holders.contains(&h))
            {
                lost[i] = true;
                shared.forget_tasks(&[main_ids[i]]);
            }
        }
        // Records at the workers: no sample of a shard can be traced
        // elsewhere; whole shards are checked after the round
        // (`held.rs`).
        let verify = cfg.verify_fraction > 0.0 && !self.keep;
        let mut local_said = false;
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
        while !st
            .iter()
            .zip(&lost)
            .all(|(s, &l)| l || (s.out.is_some() && s.verified))
        {
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
                                    self.trace_locally(arbiter, i, (s, k), Purpose::Verify, &local_tx);
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
                                self.trace_locally(arbiter, i, (s, k), Purpose::Arbitrate(worker, sample), &local_tx);
                            }
                        }
                        None => {}
                    },
                    Some(TaskEvent::Lost { task, error }) => {
                        if let Some(&Kind::Main(i)) = kinds.get(&task)
                            && st[i].out.is_none()
                        {
                            lost[i] = true;
                            let (first, count) = self.shards[i];
                            if let Some(h) = self.inputs[i].held.preferred(first, count)
                                && !self.lost_holders.contains(&h)
                            {
                                // The other tasks pinned to that worker
                                // are lost with it: it is gone, or stuck
                                // and given nothing more, so they would
                                // wait for it for ever.
                                for j in 0..total {
                                    let (f, c) = self.shards[j];
                                    let inp = &self.inputs[j].held;
                                    if !lost[j]
                                        && st[j].out.is_none()
                                        && inp.pinned
                                        && inp.preferred(f, c).as_ref() == Some(&h)
                                    {
                                        lost[j] = true;
                                        shared.forget_tasks(&[self.main_ids[j]]);
                                    }
                                }
                                self.lost_holders.push(h);
                            }
                            self.entry.log(format!(
                                "round {} {} shard {i}: {error}",
                                self.round, self.name()
                            ));
                        }
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
                                self.trace_locally(arbiter, i, (s, k), Purpose::Verify, &local_tx);
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
                            self.trace_locally(arbiter, i, (s, k), Purpose::Verify, &local_tx);
                        }
                    }
                    // Work that no worker may take.
                    for (id, blocked, why) in shared.stranded(&guard.ids) {
                        match kinds.get(&id) {
                            Some(&Kind::Verify(i)) => {
                                if let Some((vid, s, k)) = st[i].verify && vid == id {
                                    shared.forget_tasks(&[id]);
                                    st[i].verify = Some((0, s, k));
                                    self.trace_locally(arbiter, i, (s, k), Purpose::Verify, &local_tx);
                                }
                            }
                            Some(Kind::Main(_)) if blocked > cfg.worker_wait => {
                                if workers == 0 {
                                    bail!(
                                        "no worker has been connected for {} s: start workers with `sray worker --coordinator URL`",
                                        cfg.worker_wait.as_secs()
                                    );
                                }
                                bail!(
                                    "no worker could run a task of round {} ({}) for {} s: {why}",
                                    self.round, self.name(), cfg.worker_wait.as_secs()
                                );
                            }
                            _ => {}
                        }
                    }
                    // The coordinator's own faults (its disk): said once in
                    // the job's log; the job fails if they last.
                    for (_, since, why) in shared.local_faults(&guard.ids) {
                        if !local_said {
                            local_said = true;
                            self.entry.log(format!(
                                "the coordinator cannot keep this job's records ({why}): its tasks wait until it can; no worker is blamed"
                            ));
                        }
                        if since.elapsed() > cfg.worker_wait {
                            bail!(
                                "the coordinator could not keep this job's records for {} s: {why}",
                                cfg.worker_wait.as_secs()
                            );
                        }
                    }
                }
            }
        }
        drop(guard);
        let outs: Vec<Option<(TaskOutput, WorkerTag)>> = st
            .into_iter()
            .zip(lost)
            .map(|(s, l)| match s.out {
                Some(_) if l => Ok(None),
                None => Ok(None),
                Some((o, w)) => Arc::try_unwrap(o)
                    .map(|o| Some((o, w)))
                    .map_err(|_| anyhow::anyhow!("internal: an output is still shared")),
            })
            .collect::<anyhow::Result<_>>()?;
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

pub(super) fn stage_name(s: v1::Stage) -> &'static str {
    match s {
        v1::Stage::Intersect => "intersection",
        v1::Stage::Shade => "shading",
        v1::Stage::Unspecified => "unknown",
    }
}

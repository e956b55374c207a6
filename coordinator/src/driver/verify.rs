//! Verification's judges: the bit-for-bit comparison of a sample with
//! its shard's output, and the coordinator's own tracer, which traces a
//! sample when no other worker may, and decides a mismatch.

use super::job::Job;
use crate::state::Shared;
use crate::task::{TaskInput, TaskOutput, WorkerTag};
use crate::task_output::Receiver;
use anyhow::{Context, bail};
use sray_engine::bf::{BfOptions, Contribution, RayRec, ResultRec, SPAWN_SLOTS, StoreNumber};
use sray_engine::render::RenderOptions;
use sray_engine::spill::RecordWriter;
use sray_proto::v1;
use std::collections::HashMap;
use std::sync::Arc;
use tokio::sync::mpsc;

/// What the coordinator's own trace of a sample is for.
pub(super) enum Purpose {
    /// No other worker could check the shard.
    Verify,
    /// A worker's check disagreed with the shard's output.
    Arbitrate(WorkerTag, Arc<TaskOutput>),
}

/// The outcome of a sample traced here, for shard `shard`'s stage.
pub(super) struct Local {
    pub(super) shard: usize,
    pub(super) sample: (u64, u64),
    pub(super) purpose: Purpose,
    pub(super) result: anyhow::Result<TaskOutput>,
}

/// The coordinator's own tracer for a job, started the first time a
/// sample must be traced here (no other worker, or a mismatch to decide).
pub(super) struct Arbiter {
    shared: Arc<Shared>,
    exec: Option<Arc<sray_worker::exec::Executor>>,
    db: std::path::PathBuf,
    opts: RenderOptions,
    store: StoreNumber,
    hash: String,
}

impl Arbiter {
    pub(super) fn new(shared: &Arc<Shared>, job: &Job) -> Arbiter {
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

    /// Traces shard `i`'s sample here (the verification `task`, of
    /// `input`); the outcome goes to `tx`.
    pub(super) fn trace(
        &mut self,
        task: v1::Task,
        input: Arc<TaskInput>,
        i: usize,
        sample: (u64, u64),
        purpose: Purpose,
        tx: &mpsc::UnboundedSender<Local>,
    ) {
        let exec = self.executor();
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

    /// Runs `task` here on the input records `inputs` (the task's own,
    /// whole), its output checked against the bounds of `bounds`.
    pub(super) async fn run(
        &mut self,
        task: v1::Task,
        bounds: &TaskInput,
        inputs: sray_worker::exec::Inputs,
    ) -> anyhow::Result<TaskOutput> {
        let exec = self.executor();
        run_here(&self.shared, &exec, task, bounds, inputs).await
    }

    /// The coordinator's executor for the job, started the first time.
    fn executor(&mut self) -> Arc<sray_worker::exec::Executor> {
        self.exec
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
            .clone()
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
    use sray_worker::exec::{Inputs, ResultSlice, Slice};
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
    run_here(shared, exec, task, &input, files).await
}

/// Runs one task on the coordinator's own executor from the input
/// records `files`, checking its output as a worker's is checked
/// (against the bounds of `input`).
async fn run_here(
    shared: &Arc<Shared>,
    exec: &sray_worker::exec::Executor,
    task: v1::Task,
    input: &TaskInput,
    files: sray_worker::exec::Inputs,
) -> anyhow::Result<TaskOutput> {
    use sray_worker::exec::{Input, Work};
    let (out_tx, mut out_rx) = mpsc::channel::<v1::TaskOutput>(4);
    let (done_tx, done_rx) = tokio::sync::oneshot::channel();
    let work = Work {
        task: task.clone(),
        input: Input::Files(files),
        out: out_tx,
        done: done_tx,
        fresh: false,
        next: None,
    };
    if !exec.submit(work) {
        bail!("the coordinator's tracer has stopped");
    }
    let mut rx = Receiver::new(shared, &task, input);
    let mut summary = None;
    while let Some(m) = out_rx.recv().await {
        match m.part {
            Some(v1::task_output::Part::Records(c)) => rx.take(c)?,
            Some(v1::task_output::Part::Summary(s)) => summary = Some(s),
            _ => {}
        }
    }
    done_rx
        .await
        .map_err(|_| anyhow::anyhow!("the coordinator's tracer stopped"))?
        .map_err(anyhow::Error::msg)?;
    Ok(rx.finish(summary.context("no summary")?)?)
}

/// Whether `sample` (rays `s .. s + k`) agrees bit for bit with what
/// `main` (a shard from ray `first`) says of those rays.
pub(super) fn same_sample(
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

//! What a task is to the queue, the service and the drivers: its input
//! and where workers hold it, its output as received, who did it, and
//! what its stage hears of it.

use sray_engine::bf::{Contribution, RayRec, ResultRec};
use sray_engine::spill::Records;
use sray_proto::v1;
use std::collections::HashMap;
use std::sync::Arc;

/// A task's input, as `TaskInput` serves it, and the bounds its output
/// must respect.
#[derive(Default)]
pub struct TaskInput {
    /// The round's rays (absent for eye rays, which workers make).
    pub rays: Option<Arc<Records<RayRec>>>,
    /// The shard's results (shading), from record `results_offset` on.
    pub results: Option<Arc<Records<ResultRec>>>,
    pub results_offset: u64,
    pub objects: u64,
    /// The most triangles of any model (the bound of an instance hit's
    /// triangle; the shading checks it against the instance's own model).
    pub model_triangles: u64,
    /// Frame slots (pixel corners, or pixels): the bound of contributions.
    pub corners: u64,
    /// Where workers may hold this input already.
    pub held: Held,
}

/// Which workers hold which records of a stage's input, by the tasks
/// that left them there: what a worker holds is named, not sent.
#[derive(Clone, Default)]
pub struct Held {
    /// The round's rays as the shadings of the previous round spawned
    /// them, in order (the round's ray file is their concatenation).
    pub rays: Arc<Vec<Segment>>,
    /// Shading: the intersection of this shard (its task and the worker
    /// whose output was taken), which holds the shard's rays and results
    /// from the shard's first ray, `shard_first`, on.
    pub intersect: Option<(u64, String)>,
    pub shard_first: u64,
    /// The input is nowhere but at the worker holding it (records at the
    /// workers): the task runs there or, once that worker is gone, fails
    /// as [`TaskEvent::Lost`].
    pub pinned: bool,
    /// The worker that must run the task, whose input is made there (a
    /// recomputation's eye rays, see `driver/recover.rs`).
    pub at: Option<String>,
}

/// Rays `start .. start + len` of a round: the output of task `task`,
/// taken from the worker `session`.
#[derive(Clone, Debug)]
pub struct Segment {
    pub start: u64,
    pub len: u64,
    pub task: u64,
    pub session: String,
}

impl Held {
    /// The worker most of the rays `first .. first + count` are with.
    pub fn preferred(&self, first: u64, count: u64) -> Option<String> {
        if let Some(s) = &self.at {
            return Some(s.clone());
        }
        if let Some((_, s)) = &self.intersect {
            return Some(s.clone());
        }
        let mut best: Option<(u64, &str)> = None;
        let mut by: HashMap<&str, u64> = HashMap::new();
        for g in self.rays.iter() {
            let lo = g.start.max(first);
            let hi = (g.start + g.len).min(first + count);
            if lo < hi {
                let n = by.entry(&g.session).or_default();
                *n += hi - lo;
                if best.is_none_or(|(b, _)| *n > b) {
                    best = Some((*n, &g.session));
                }
            }
        }
        best.map(|(_, s)| s.to_string())
    }
}

/// A task's output, as received.
#[derive(Default)]
pub struct TaskOutput {
    pub results: Option<Records<ResultRec>>,
    pub contributions: Option<Records<Contribution>>,
    /// Colour packed per frame slot (`RECORD_KIND_COLOUR`: from a worker
    /// that keeps its records), the chunks as they came, back to back.
    pub colour: Option<Records<u8>>,
    pub rays: Option<Records<RayRec>>,
    /// Results that hit something (intersection).
    pub hits: u64,
    /// Spawned rays the worker kept instead of sending (shading, with
    /// `Task.keep_output`).
    pub kept_rays: u64,
    pub summary: v1::TaskSummary,
}

impl TaskOutput {
    /// Calls `f` with each contribution of the output: those sent one by
    /// one, then those packed per slot (read as they lie, in memory or in
    /// a spill file's pieces).
    pub fn for_each_contribution(&self, mut f: impl FnMut(&Contribution)) -> anyhow::Result<()> {
        if let Some(c) = &self.contributions {
            c.for_each_slice(&mut |s| {
                s.iter().for_each(&mut f);
                Ok(())
            })?;
        }
        if let Some(p) = &self.colour {
            let mut r = sray_proto::colour::Reader::default();
            let mut bad = None;
            p.for_each_slice(&mut |s| {
                if bad.is_none()
                    && let Err(e) = r.feed(s, &mut |x| {
                        f(&Contribution {
                            corner: x.slot,
                            run: x.run,
                            rgb: x.rgb,
                        })
                    })
                {
                    bad = Some(e);
                }
                Ok(())
            })?;
            match bad {
                Some(e) => return Err(e.into()),
                None => r.finish()?,
            }
        }
        Ok(())
    }
}

/// Who did a piece of work.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct WorkerTag {
    pub session: String,
    pub name: String,
}

/// What a job's driver hears about its tasks.
// One event per task, moved once through a channel: the size difference
// between the variants costs nothing worth a box.
#[allow(clippy::large_enum_variant)]
pub enum TaskEvent {
    Done {
        task: u64,
        shard: usize,
        output: TaskOutput,
        worker: WorkerTag,
    },
    Failed {
        task: u64,
        error: String,
    },
    /// A pinned task's input is gone with its worker.
    Lost {
        task: u64,
        error: String,
    },
}

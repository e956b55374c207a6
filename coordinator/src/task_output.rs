//! A task's output as it arrives from its worker (or from the
//! coordinator's own tracer), checked record by record before anything
//! is kept: results in ray order for exactly the shard's rays,
//! contributions to pixel corners of the image, spawned rays in key order
//! within the keys the shard's rays can spawn.

use crate::state::Shared;
use crate::task::{TaskInput, TaskOutput};
use sray_engine::bf::{Contribution, RayRec, ResultRec};
use sray_engine::spill::RecordsWriter;
use sray_proto::v1;
use sray_proto::wire::{decode_bytes, decode_chunk, records_per_chunk};

/// Takes a task's output records, checking them as they come.
pub(crate) struct Receiver<'a> {
    shared: &'a Shared,
    task: &'a v1::Task,
    input: &'a TaskInput,
    results: Option<RecordsWriter<ResultRec>>,
    contributions: Option<RecordsWriter<Contribution>>,
    colour: Option<RecordsWriter<u8>>,
    rays: Option<RecordsWriter<RayRec>>,
    n_results: u64,
    hits: u64,
    last_key: Option<u64>,
    /// Frame slots the contributions so far add to, runs counted whole.
    slots_added: u64,
}

impl<'a> Receiver<'a> {
    pub(crate) fn new(shared: &'a Shared, task: &'a v1::Task, input: &'a TaskInput) -> Self {
        Receiver {
            shared,
            task,
            input,
            results: None,
            contributions: None,
            colour: None,
            rays: None,
            n_results: 0,
            hits: 0,
            last_key: None,
            slots_added: 0,
        }
    }

    /// Takes a chunk of the output: checked (a fault of the worker's if it
    /// fails), then kept (the coordinator's own, if that fails).
    pub(crate) fn take(&mut self, c: v1::RecordChunk) -> Result<(), OutputError> {
        let recs = self.check(c).map_err(OutputError::Bad)?;
        let local = |e: sray_engine::Error| OutputError::Local(e.to_string());
        match recs {
            Checked::Results(v) => self
                .results
                .get_or_insert_with(|| {
                    RecordsWriter::new(&self.shared.records, &self.shared.spill, "out-results")
                })
                .push_vec(v)
                .map_err(local),
            Checked::Contributions(v) => self
                .contributions
                .get_or_insert_with(|| {
                    RecordsWriter::new(&self.shared.records, &self.shared.spill, "out-contrib")
                })
                .push_vec(v)
                .map_err(local),
            Checked::Colour(v) => self
                .colour
                .get_or_insert_with(|| {
                    RecordsWriter::new(&self.shared.records, &self.shared.spill, "out-colour")
                })
                .push_vec(v)
                .map_err(local),
            Checked::Rays(v) => self
                .rays
                .get_or_insert_with(|| {
                    RecordsWriter::new(&self.shared.records, &self.shared.spill, "out-rays")
                })
                .push_vec(v)
                .map_err(local),
        }
    }

    /// A chunk of the output, decoded and checked.
    fn check(&mut self, c: v1::RecordChunk) -> Result<Checked, String> {
        if c.held.is_some() {
            return Err("an output names held records".into());
        }
        let intersect = self.task.stage == v1::Stage::Intersect as i32;
        match (v1::RecordKind::try_from(c.kind), intersect) {
            (Ok(v1::RecordKind::Results), true) => {
                let v = decode_chunk::<ResultRec>(&c.data, c.raw, records_per_chunk::<ResultRec>())
                    .map_err(|e| e.to_string())?;
                for r in &v {
                    let want = self.task.first_ray + self.n_results;
                    if r.ray != want {
                        return Err(format!("result for ray {} where ray {want} was due", r.ray));
                    }
                    // An instance's hit names its record and a triangle
                    // of a model (checked against the instance's own
                    // model when it is shaded).
                    let past_models = r
                        .prim
                        .instance_parts()
                        .is_some_and(|(_, p)| u64::from(p) >= self.input.model_triangles);
                    if !r.prim.is_none()
                        && (r.prim.world_index() as u64 >= self.input.objects
                            || past_models
                            || !r.t.is_finite())
                    {
                        return Err(format!(
                            "ray {}: no object {} at distance {}",
                            r.ray, r.prim.0, r.t
                        ));
                    }
                    self.hits += !r.prim.is_none() as u64;
                    self.n_results += 1;
                }
                if self.n_results > self.task.ray_count {
                    return Err("more results than rays".into());
                }
                Ok(Checked::Results(v))
            }
            (Ok(v1::RecordKind::Contributions), false) => {
                let v = decode_chunk::<Contribution>(
                    &c.data,
                    c.raw,
                    records_per_chunk::<Contribution>(),
                )
                .map_err(|e| e.to_string())?;
                if let Some(bad) = v.iter().find(|x| x.end() > self.input.corners) {
                    return Err(format!(
                        "a contribution to pixel corners {}..{} of {}",
                        bad.corner,
                        bad.end(),
                        self.input.corners
                    ));
                }
                // Runs come only from a worker that keeps its records
                // (nothing compares its contributions one by one), and a
                // ray adds its colour to one slot at most: a shard's
                // contributions cover no more slots than it has rays, so
                // a few bytes can never ask for unbounded work here.
                if !self.task.keep_output && v.iter().any(|x| x.run != 0) {
                    return Err("a run of contributions from a task whose output is checked".into());
                }
                self.slots_added += v.iter().map(|x| x.run as u64 + 1).sum::<u64>();
                if self.slots_added > self.task.ray_count {
                    return Err(format!(
                        "contributions to {} frame slots from a shard of {} rays",
                        self.slots_added, self.task.ray_count
                    ));
                }
                Ok(Checked::Contributions(v))
            }
            (Ok(v1::RecordKind::Colour), false) => {
                // Packed per slot: only from a worker that keeps its
                // records, as runs are. Read through once here, for the
                // same bounds as contributions; kept as it came.
                if !self.task.keep_output {
                    return Err("packed colour from a task whose output is checked".into());
                }
                let data = decode_bytes(&c.data, c.raw, sray_proto::colour::MAX_CHUNK_BYTES)
                    .map_err(|e| e.to_string())?;
                let mut r = sray_proto::colour::Reader::new(self.input.corners);
                r.feed(&data, &mut |_| ())
                    .and_then(|()| r.finish())
                    .map_err(|e| e.to_string())?;
                self.slots_added += r.slots;
                if self.slots_added > self.task.ray_count {
                    return Err(format!(
                        "contributions to {} frame slots from a shard of {} rays",
                        self.slots_added, self.task.ray_count
                    ));
                }
                Ok(Checked::Colour(data))
            }
            (Ok(v1::RecordKind::Rays), false) => {
                let v = decode_chunk::<RayRec>(&c.data, c.raw, records_per_chunk::<RayRec>())
                    .map_err(|e| e.to_string())?;
                let slots = sray_engine::bf::SPAWN_SLOTS;
                let lo = self.task.first_ray * slots;
                let hi = (self.task.first_ray + self.task.ray_count) * slots;
                for r in &v {
                    if r.key < lo || r.key >= hi || self.last_key.is_some_and(|k| r.key <= k) {
                        return Err(format!("spawned ray key {} out of order or range", r.key));
                    }
                    if r.corner as u64 >= self.input.corners
                        || !r.o.iter().chain(&r.d).all(|x| x.is_finite())
                    {
                        return Err(format!("spawned ray {} is malformed", r.key));
                    }
                    self.last_key = Some(r.key);
                }
                Ok(Checked::Rays(v))
            }
            _ => Err(format!(
                "record kind {} does not belong in this stage's output",
                c.kind
            )),
        }
    }

    /// The output, once its summary came: checked, then its records kept.
    pub(crate) fn finish(self, summary: v1::TaskSummary) -> Result<TaskOutput, OutputError> {
        self.check_summary(&summary).map_err(OutputError::Bad)?;
        let local = |e: sray_engine::Error| OutputError::Local(e.to_string());
        let (kept_rays, hits) = self.kept_counts(&summary);
        Ok(TaskOutput {
            results: self
                .results
                .map(|w| w.finish())
                .transpose()
                .map_err(local)?,
            contributions: self
                .contributions
                .map(|w| w.finish())
                .transpose()
                .map_err(local)?,
            colour: self.colour.map(|w| w.finish()).transpose().map_err(local)?,
            rays: self.rays.map(|w| w.finish()).transpose().map_err(local)?,
            hits,
            kept_rays,
            summary,
        })
    }

    /// Spawned rays kept at the worker, and the hits of the results.
    fn kept_counts(&self, summary: &v1::TaskSummary) -> (u64, u64) {
        let intersect = self.task.stage == v1::Stage::Intersect as i32;
        match (self.task.keep_output, intersect) {
            (true, true) => (0, summary.kept_hits),
            (true, false) => (summary.kept_records, self.hits),
            (false, _) => (0, self.hits),
        }
    }

    fn check_summary(&self, summary: &v1::TaskSummary) -> Result<(), String> {
        let intersect = self.task.stage == v1::Stage::Intersect as i32;
        if self.task.keep_output {
            // Results or spawned rays stayed at the worker: their counts.
            if self.results.is_some() || self.rays.is_some() {
                return Err("records sent that were to be kept".into());
            }
            if intersect {
                if summary.kept_records != self.task.ray_count {
                    return Err(format!(
                        "{} results kept for {} rays",
                        summary.kept_records, self.task.ray_count
                    ));
                }
                if summary.kept_hits > summary.kept_records {
                    return Err("more hits than results".into());
                }
            } else {
                let slots = sray_engine::bf::SPAWN_SLOTS;
                let lo = self.task.first_ray * slots;
                let hi = (self.task.first_ray + self.task.ray_count) * slots;
                let (a, b) = (summary.kept_first_key, summary.kept_last_key);
                let n = summary.kept_records;
                if n > 0 && (a < lo || b >= hi || a > b || n > b - a + 1) {
                    return Err(format!("kept spawned rays' keys {a}..={b} out of range"));
                }
            }
        } else if intersect && self.n_results != self.task.ray_count {
            return Err(format!(
                "{} results for {} rays",
                self.n_results, self.task.ray_count
            ));
        }
        sray_engine::shapes::KindCounts::default()
            .add_named(summary.tests_by_kind.iter().map(|(k, &n)| (k.as_str(), n)))?;
        Ok(())
    }
}

/// A chunk of output records, checked.
enum Checked {
    Results(Vec<ResultRec>),
    Contributions(Vec<Contribution>),
    Colour(Vec<u8>),
    Rays(Vec<RayRec>),
}

/// Why an output was not taken: the worker's fault (it is bad), or the
/// coordinator's own (it could not keep it: its disk).
#[derive(Debug)]
pub enum OutputError {
    Bad(String),
    Local(String),
}

impl std::fmt::Display for OutputError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            OutputError::Bad(e) => f.write_str(e),
            OutputError::Local(e) => write!(f, "the coordinator cannot keep the output: {e}"),
        }
    }
}

impl std::error::Error for OutputError {}

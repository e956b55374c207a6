//! A job's totals, kept over its rounds (and journaled with every
//! checkpoint), and the statistics it ends with.

use super::job::Job;
use crate::jobs::JobEntry;
use crate::state::Shared;
use crate::task::TaskOutput;
use sray_engine::render::{KindCounts, RayCounts, RenderStats};
use std::collections::BTreeMap;

/// Totals over a job (journaled with every checkpoint).
#[derive(Default, serde::Serialize, serde::Deserialize)]
pub(super) struct Totals {
    pub(super) eye_hit_rays: u64,
    pub(super) reflect_rays: u64,
    pub(super) refract_rays: u64,
    pub(super) shadow_rays: u64,
    pub(super) tests: BTreeMap<String, u64>,
    pub(super) hits: u64,
    pub(super) tasks: u64,
    pub(super) worker_seconds: f64,
    pub(super) intersect_seconds: f64,
    pub(super) shade_seconds: f64,
    pub(super) max_workers: usize,
    pub(super) rays_per_round: Vec<u64>,
    pub(super) shards_per_round: Vec<u64>,
    pub(super) passes: Vec<Vec<u64>>,
    /// Verification: samples checked, their rays, samples traced by the
    /// coordinator itself, mismatches, workers quarantined for lying,
    /// outputs redone.
    pub(super) samples: u64,
    pub(super) sample_rays: u64,
    pub(super) shard_rays: u64,
    pub(super) local_samples: u64,
    pub(super) mismatches: u64,
    pub(super) quarantined: Vec<String>,
    pub(super) redone: u64,
    pub(super) backups: u64,
    /// Seconds workers (and the coordinator) spent tracing samples.
    #[serde(default)]
    pub(super) verify_seconds: f64,
    /// Passes over the objects made by shading tasks: none when every
    /// shard's results stayed, with their surfaces, on the worker that
    /// found them.
    #[serde(default)]
    pub(super) shading_scans: u64,
    /// Tasks for which a worker had to build its grids.
    #[serde(default)]
    pub(super) grid_builds: u64,
    /// Times the job started again from its eye rays (records lost with
    /// a worker).
    #[serde(default)]
    pub(super) restarts: u32,
    /// Lost records recovered (records at the workers): recomputations
    /// (each for one stage's lost shards), and the tasks they ran (those
    /// of the earlier rounds, and the lost ones again).
    #[serde(default)]
    pub(super) recomputations: u32,
    #[serde(default)]
    pub(super) recomputed_tasks: u64,
    /// Seconds spent writing checkpoints (between rounds).
    #[serde(default)]
    pub(super) checkpoint_seconds: f64,
}

impl Totals {
    pub(super) fn add(&mut self, o: &TaskOutput) {
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

/// The counts the coordinator reads from a task's statistics (which it
/// keeps as they are otherwise): read into these fields alone, every task's
/// statistics are skimmed, not built into a tree.
#[derive(serde::Deserialize, Default)]
#[serde(default)]
pub(super) struct TaskCounts {
    /// An intersection's passes over the objects.
    pub passes: Option<u64>,
    /// Scans of the objects (a shading's joins).
    pub db_scans: Option<u64>,
}

impl TaskCounts {
    /// The counts of a task's statistics; none if they do not parse.
    pub fn of(stats_json: &str) -> TaskCounts {
        serde_json::from_str(stats_json).unwrap_or_default()
    }
}

pub(super) fn job_stats(
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
        "recomputations": tot.recomputations,
        "recomputed_tasks": tot.recomputed_tasks,
        "backup_tasks": backups.max(tot.backups),
        "worker_seconds": tot.worker_seconds,
        "checkpoint_seconds": tot.checkpoint_seconds,
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

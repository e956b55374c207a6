//! What the cluster is doing, for operators: the `Status` call (`sray
//! status`), and the JSON the dashboard polls (`/api/status`), both made
//! from one snapshot so that they always agree.

use crate::state::Shared;
use serde_json::{Value, json};
use sray_proto::v1;

/// Workers (by id) and jobs (oldest first), now.
pub fn snapshot(shared: &Shared) -> v1::StatusReply {
    let mut jobs: Vec<v1::JobStatus> = shared.jobs.all().iter().map(|e| e.status()).collect();
    jobs.sort_by(|a, b| (a.submitted_unix, &a.id).cmp(&(b.submitted_unix, &b.id)));
    let (queued, _, _) = shared.task_counts();
    v1::StatusReply {
        workers: shared.worker_status(),
        jobs,
        run_id: shared.run_id.clone(),
        uptime_seconds: shared.uptime().as_secs_f64(),
        queued_tasks: queued,
    }
}

pub fn stage_name(stage: i32) -> &'static str {
    match v1::Stage::try_from(stage) {
        Ok(v1::Stage::Intersect) => "intersect",
        Ok(v1::Stage::Shade) => "shade",
        _ => "",
    }
}

/// The snapshot as one JSON object: `workers` and `jobs` (arrays), and
/// the coordinator's `run_id`, `uptime_seconds` and `queued_tasks`.
pub fn to_json(r: &v1::StatusReply) -> Value {
    let workers: Vec<Value> = r
        .workers
        .iter()
        .map(|w| {
            json!({
                "id": w.id,
                "name": w.name,
                "address": w.address,
                "state": w.state,
                "tasks": w.tasks,
                "memory_bytes": w.memory_bytes,
                "threads": w.threads,
                "tasks_done": w.tasks_done,
                "failures": w.failures,
                "quarantined": w.quarantined,
                "last_seen_seconds": w.last_seen_seconds,
            })
        })
        .collect();
    let opt = |t: u64| if t == 0 { Value::Null } else { t.into() };
    let jobs: Vec<Value> = r
        .jobs
        .iter()
        .map(|j| {
            json!({
                "id": j.id,
                "scene": j.scene,
                "width": j.width,
                "height": j.height,
                "samples": j.samples,
                "max_depth": j.max_depth,
                "state": j.state,
                "error": if j.error.is_empty() { Value::Null } else { j.error.clone().into() },
                "round": j.round,
                "stage": stage_name(j.stage),
                "progress_percent": j.progress_percent,
                "eta_seconds": if j.eta_seconds < 0.0 { Value::Null } else { j.eta_seconds.into() },
                "submitted_unix": opt(j.submitted_unix),
                "started_unix": opt(j.started_unix),
                "finished_unix": opt(j.finished_unix),
                "rounds": j.rounds.iter().map(|r| json!({
                    "round": r.round,
                    "rays": r.rays,
                    "shards": r.shards,
                    "intersect_done": r.intersect_done,
                    "shade_done": r.shade_done,
                })).collect::<Vec<_>>(),
                "log": j.log,
            })
        })
        .collect();
    json!({
        "workers": workers,
        "jobs": jobs,
        "run_id": r.run_id,
        "uptime_seconds": r.uptime_seconds,
        "queued_tasks": r.queued_tasks,
    })
}

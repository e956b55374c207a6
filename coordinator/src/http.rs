//! `--http-listen ADDR`: the coordinator's optional HTTP listener for
//! operators (off by default).
//!
//! - `GET /healthz`: 200 `ok` while serving, 503 once stopping;
//! - `GET /metrics`: Prometheus metrics, every name prefixed `sray_`: in
//!   the classic text format (0.0.4), or OpenMetrics text when the
//!   scraper's `Accept` header asks for it;
//! - `GET /api/status`: what `sray status --json` prints;
//! - `GET /jobs/{id}/preview.png`: a job's image as far as it is done (the
//!   last finished round's frame, or the finished image);
//! - `GET /`: a dashboard that polls `/api/status` every second.
//!
//! There is **no authentication** here, by choice: health probes and
//! Prometheus scrapers carry no token, and nothing served lets a caller
//! act on the cluster (job secrets are never shown; a job id alone can
//! neither fetch the final image over gRPC nor cancel the job). It does
//! show job ids, progress and preview images: bind it to loopback (the
//! examples use 127.0.0.1) or a private network, or put an authenticating
//! proxy in front. A non-loopback address is warned about at start.

use crate::state::Shared;
use axum::Router;
use axum::extract::{Path, State};
use axum::http::{StatusCode, header};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use prometheus_client::encoding::text::encode;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use tokio::net::TcpListener;

const DASHBOARD: &str = include_str!("dashboard.html");

/// The routes, over the coordinator's state.
pub fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(dashboard))
        .route("/healthz", get(healthz))
        .route("/metrics", get(metrics))
        .route("/api/status", get(status))
        .route("/jobs/{id}/preview.png", get(preview))
        .with_state(shared)
}

/// Serves until `shutdown` completes.
pub async fn serve(
    shared: Arc<Shared>,
    listener: TcpListener,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    axum::serve(listener, router(shared))
        .with_graceful_shutdown(shutdown)
        .await
}

async fn dashboard() -> Html<&'static str> {
    Html(DASHBOARD)
}

async fn healthz(State(shared): State<Arc<Shared>>) -> (StatusCode, &'static str) {
    if shared.is_stopping() {
        (StatusCode::SERVICE_UNAVAILABLE, "stopping\n")
    } else {
        (StatusCode::OK, "ok\n")
    }
}

async fn status(State(shared): State<Arc<Shared>>) -> Response {
    let r = crate::status::snapshot(&shared);
    (
        [(header::CACHE_CONTROL, "no-store")],
        axum::Json(crate::status::to_json(&r)),
    )
        .into_response()
}

async fn preview(State(shared): State<Arc<Shared>>, Path(id): Path<String>) -> Response {
    if !sray_proto::ids::is_hex_id(&id, 32) {
        return (StatusCode::BAD_REQUEST, "not a job id\n").into_response();
    }
    let Some(e) = shared.jobs.find(&id) else {
        return (StatusCode::NOT_FOUND, "no such job here\n").into_response();
    };
    match tokio::task::spawn_blocking(move || e.preview_png()).await {
        Ok(Ok(png)) => (
            [
                (header::CONTENT_TYPE, "image/png"),
                (header::CACHE_CONTROL, "no-store"),
            ],
            png.as_ref().clone(),
        )
            .into_response(),
        Ok(Err(e)) => (StatusCode::NOT_FOUND, format!("no preview: {e:#}\n")).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("{e}\n")).into_response(),
    }
}

type Labels = Vec<(&'static str, &'static str)>;

fn counter(reg: &mut Registry, name: &str, help: &str, v: u64) {
    let c: Counter = Counter::default();
    c.inc_by(v);
    reg.register(name, help, c);
}

fn counters(
    reg: &mut Registry,
    name: &str,
    help: &str,
    label: &'static str,
    v: &[(&'static str, u64)],
) {
    let f: Family<Labels, Counter> = Family::default();
    for (l, n) in v {
        f.get_or_create(&vec![(label, *l)]).inc_by(*n);
    }
    reg.register(name, help, f);
}

fn gauges(
    reg: &mut Registry,
    name: &str,
    help: &str,
    label: &'static str,
    v: &[(&'static str, i64)],
) {
    let f: Family<Labels, Gauge> = Family::default();
    for (l, n) in v {
        f.get_or_create(&vec![(label, *l)]).set(*n);
    }
    reg.register(name, help, f);
}

fn gauge(reg: &mut Registry, name: &str, help: &str, v: i64) {
    let g: Gauge = Gauge::default();
    g.set(v);
    reg.register(name, help, g);
}

/// The metrics, made afresh from the coordinator's state at every scrape
/// (nothing is kept between scrapes; counters come from the state's own).
pub fn metrics_text(shared: &Shared) -> Result<String, std::fmt::Error> {
    let mut reg = Registry::with_prefix("sray");
    let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
    let c = &shared.counters;
    let workers = shared.worker_status();
    let by = |s: &str| workers.iter().filter(|w| w.state == s).count() as i64;
    gauges(
        &mut reg,
        "workers",
        "Registered workers by state (idle, busy, quarantined)",
        "state",
        &[
            ("idle", by("idle")),
            ("busy", by("busy")),
            ("quarantined", by("quarantined")),
        ],
    );
    counter(
        &mut reg,
        "workers_registered",
        "Worker registrations",
        load(&c.workers_registered),
    );
    let mut jobs = [0i64; 3];
    for e in shared.jobs.all() {
        jobs[match e.view().state {
            crate::jobs::JobState::Running => 0,
            crate::jobs::JobState::Done => 1,
            crate::jobs::JobState::Failed(_) => 2,
        }] += 1;
    }
    gauges(
        &mut reg,
        "jobs",
        "Jobs by state (finished ones while they are kept)",
        "state",
        &[("running", jobs[0]), ("done", jobs[1]), ("failed", jobs[2])],
    );
    counter(
        &mut reg,
        "jobs_submitted",
        "Jobs accepted",
        load(&c.jobs_submitted),
    );
    counters(
        &mut reg,
        "jobs_finished",
        "Jobs ended, by outcome",
        "outcome",
        &[
            ("done", load(&c.jobs_done)),
            ("failed", load(&c.jobs_failed)),
        ],
    );
    counters(
        &mut reg,
        "tasks_completed",
        "Tasks completed, by stage (verification samples included)",
        "stage",
        &[
            ("intersect", load(&c.tasks_intersect)),
            ("shade", load(&c.tasks_shade)),
        ],
    );
    counters(
        &mut reg,
        "rays",
        "Rays of completed tasks, by stage (rate() gives rays per second)",
        "stage",
        &[
            ("intersect", load(&c.rays_intersected)),
            ("shade", load(&c.rays_shaded)),
        ],
    );
    counters(
        &mut reg,
        "tasks_given",
        "Tasks given to workers, by how the worker asked: a NextTask call, or with its previous output",
        "asked",
        &[
            ("next_task", load(&c.given_on_request)),
            ("with_output", load(&c.given_with_output)),
        ],
    );
    counters(
        &mut reg,
        "task_inputs",
        "Task inputs sent, by how: with the task (records the worker holds), or streamed by a TaskInput call",
        "how",
        &[
            ("inline", load(&c.inputs_inline)),
            ("streamed", load(&c.inputs_streamed)),
        ],
    );
    counter(
        &mut reg,
        "verification_tasks",
        "Verification samples completed by workers",
        load(&c.tasks_verification),
    );
    counter(
        &mut reg,
        "verification_mismatches",
        "Verification samples that disagreed with a shard's output",
        load(&c.mismatches),
    );
    counter(
        &mut reg,
        "tasks_failed",
        "Task attempts that workers reported failed",
        load(&c.tasks_failed),
    );
    let (queued, running, requeued) = shared.task_counts();
    counter(
        &mut reg,
        "tasks_requeued",
        "Tasks queued again (a worker lost or failed, an output redone)",
        requeued,
    );
    gauge(
        &mut reg,
        "queue_depth",
        "Tasks waiting for a worker",
        queued as i64,
    );
    gauge(
        &mut reg,
        "tasks_running",
        "Tasks with an attempt running",
        running as i64,
    );
    let [to, from, scene, chunks] = shared.traffic.snapshot();
    counters(
        &mut reg,
        "wire_bytes",
        "Record bytes on the wire, by direction (protocol framing not counted)",
        "direction",
        &[("to_workers", to), ("from_workers", from)],
    );
    counter(
        &mut reg,
        "scene_bytes_served",
        "Scene bytes served to workers",
        scene,
    );
    counter(
        &mut reg,
        "scene_chunks_served",
        "Scene chunks served to workers",
        chunks,
    );
    gauge(
        &mut reg,
        "uptime_seconds",
        "Seconds since the coordinator started",
        shared.uptime().as_secs() as i64,
    );
    let mut out = String::new();
    encode(&mut out, &reg)?;
    Ok(out)
}

/// OpenMetrics text to a scraper whose `Accept` header names it (as
/// Prometheus's own does), the classic text format (0.0.4) to every other:
/// a classic parser reads a counter's `# TYPE` by the name of its samples,
/// which OpenMetrics gives without the `_total` they carry.
async fn metrics(State(shared): State<Arc<Shared>>, headers: axum::http::HeaderMap) -> Response {
    let openmetrics = headers
        .get_all(header::ACCEPT)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .any(|v| v.contains("application/openmetrics-text"));
    match metrics_text(&shared) {
        Ok(text) if openmetrics => (
            [(
                header::CONTENT_TYPE,
                "application/openmetrics-text; version=1.0.0; charset=utf-8",
            )],
            text,
        )
            .into_response(),
        Ok(text) => (
            [(
                header::CONTENT_TYPE,
                "text/plain; version=0.0.4; charset=utf-8",
            )],
            classic_text(&text),
        )
            .into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("{e}\n")).into_response(),
    }
}

/// OpenMetrics text as the classic Prometheus text format: a counter
/// family's `# HELP` and `# TYPE` name its samples (`NAME_total`), as a
/// classic parser needs to type them, and there is no `# EOF`.
pub fn classic_text(openmetrics: &str) -> String {
    // The counter families, by the name their `# TYPE` gives.
    let counters: std::collections::HashSet<&str> = openmetrics
        .lines()
        .filter_map(|l| l.strip_prefix("# TYPE ")?.strip_suffix(" counter"))
        .collect();
    let mut out = String::with_capacity(openmetrics.len() + 16 * counters.len());
    for line in openmetrics.lines() {
        if line == "# EOF" {
            continue;
        }
        let meta = ["# HELP ", "# TYPE ", "# UNIT "]
            .into_iter()
            .find_map(|p| Some((p, line.strip_prefix(p)?)));
        match meta {
            Some(("# UNIT ", _)) => continue,
            Some((p, rest)) => {
                let (name, tail) = rest.split_once(' ').unwrap_or((rest, ""));
                if counters.contains(name) && !name.ends_with("_total") {
                    out.push_str(&format!("{p}{name}_total {tail}"));
                } else {
                    out.push_str(line);
                }
            }
            None => out.push_str(line),
        }
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn classic_text_types_counters_by_their_samples_names() {
        let om = "# HELP sray_rays Rays.\n# TYPE sray_rays counter\nsray_rays_total{stage=\"shade\"} 3\n\
                  # HELP sray_queue_depth Tasks.\n# TYPE sray_queue_depth gauge\nsray_queue_depth 1\n# EOF\n";
        assert_eq!(
            super::classic_text(om),
            "# HELP sray_rays_total Rays.\n# TYPE sray_rays_total counter\nsray_rays_total{stage=\"shade\"} 3\n\
             # HELP sray_queue_depth Tasks.\n# TYPE sray_queue_depth gauge\nsray_queue_depth 1\n"
        );
    }
}

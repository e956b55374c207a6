//! Cluster scaling on this machine: the embedded breadth-first render
//! against one and two local worker processes, with the traffic per ray
//! and per hit, against the goals of a cheap wire (issue 17): one local
//! worker at most [`GOAL_ONE_WORKER`] times the embedded time, at most
//! [`GOAL_BYTES_PER_RAY`] bytes on the wire per ray.

use super::report::{Report, num};
use super::{Ctx, Plan, chart, exec};
use sray_engine::spd::SpdScene;

/// (label, extra arguments).
const SETUPS: [(&str, &[&str]); 3] = [
    (
        "embedded bf, 2 threads",
        &["--mode", "bf", "--threads", "2"],
    ),
    (
        "1 local worker, 2 threads",
        &["--local-workers", "1", "--threads", "2"],
    ),
    (
        "2 local workers, 1 thread each",
        &["--local-workers", "2", "--threads", "2"],
    ),
];

/// One local worker's wall time over the embedded breadth-first render's.
pub const GOAL_ONE_WORKER: f64 = 1.15;
/// Bytes of records on the wire per ray traced.
pub const GOAL_BYTES_PER_RAY: f64 = 64.0;

fn met(ok: bool) -> &'static str {
    if ok { "met" } else { "NOT met" }
}

fn scenes(ctx: &Ctx) -> Vec<(SpdScene, u32)> {
    if ctx.quick {
        vec![(SpdScene::Balls, 2), (SpdScene::Tetra, 4)]
    } else {
        vec![
            (SpdScene::Balls, 4),
            (SpdScene::Rings, 7),
            (SpdScene::Tetra, 9),
        ]
    }
}

pub(super) fn plan(ctx: &Ctx) -> Plan {
    let steps = scenes(ctx).len() * SETUPS.len();
    Plan {
        steps,
        seconds: (steps * ctx.runs) as f64 * if ctx.quick { 0.5 } else { 3.0 },
    }
}

pub(super) fn run(ctx: &Ctx, r: &mut Report) -> anyhow::Result<()> {
    let side = ctx.side();
    r.section("Cluster: local workers and traffic");
    r.para(&format!(
        "{side}x{side}, depth 5, whole processes, medians of {} run(s), the setups taking turns run \
         by run; \"time vs embedded\" is the median of the ratios of runs made one right after the \
         other. The two cores of this machine are \
         shared between the workers. Throughput counts every ray traced (eye, shadow, reflection, \
         refraction) per second of wall time, start-up included. Traffic counts the records \
         exchanged with the workers (rays, results, contributions), not the scene's one-time \
         distribution, which the local workers skip (they share the database file). Local \
         workers keep their results and spawned rays (records at the workers): what travels is \
         colour and counts, sent raw (on one machine compressing costs more than it saves).",
        ctx.runs
    ));
    let mut rows = Vec::new();
    let mut data = Vec::new();
    let mut cats = Vec::new();
    let mut goals = Vec::new();
    let mut series: Vec<(String, Vec<f64>)> = SETUPS
        .iter()
        .map(|(l, _)| (l.to_string(), Vec::new()))
        .collect();
    for (scene, size) in scenes(ctx) {
        let name = format!("{}{size}", scene.name());
        cats.push(name.clone());
        let sdb = ctx.scene_file(scene, size, "sdb")?;
        // The setups take turns, run by run, so that a slow spell of this
        // shared machine weighs on all of them alike; each setup's time
        // against the embedded render is the median of the ratios of
        // runs made one right after the other.
        let args_of = |extra: &[&str]| -> Vec<String> {
            let mut args: Vec<String> = vec![
                sdb.display().to_string(),
                "-o".into(),
                ctx.work().join("scaling.png").display().to_string(),
                "--width".into(),
                side.to_string(),
                "--height".into(),
                side.to_string(),
            ];
            args.extend(extra.iter().map(|s| s.to_string()));
            args
        };
        let mut runs: Vec<Vec<exec::Measured>> = vec![Vec::new(); SETUPS.len()];
        for k in 0..ctx.runs.max(1) {
            for (si, (label, extra)) in SETUPS.iter().enumerate() {
                if k == 0 {
                    ctx.step(&format!("scaling: {name}, {label} (setups take turns)"));
                }
                runs[si].push(exec::sray_render(&args_of(extra), ctx.work())?);
            }
        }
        let base_runs: Vec<f64> = runs[0].iter().map(|m| m.seconds).collect();
        let mut base_rate = f64::NAN;
        for (si, ((label, _), all)) in SETUPS.iter().zip(runs).enumerate() {
            let vs_base = exec::median(
                all.iter()
                    .zip(&base_runs)
                    .map(|(m, b)| m.seconds / b)
                    .collect(),
            );
            let m = exec::Median::of(all);
            let st = m.stats();
            let rays: f64 = ["eye_rays", "reflect_rays", "refract_rays", "shadow_rays"]
                .iter()
                .map(|k| st[k].as_f64().unwrap_or(0.0))
                .sum();
            let rate = rays / m.seconds();
            let bpr = st["bytes_per_ray"].as_f64().unwrap_or(f64::NAN);
            if si == 0 {
                base_rate = rate;
            }
            if si == 1 {
                goals.push(format!(
                    "{name}: one local worker takes {} the embedded time (goal at most {GOAL_ONE_WORKER}: {}); \
                     {} bytes per ray on the wire (goal at most {GOAL_BYTES_PER_RAY}: {})",
                    num(vs_base, 2),
                    met(vs_base <= GOAL_ONE_WORKER),
                    num(bpr, 1),
                    met(bpr <= GOAL_BYTES_PER_RAY),
                ));
            }
            series[si].1.push(rate / 1e6);
            rows.push(vec![
                name.clone(),
                label.to_string(),
                num(m.seconds(), 2),
                num(rate / 1e6, 3),
                num(rate / base_rate, 2),
                num(vs_base, 2),
                num(bpr, 1),
                num(st["bytes_per_hit"].as_f64().unwrap_or(f64::NAN), 0),
                st["tasks"].as_u64().map_or("-".into(), |t| t.to_string()),
                num(m.peak_kib() as f64 / 1024.0, 1),
            ]);
            data.push(serde_json::json!({
                "scene": name, "setup": label, "seconds": m.seconds(),
                "runs": m.all.iter().map(|x| x.seconds).collect::<Vec<_>>(),
                "time_vs_embedded": vs_base,
                "rays": rays, "rays_per_second": rate,
                "bytes_to_workers": st["bytes_to_workers"], "bytes_from_workers": st["bytes_from_workers"],
                "bytes_per_ray": st["bytes_per_ray"], "bytes_per_hit": st["bytes_per_hit"],
                "tasks": st["tasks"], "passes": st["passes"], "client_peak_kib": m.peak_kib(),
            }));
        }
    }
    r.table(
        "scaling",
        &[
            "scene",
            "setup",
            "seconds",
            "Mrays/s",
            "vs embedded",
            "time vs embedded",
            "bytes/ray",
            "bytes/hit",
            "tasks",
            "peak MiB (largest process)",
        ],
        &rows,
    )?;
    r.json("scaling", &serde_json::Value::Array(data))?;
    r.para(&format!(
        "Goals of a cheap wire (issue 17): one local worker at most {GOAL_ONE_WORKER}x the embedded \
         breadth-first time, at most {GOAL_BYTES_PER_RAY} bytes per ray. {}.",
        goals.join("; ")
    ));
    let file = "throughput_local_workers.svg";
    chart::bars(
        &r.path(file),
        &format!("Rays per second, {side}x{side}, this 2-core machine"),
        "million rays / s",
        &cats,
        &series,
    )?;
    r.chart(file, "throughput with local workers");
    Ok(())
}

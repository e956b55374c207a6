//! The paper's Table 1: the depth-first tracer against the breadth-first
//! one in memory on the seven default scenes, time split into preprocess,
//! intersection and shading.
//!
//! The breadth-first tracer times its phases directly. The depth-first one
//! interleaves them per ray, so its split comes from a second, profiled run
//! (`--profile` times every intersection query): the profiled run's
//! intersection share of its trace time, applied to the unprofiled run's
//! trace time. That is the paper's method too ("estimated with profiling
//! data", shading = total - preprocess - intersection).

use super::report::{Report, num};
use super::{Ctx, Plan, chart, exec};
use sray_engine::spd::SpdScene;

/// The paper's Table 1 total-time ratio sray / rayshade-ss, for reference.
fn paper_ratio(s: SpdScene) -> Option<f64> {
    match s {
        SpdScene::Balls => Some(5.16),
        SpdScene::Gears => Some(3.61),
        SpdScene::Mount => Some(4.77),
        SpdScene::Rings => Some(3.33),
        SpdScene::Tetra => Some(2.47),
        SpdScene::Tree => Some(4.69),
        SpdScene::Teapot => None,
    }
}

pub(super) fn plan(ctx: &Ctx) -> Plan {
    let n = ctx.scenes().len();
    // Per scene: df, df profiled, bf (carry and join) at one thread; df
    // and bf at two.
    let steps = n * 6;
    let per_run = if ctx.quick { 0.15 } else { 1.6 };
    Plan {
        steps,
        seconds: (steps * ctx.runs) as f64 * per_run,
    }
}

/// Times from a run's statistics.
struct Split {
    pre: f64,
    isect: f64,
    shade: f64,
    total: f64,
}

pub(super) fn run(ctx: &Ctx, r: &mut Report) -> anyhow::Result<()> {
    let side = ctx.side();
    r.section("Table 1: depth-first against breadth-first, in memory");
    r.para(&format!(
        "The seven default scenes at {side}x{side}, depth 5, from object databases made beforehand, \
         both tracers with their defaults (the breadth-first one with the adaptive store number and \
         a memory budget large enough to hold every ray). Times are the renders' own (`--stats`), \
         medians of {} run(s). The depth-first split into intersection and shading comes from a second \
         run with `--profile` (its intersection share of the trace time, applied to the unprofiled run), \
         as the paper estimated RayShade's from profiling data. The paper's last column is its \
         sray/rayshade-ss total ratio (view rays and first shadow rays only, store number 1).",
        ctx.runs
    ));
    let mut rows = Vec::new();
    let mut rows2 = Vec::new();
    let mut data = Vec::new();
    let mut cats = Vec::new();
    let (mut df_t, mut bf_t) = (Vec::new(), Vec::new());
    for (scene, size) in ctx.scenes() {
        let name = format!("{}{size}", scene.name());
        cats.push(name.clone());
        let sdb = ctx.scene_file(scene, size, "sdb")?;
        let base = |mode: &str, threads: u32| -> Vec<String> {
            [
                sdb.display().to_string(),
                "-o".into(),
                ctx.work().join("t1.png").display().to_string(),
                "--mode".into(),
                mode.into(),
                "--threads".into(),
                threads.to_string(),
                "--width".into(),
                side.to_string(),
                "--height".into(),
                side.to_string(),
            ]
            .into()
        };
        let df = ctx.median(&format!("table1: {name} df"), || {
            exec::sray_render(&base("df", 1), ctx.work())
        })?;
        let mut prof_args = base("df", 1);
        prof_args.push("--profile".into());
        let prof = ctx.median(&format!("table1: {name} df --profile"), || {
            exec::sray_render(&prof_args, ctx.work())
        })?;
        let bf = ctx.median(&format!("table1: {name} bf"), || {
            exec::sray_render(&base("bf", 1), ctx.work())
        })?;
        // The paper's algorithm whole: its shading (Pseudocode 4, hits
        // sorted by object and joined with a scan of the objects) and its
        // passes, each a full scan (no block passed over).
        let mut join_args = base("bf", 1);
        join_args.extend(["--shading".into(), "join".into(), "--full-scans".into()]);
        let join = ctx.median(
            &format!("table1: {name} bf --shading join --full-scans"),
            || exec::sray_render(&join_args, ctx.work()),
        )?;
        let share = prof.stat("intersect_seconds") / prof.stat("trace_seconds");
        let d = Split {
            pre: df.stat("preprocess_seconds"),
            isect: df.stat("trace_seconds") * share,
            shade: df.stat("trace_seconds") * (1.0 - share),
            total: df.stat("total_seconds"),
        };
        let b = Split {
            pre: bf.stat("preprocess_seconds"),
            isect: bf.stat("intersect_seconds"),
            shade: bf.stat("shade_seconds"),
            total: bf.stat("total_seconds"),
        };
        rows.push(vec![
            name.clone(),
            num(d.pre, 3),
            num(b.pre, 3),
            num(d.isect, 3),
            num(b.isect, 3),
            num(b.isect / d.isect, 2),
            num(d.shade, 3),
            num(b.shade, 3),
            num(b.shade / d.shade, 2),
            num(join.stat("shade_seconds"), 3),
            num(d.total, 3),
            num(b.total, 3),
            format!("**{}**", num(b.total / d.total, 2)),
            paper_ratio(scene).map_or("-".into(), |v| num(v, 2)),
        ]);
        df_t.push(d.total);
        bf_t.push(b.total);
        let df2 = ctx.median(&format!("table1: {name} df, 2 threads"), || {
            exec::sray_render(&base("df", 2), ctx.work())
        })?;
        let bf2 = ctx.median(&format!("table1: {name} bf, 2 threads"), || {
            exec::sray_render(&base("bf", 2), ctx.work())
        })?;
        let (d2, b2) = (df2.stat("total_seconds"), bf2.stat("total_seconds"));
        rows2.push(vec![
            name.clone(),
            num(d2, 3),
            num(b2, 3),
            num(b2 / d2, 2),
            num(b.total / b2, 2),
            num(df.peak_kib() as f64 / 1024.0, 1),
            num(bf.peak_kib() as f64 / 1024.0, 1),
        ]);
        let same_counts = [
            "eye_hit_rays",
            "shadow_rays",
            "reflect_rays",
            "refract_rays",
        ]
        .iter()
        .all(|k| df.stats()[k] == bf.stats()[k]);
        anyhow::ensure!(
            same_counts,
            "{name}: depth-first and breadth-first ray counts differ"
        );
        data.push(serde_json::json!({
            "scene": name,
            "df": {"preprocess": d.pre, "intersect": d.isect, "shade": d.shade, "total": d.total,
                   "profiled_intersect_share": share, "peak_kib": df.peak_kib()},
            "bf_join": {"shade": join.stat("shade_seconds"), "total": join.stat("total_seconds"),
                        "db_scans": join.stats()["db_scans"]},
            "bf": {"preprocess": b.pre, "intersect": b.isect, "shade": b.shade, "total": b.total,
                   "peak_kib": bf.peak_kib(), "passes": bf.stats()["passes"],
                   "intersection_tests": bf.stats()["intersection_tests"]},
            "df_intersection_tests": df.stats()["intersection_tests"],
            "two_threads": {"df_total": d2, "bf_total": b2},
            "paper_sray_over_rayshade": paper_ratio(scene),
        }));
    }
    r.table(
        "table1_df_vs_bf",
        &[
            "scene",
            "df pre",
            "bf pre",
            "df isect",
            "bf isect",
            "bf/df",
            "df shade",
            "bf shade",
            "bf/df",
            "bf shade (join)",
            "df total",
            "bf total",
            "bf/df",
            "paper sray/rss",
        ],
        &rows,
    )?;
    r.para(
        "Seconds, one thread. The breadth-first shading carries each hit's surface from the \
         intersection scan (`--shading carry`, the default); \"bf shade (join)\" is the paper's \
         Pseudocode 4 (`--shading join`: hits sorted by object, joined with a scan of the objects), \
         run as the paper runs it: every pass reads the whole database, and each join reads it \
         up to the last hit object (`--full-scans`; by default passes and joins skip the blocks \
         no ray or hit is in). \
         Two threads (\"bf 1T/2T\" is the breadth-first speed-up from one thread to two), and peak \
         memory of the one-thread runs:",
    );
    r.table(
        "table1_two_threads",
        &[
            "scene",
            "df total 2T",
            "bf total 2T",
            "bf/df",
            "bf 1T/2T",
            "df peak MiB",
            "bf peak MiB",
        ],
        &rows2,
    )?;
    r.json("table1", &serde_json::Value::Array(data))?;
    let file = "time_df_vs_bf_table1.svg";
    chart::bars(
        &r.path(file),
        &format!("Total render time, {side}x{side}, one thread"),
        "seconds",
        &cats,
        &[("depth-first".into(), df_t), ("breadth-first".into(), bf_t)],
    )?;
    r.chart(file, "depth-first against breadth-first");
    Ok(())
}

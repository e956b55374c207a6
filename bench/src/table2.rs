//! The paper's Table 2 and Figs. 6-8: time against scene size, depth-first
//! against breadth-first, under a real memory cap that the larger scenes
//! exceed. The depth-first tracer, forced to run on scenes larger than its
//! budget, keeps its big arrays in file-backed memory and pages, as the
//! paper's RayShade paged through swap (it runs in `sray-paged`, the
//! binary with the file-backed allocator); the breadth-first tracer stays
//! within its budget.

use super::chart::{self, Scale, Series};
use super::exec::{self, Capped, MemoryCap};
use super::report::{Report, num};
use super::{Ctx, Plan};
use sray_engine::spd::SpdScene;
use sray_engine::units::fmt_bytes;

struct Setup {
    cap: u64,
    /// `--memory` of both tracers, below the cap by the process's overhead.
    budget: u64,
    side: u32,
    limit_secs: f64,
    scenes: Vec<(SpdScene, Vec<u32>)>,
}

fn setup(ctx: &Ctx) -> Setup {
    if ctx.quick {
        Setup {
            cap: 96 << 20,
            budget: 64 << 20,
            side: 64,
            limit_secs: 60.0,
            scenes: vec![(SpdScene::Balls, vec![1, 2]), (SpdScene::Tetra, vec![3, 5])],
        }
    } else {
        Setup {
            cap: 256 << 20,
            budget: 200 << 20,
            side: 512,
            limit_secs: 600.0,
            scenes: vec![
                (SpdScene::Balls, vec![3, 4, 5, 6, 7]),
                (SpdScene::Gears, vec![4, 6, 8, 10, 14, 20]),
                (SpdScene::Mount, vec![6, 7, 8, 9, 10]),
                (SpdScene::Rings, vec![7, 10, 13, 17, 25, 35]),
                (SpdScene::Tetra, vec![6, 7, 8, 9, 10, 11]),
                (SpdScene::Tree, vec![11, 13, 15, 17, 19]),
            ],
        }
    }
}

pub(super) fn plan(ctx: &Ctx) -> Plan {
    let s = setup(ctx);
    let points: usize = s.scenes.iter().map(|(_, v)| v.len()).sum();
    Plan {
        steps: points * 2,
        seconds: if ctx.quick {
            points as f64 * 2.0
        } else {
            points as f64 * 90.0
        },
    }
}

/// One tracer at one size: the median of a few runs when runs are short,
/// one run when they are long (the points span orders of magnitude).
fn measure(
    ctx: &Ctx,
    exe: &std::path::Path,
    cap: Option<&MemoryCap>,
    args: &[String],
    limit: f64,
) -> anyhow::Result<Capped> {
    let once = || exec::sray_render_maybe_capped(exe, cap, args, ctx.work(), limit);
    let first = once()?;
    let short = first.measured.as_ref().is_some_and(|m| m.seconds < 20.0);
    if !short || ctx.runs < 2 {
        return Ok(first);
    }
    let mut all = vec![first];
    for _ in 1..ctx.runs.min(3) {
        all.push(once()?);
    }
    all.sort_by(|a, b| {
        let t = |c: &Capped| c.measured.as_ref().map_or(f64::INFINITY, |m| m.seconds);
        t(a).total_cmp(&t(b))
    });
    Ok(all.swap_remove(all.len() / 2))
}

fn outcome(c: &Capped, limit: f64) -> String {
    match (&c.measured, c.oom_killed, c.timed_out) {
        (Some(m), _, _) => num(m.seconds, 2),
        (None, true, _) => "killed (out of memory)".into(),
        (None, _, true) => format!("> {limit:.0} (stopped)"),
        (None, _, _) => format!("failed: {}", c.error.clone().unwrap_or_default()),
    }
}

pub(super) fn run(ctx: &Ctx, r: &mut Report) -> anyhow::Result<()> {
    let s = setup(ctx);
    r.section("Table 2, Figs. 6-8: time against scene size under a memory cap");
    let cap = match MemoryCap::new(s.cap) {
        Ok(c) => Some(c),
        Err(why) => {
            eprintln!("sray bench: table2 runs without a memory cap: {why}");
            r.para(&format!(
                "**No memory cap could be set ({why}); these runs are uncapped**, so they show how \
                 time grows with size but not the breakdown of the depth-first tracer beyond memory. \
                 Run `sray bench table2` as root on Linux for the capped figures."
            ));
            None
        }
    };
    r.para(&format!(
        "{side}x{side}, depth 5, two threads, whole processes in a cgroup limited to {} (memory and \
         page cache alike, no swap). Both tracers get `--memory {}`. The depth-first tracer (`--mode \
         df`, run by `sray-paged`) keeps its objects and grids in memory; when they need more than \
         its budget it puts its large arrays in a file-backed mapping, which the kernel pages out and \
         in under the cap, \
         as the paper's RayShade paged through swap. The breadth-first tracer (`--mode bf`) holds rays \
         within its budget and reads the database front to back. \"df need\" is the depth-first \
         tracer's estimate of its memory. Runs stop after {:.0} s.",
        fmt_bytes(s.cap),
        fmt_bytes(s.budget),
        s.limit_secs,
        side = s.side
    ));
    let mut rows = Vec::new();
    let mut data = Vec::new();
    for (scene, sizes) in &s.scenes {
        let mut series: Vec<Series> = ["df total", "bf total", "df preprocess", "bf preprocess"]
            .iter()
            .map(|n| Series::new(*n, Vec::new()))
            .collect();
        for &size in sizes {
            let name = format!("{}{size}", scene.name());
            let sdb = ctx.scene_file(*scene, size, "sdb")?;
            let info = sray_engine::sdb::Database::open(&sdb)?;
            let objects = info.object_count() as f64;
            let need = sray_engine::df::estimate_bytes(&info);
            let db_bytes = info.file_bytes();
            drop(info);
            let mut line = vec![
                name.clone(),
                format!("{}", objects as u64),
                fmt_bytes(db_bytes),
                fmt_bytes(need),
            ];
            let mut entry = serde_json::json!({
                "scene": name, "objects": objects, "db_bytes": db_bytes, "df_need_bytes": need,
            });
            for (ti, mode) in ["df", "bf"].iter().enumerate() {
                ctx.step(&format!("table2: {name} {mode}"));
                let args: Vec<String> = [
                    sdb.display().to_string(),
                    "-o".into(),
                    ctx.work().join("t2.png").display().to_string(),
                    "--mode".into(),
                    mode.to_string(),
                    "--memory".into(),
                    s.budget.to_string(),
                    "--threads".into(),
                    "2".into(),
                    "--width".into(),
                    s.side.to_string(),
                    "--height".into(),
                    s.side.to_string(),
                    "--tmp-dir".into(),
                    ctx.work().display().to_string(),
                ]
                .into();
                // The depth-first tracer pages past its budget only in
                // sray-paged, which installs the file-backed allocator.
                let exe = if *mode == "df" {
                    exec::sray_paged_exe()?
                } else {
                    exec::sray_exe()?
                };
                let c = measure(ctx, &exe, cap.as_ref(), &args, s.limit_secs)?;
                line.push(outcome(&c, s.limit_secs));
                line.push(if c.peak_bytes > 0 {
                    fmt_bytes(c.peak_bytes)
                } else {
                    "-".into()
                });
                if let Some(m) = &c.measured {
                    let st = m.stats.clone().unwrap_or_default();
                    let pre = st["preprocess_seconds"].as_f64().unwrap_or(f64::NAN)
                        + st["convert_seconds"].as_f64().unwrap_or(0.0);
                    series[ti].points.push((objects, m.seconds));
                    series[2 + ti].points.push((objects, pre));
                    entry[*mode] = serde_json::json!({
                        "seconds": m.seconds, "preprocess_seconds": pre,
                        "peak_rss_kib": m.peak_kib, "cgroup_peak_bytes": c.peak_bytes,
                        "df_paged": st["df_paged"], "passes": st["passes"],
                    });
                } else {
                    entry[*mode] = serde_json::json!({
                        "oom_killed": c.oom_killed, "timed_out": c.timed_out, "error": c.error,
                        "cgroup_peak_bytes": c.peak_bytes,
                    });
                }
            }
            rows.push(line);
            data.push(entry);
            // Big databases are not needed again.
            let _ = std::fs::remove_file(&sdb);
        }
        let file = format!("time_vs_size_{}.svg", scene.name());
        chart::lines(
            &r.path(&file),
            &format!(
                "{}: time against objects, cap {}",
                scene.name(),
                fmt_bytes(s.cap)
            ),
            "objects",
            "seconds",
            &series,
            Scale::LogLog,
        )?;
        r.chart(&file, &format!("time against size, {}", scene.name()));
    }
    r.table(
        "table2_time_vs_size",
        &[
            "scene",
            "objects",
            "database",
            "df need",
            "df s",
            "df cgroup peak",
            "bf s",
            "bf cgroup peak",
        ],
        &rows,
    )?;
    r.json("table2", &serde_json::Value::Array(data))?;
    Ok(())
}

//! The paper's Fig. 9 (plain against compressed databases, tetra at
//! growing sizes) and Table 3 (mount 11, rings 80 and tetra 12 rendered
//! from compressed databases under a memory cap below their size).

use super::chart::{self, Scale, Series};
use super::exec::{self, Capped, MemoryCap};
use super::report::{Report, num};
use super::{Ctx, Plan};
use sray_engine::spd::SpdScene;
use sray_engine::units::fmt_bytes;
use std::path::PathBuf;

struct Setup {
    cap: u64,
    budget: u64,
    side: u32,
    limit_secs: f64,
    fig9_sizes: Vec<u32>,
    table3: Vec<(SpdScene, u32, f64)>,
}

fn setup(ctx: &Ctx) -> Setup {
    if ctx.quick {
        Setup {
            cap: 96 << 20,
            budget: 64 << 20,
            side: 64,
            limit_secs: 120.0,
            fig9_sizes: vec![3, 4, 5],
            table3: vec![
                (SpdScene::Mount, 4, f64::NAN),
                (SpdScene::Rings, 4, f64::NAN),
                (SpdScene::Tetra, 5, f64::NAN),
            ],
        }
    } else {
        Setup {
            cap: 256 << 20,
            budget: 200 << 20,
            side: 512,
            limit_secs: 1800.0,
            fig9_sizes: vec![6, 7, 8, 9, 10, 11],
            table3: vec![
                (SpdScene::Mount, 11, 8.35),
                (SpdScene::Rings, 80, 6.30),
                (SpdScene::Tetra, 12, 2.37),
            ],
        }
    }
}

pub(super) fn plan(ctx: &Ctx) -> Plan {
    let s = setup(ctx);
    let steps = s.fig9_sizes.len() * 2 + s.table3.len() * 2;
    Plan {
        steps,
        seconds: if ctx.quick { steps as f64 * 1.5 } else { 900.0 },
    }
}

fn cap_or_note(bytes: u64, r: &mut Report) -> Option<MemoryCap> {
    match MemoryCap::new(bytes) {
        Ok(c) => Some(c),
        Err(why) => {
            eprintln!("sray bench: running without a memory cap: {why}");
            r.para(&format!(
                "**No memory cap could be set ({why}); these runs are uncapped.** Run as root on \
                 Linux for the capped figures."
            ));
            None
        }
    }
}

fn render(
    ctx: &Ctx,
    cap: Option<&MemoryCap>,
    sdb: &std::path::Path,
    s: &Setup,
) -> anyhow::Result<Capped> {
    let args: Vec<String> = [
        sdb.display().to_string(),
        "-o".into(),
        ctx.work().join("big.png").display().to_string(),
        "--mode".into(),
        "bf".into(),
        "--memory".into(),
        s.budget.to_string(),
        "--width".into(),
        s.side.to_string(),
        "--height".into(),
        s.side.to_string(),
        "--tmp-dir".into(),
        ctx.work().display().to_string(),
    ]
    .into();
    exec::sray_render_maybe_capped(&exec::sray_exe()?, cap, &args, ctx.work(), s.limit_secs)
}

/// Generates a database with `sray gen`, timed.
fn generate(ctx: &Ctx, scene: SpdScene, size: u32, zstd: bool) -> anyhow::Result<(PathBuf, f64)> {
    let p = ctx.work().join(format!(
        "{}{size}{}.sdb",
        scene.name(),
        if zstd { "z" } else { "" }
    ));
    let mut args = vec![
        "gen".to_string(),
        scene.name().into(),
        "--size".into(),
        size.to_string(),
        "-o".into(),
        p.display().to_string(),
    ];
    if zstd {
        args.extend(["--compress".into(), "zstd".into()]);
    }
    let m = exec::measure(&exec::sray_exe()?, &args, ctx.work())?;
    Ok((p, m.seconds))
}

fn seconds(c: &Capped, limit: f64) -> (String, f64) {
    match (&c.measured, c.oom_killed, c.timed_out) {
        (Some(m), _, _) => (num(m.seconds, 1), m.seconds),
        (None, true, _) => ("killed (out of memory)".into(), f64::NAN),
        (None, _, true) => (format!("> {limit:.0} (stopped)"), f64::NAN),
        _ => (
            format!("failed: {}", c.error.clone().unwrap_or_default()),
            f64::NAN,
        ),
    }
}

pub(super) fn run(ctx: &Ctx, r: &mut Report) -> anyhow::Result<()> {
    let s = setup(ctx);
    r.section("Fig. 9 and Table 3: compressed databases");
    let cap = cap_or_note(s.cap, r);
    r.para(&format!(
        "Breadth-first, {side}x{side}, depth 5, both cores, `--memory {}` inside a cgroup limited to {} \
         (memory and page cache, no swap). Databases made by `sray gen` plain or with `--compress zstd` \
         (level 3); the time does not include generation, which is listed apart.",
        fmt_bytes(s.budget),
        fmt_bytes(s.cap),
        side = s.side
    ));

    // Fig. 9: tetra, plain against compressed.
    let mut series = vec![
        Series::new("plain", Vec::new()),
        Series::new("zstd", Vec::new()),
    ];
    let mut rows = Vec::new();
    let mut data = Vec::new();
    for &size in &s.fig9_sizes {
        let mut line = vec![format!("tetra{size}")];
        for (zi, zstd) in [false, true].into_iter().enumerate() {
            ctx.step(&format!(
                "fig9: tetra{size} {}",
                if zstd { "zstd" } else { "plain" }
            ));
            let (sdb, gen_s) = generate(ctx, SpdScene::Tetra, size, zstd)?;
            let db = sray_engine::sdb::Database::open(&sdb)?;
            let (objects, bytes, raw) = (db.object_count(), db.file_bytes(), db.decoded_bytes());
            drop(db);
            let c = render(ctx, cap.as_ref(), &sdb, &s)?;
            let _ = std::fs::remove_file(&sdb);
            let (text, secs) = seconds(&c, s.limit_secs);
            series[zi].points.push((objects as f64, secs));
            line.extend([fmt_bytes(bytes), text]);
            data.push(serde_json::json!({
                "scene": format!("tetra{size}"), "zstd": zstd, "objects": objects,
                "file_bytes": bytes, "raw_bytes": raw, "seconds": secs, "generate_seconds": gen_s,
                "cgroup_peak_bytes": c.peak_bytes,
            }));
        }
        rows.push(line);
    }
    r.table(
        "fig9_plain_vs_zstd",
        &["scene", "plain size", "plain s", "zstd size", "zstd s"],
        &rows,
    )?;
    r.json("fig9", &serde_json::Value::Array(data))?;
    let file = "time_vs_size_tetra_plain_vs_zstd.svg";
    chart::lines(
        &r.path(file),
        "tetra: plain against zstd databases",
        "objects",
        "seconds",
        &series,
        Scale::LogLog,
    )?;
    r.chart(file, "plain against compressed");

    // Table 3: the three big scenes from compressed databases.
    let mut rows = Vec::new();
    let mut data = Vec::new();
    for &(scene, size, paper_hours) in &s.table3 {
        let name = format!("{}{size}", scene.name());
        ctx.step(&format!("table3: generating {name} (zstd)"));
        let (sdb, gen_s) = generate(ctx, scene, size, true)?;
        let db = sray_engine::sdb::Database::open(&sdb)?;
        // "data" is the records' size (runs expanded), comparable across
        // database versions; the JSON has the stored size too.
        let (objects, bytes, raw, stored) = (
            db.object_count(),
            db.file_bytes(),
            db.decoded_bytes(),
            db.raw_bytes(),
        );
        drop(db);
        ctx.step(&format!("table3: rendering {name}"));
        let c = render(ctx, cap.as_ref(), &sdb, &s)?;
        let _ = std::fs::remove_file(&sdb);
        let (text, secs) = seconds(&c, s.limit_secs);
        let st = c
            .measured
            .as_ref()
            .and_then(|m| m.stats.clone())
            .unwrap_or_default();
        rows.push(vec![
            name.clone(),
            objects.to_string(),
            fmt_bytes(raw),
            fmt_bytes(bytes),
            num(gen_s, 1),
            text,
            if c.peak_bytes > 0 {
                fmt_bytes(c.peak_bytes)
            } else {
                "-".into()
            },
            st["db_scans"].to_string(),
            st["db_bytes_read"]
                .as_u64()
                .map_or_else(|| "-".into(), fmt_bytes),
            st["db_blocks_skipped"].to_string(),
            if paper_hours.is_finite() {
                num(paper_hours, 2)
            } else {
                "-".into()
            },
        ]);
        data.push(serde_json::json!({
            "scene": name, "objects": objects, "raw_bytes": raw, "stored_bytes": stored,
            "file_bytes": bytes, "generate_seconds": gen_s, "seconds": secs, "cgroup_peak_bytes": c.peak_bytes,
            "db_scans": st["db_scans"], "db_bytes_read": st["db_bytes_read"],
            "db_blocks_skipped": st["db_blocks_skipped"],
            "passes": st["passes"], "grid_res": st["grid_res"],
            "paper_hours": paper_hours.is_finite().then_some(paper_hours),
        }));
    }
    r.table(
        "table3_compressed",
        &[
            "scene",
            "objects",
            "data size",
            "zstd size",
            "generate s",
            "render s",
            "cgroup peak",
            "database scans",
            "bytes read",
            "blocks skipped",
            "paper (hours)",
        ],
        &rows,
    )?;
    r.json("table3", &serde_json::Value::Array(data))?;
    Ok(())
}

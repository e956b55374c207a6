//! The depth-first tracer against POV-Ray 3.7 on the seven default SPD
//! scenes, one and two threads, whole processes; and against the times the
//! issue gives for RayShade 4 (22x22x22 grid, one core) on this machine.

use super::report::{Report, num};
use super::{Ctx, Plan, chart, exec};
use sray_engine::spd::SpdScene;
use std::path::{Path, PathBuf};

/// RayShade 4, one core, whole process, 512x512 depth 5 (from the issue).
fn rayshade_seconds(s: SpdScene) -> f64 {
    match s {
        SpdScene::Balls => 0.34,
        SpdScene::Gears => 0.73,
        SpdScene::Mount => 0.47,
        SpdScene::Rings => 0.87,
        SpdScene::Tetra => 0.07,
        SpdScene::Tree => 0.20,
        SpdScene::Teapot => 0.36,
    }
}

const THREADS: [u32; 2] = [1, 2];

fn povray_exe() -> Option<PathBuf> {
    std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|d| d.join("povray"))
            .find(|p| p.is_file())
    })
}

/// The `.pov` file of a scene, when both POV-Ray and the files are here.
fn pov_file(ctx: &Ctx, s: SpdScene, size: u32) -> Option<PathBuf> {
    let p = ctx
        .spd_dir
        .as_ref()?
        .join(format!("{}{size}.pov", s.name()));
    p.is_file().then_some(p)
}

pub(super) fn plan(ctx: &Ctx) -> Plan {
    let pov = povray_exe().is_some();
    let n = ctx.scenes().len() * THREADS.len();
    let steps = n * if pov { 2 } else { 1 };
    let per_run = if ctx.quick {
        0.2
    } else if pov {
        3.5
    } else {
        1.0
    };
    Plan {
        steps,
        seconds: (n * ctx.runs) as f64 * per_run,
    }
}

pub(super) fn run(ctx: &Ctx, r: &mut Report) -> anyhow::Result<()> {
    let side = ctx.side();
    r.section("Depth-first against POV-Ray 3.7 and RayShade 4");
    let pov = povray_exe();
    r.para(&format!(
        "The seven default SPD scenes at {side}x{side}, depth 5, whole processes (parse, build, trace, write), \
         `sray render SCENE.nff --mode df --threads T` against \
         `povray +W{side} +H{side} -A +MV3.1 +FN -D -P +WT<T>` on the SPD's own `.pov` files. \
         RayShade's times (one core, 22x22x22 grid, ground polygon outside it) are the figures the project \
         was given for this machine; they were not measured here. Ratios below 1 mean sray is faster."
    ));
    if pov.is_none() {
        r.para("POV-Ray was not found on PATH (`apt-get install povray`): its columns are empty.");
    }
    let mut rows = Vec::new();
    let mut data = Vec::new();
    let mut bars: [Vec<(String, Vec<f64>)>; 2] = Default::default();
    let cats: Vec<String> = ctx
        .scenes()
        .iter()
        .map(|(s, n)| format!("{}{n}", s.name()))
        .collect();
    for (ti, &threads) in THREADS.iter().enumerate() {
        let mut ours = Vec::new();
        let mut theirs = Vec::new();
        let mut rs = Vec::new();
        for (scene, size) in ctx.scenes() {
            let name = format!("{}{size}", scene.name());
            let nff = ctx.scene_file(scene, size, "nff")?;
            let out = ctx.work().join("df.png");
            let args: Vec<String> = [
                nff.display().to_string(),
                "-o".into(),
                out.display().to_string(),
                "--mode".into(),
                "df".into(),
                "--threads".into(),
                threads.to_string(),
                "--width".into(),
                side.to_string(),
                "--height".into(),
                side.to_string(),
            ]
            .into();
            let s = ctx.median(&format!("povray: sray {name}, {threads} thread(s)"), || {
                exec::sray_render(&args, ctx.work())
            })?;
            let p = match (&pov, pov_file(ctx, scene, size)) {
                (Some(exe), Some(file)) => Some(ctx.median(
                    &format!("povray: POV-Ray {name}, {threads} thread(s)"),
                    || povray_run(exe, &file, side, threads, ctx.work()),
                )?),
                _ => None,
            };
            let p_s = p.as_ref().map_or(f64::NAN, |p| p.seconds());
            let rsh = if threads == 1 && !ctx.quick {
                rayshade_seconds(scene)
            } else {
                f64::NAN
            };
            rows.push(vec![
                name.clone(),
                threads.to_string(),
                num(s.seconds(), 2),
                num(s.peak_kib() as f64 / 1024.0, 1),
                num(p_s, 2),
                p.as_ref()
                    .map_or("-".into(), |p| num(p.peak_kib() as f64 / 1024.0, 1)),
                num(s.seconds() / p_s, 2),
                num(rsh, 2),
                num(s.seconds() / rsh, 2),
            ]);
            data.push(serde_json::json!({
                "scene": name, "threads": threads,
                "sray_seconds": s.seconds(), "sray_runs": s.all.iter().map(|m| m.seconds).collect::<Vec<_>>(),
                "sray_peak_kib": s.peak_kib(),
                "povray_seconds": p.as_ref().map(|p| p.seconds()),
                "povray_runs": p.as_ref().map(|p| p.all.iter().map(|m| m.seconds).collect::<Vec<_>>()),
                "povray_peak_kib": p.as_ref().map(|p| p.peak_kib()),
                "rayshade_seconds": rsh.is_finite().then_some(rsh),
            }));
            ours.push(s.seconds());
            theirs.push(p_s);
            rs.push(rsh);
        }
        bars[ti].push(("sray df".into(), ours));
        if pov.is_some() {
            bars[ti].push(("POV-Ray 3.7".into(), theirs));
        }
        if rs.iter().any(|v| v.is_finite()) {
            bars[ti].push(("RayShade 4 (given)".into(), rs));
        }
    }
    r.table(
        "povray",
        &[
            "scene",
            "threads",
            "sray s",
            "sray peak MiB",
            "POV-Ray s",
            "POV-Ray peak MiB",
            "sray/POV-Ray",
            "RayShade s",
            "sray/RayShade",
        ],
        &rows,
    )?;
    r.json("povray", &serde_json::Value::Array(data))?;
    for (ti, &threads) in THREADS.iter().enumerate() {
        let file = format!(
            "time_df_vs_povray_{threads}thread{}.svg",
            if threads > 1 { "s" } else { "" }
        );
        chart::bars(
            &r.path(&file),
            &format!("Whole-process time, {side}x{side}, {threads} thread(s)"),
            "seconds",
            &cats,
            &bars[ti],
        )?;
        r.chart(&file, &format!("time against POV-Ray, {threads} thread(s)"));
    }
    Ok(())
}

fn povray_run(
    exe: &Path,
    pov: &Path,
    side: u32,
    threads: u32,
    cwd: &Path,
) -> anyhow::Result<exec::Measured> {
    let out = cwd.join("pov.png");
    let args: Vec<String> = vec![
        format!("+I{}", pov.display()),
        format!("+O{}", out.display()),
        format!("+W{side}"),
        format!("+H{side}"),
        "-A".into(),
        "+MV3.1".into(),
        "+FN".into(),
        "-D".into(),
        "-P".into(),
        format!("+WT{threads}"),
    ];
    exec::measure(exe, &args, cwd)
}

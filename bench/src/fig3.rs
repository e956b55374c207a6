//! The paper's Fig. 3: eye rays still unfinished after each pass over the
//! objects, for the default rings scene with 65,536 eye rays, store number
//! fixed at one against adaptive, on 20^3 and 40^3 grids.

use super::chart::{self, Series};
use super::report::Report;
use super::{Ctx, Plan, exec};
use sray_engine::spd::SpdScene;

const RESOLUTIONS: [u32; 2] = [20, 40];
const STORE: [&str; 2] = ["1", "adaptive"];

pub(super) fn plan(ctx: &Ctx) -> Plan {
    let steps = RESOLUTIONS.len() * STORE.len();
    Plan {
        steps,
        seconds: steps as f64 * if ctx.quick { 0.2 } else { 1.0 },
    }
}

pub(super) fn run(ctx: &Ctx, r: &mut Report) -> anyhow::Result<()> {
    // 255x255 pixels have 256x256 = 65,536 corners: the paper's ray count.
    let side: u32 = if ctx.quick { 63 } else { 255 };
    let (scene, size) = (SpdScene::Rings, SpdScene::Rings.default_size());
    let sdb = ctx.scene_file(scene, size, "sdb")?;
    r.section("Fig. 3: remaining rays per pass");
    r.para(&format!(
        "rings{size}, {} eye rays ({side}x{side} pixels, rays through the corners), one grid of \
         res^3 voxels holding every object (`--grids 1 --grid-res res`), depth 1. The count is the eye \
         rays still without complete intersection information as each pass over the objects begins. Adaptive \
         starts at round(res/10) per ray, doubles with every pass the ray survives (finished rays free the memory), capped at res \
         (Section 2.2's two methods; the paper's Fig. 3b started at 1 and 2).",
        (side + 1) * (side + 1)
    ));
    let mut series = Vec::new();
    let mut rows = Vec::new();
    let mut data = Vec::new();
    for res in RESOLUTIONS {
        for store in STORE {
            ctx.step(&format!(
                "fig3: rings{size} res {res}, store number {store}"
            ));
            let args: Vec<String> = [
                sdb.display().to_string(),
                "-o".into(),
                ctx.work().join("fig3.png").display().to_string(),
                "--mode".into(),
                "bf".into(),
                "--grids".into(),
                "1".into(),
                "--grid-res".into(),
                res.to_string(),
                "--store-number".into(),
                store.into(),
                // The paper's passes: every one reads the whole database.
                "--full-scans".into(),
                "--depth".into(),
                "1".into(),
                "--width".into(),
                side.to_string(),
                "--height".into(),
                side.to_string(),
            ]
            .into();
            // Pass counts do not depend on timing: one run is enough.
            let m = exec::sray_render(&args, ctx.work())?;
            let stats = m.stats.unwrap_or_default();
            let remaining: Vec<u64> = stats["remaining_rays_per_pass"][0]
                .as_array()
                .map(|a| a.iter().filter_map(|v| v.as_u64()).collect())
                .unwrap_or_default();
            anyhow::ensure!(
                !remaining.is_empty(),
                "no remaining_rays_per_pass in the statistics"
            );
            series.push(Series::new(
                format!("{res}^3, store {store}"),
                remaining
                    .iter()
                    .enumerate()
                    .map(|(i, &n)| (i as f64 + 1.0, n as f64))
                    .collect(),
            ));
            rows.push(vec![
                res.to_string(),
                store.to_string(),
                remaining.len().to_string(),
                remaining
                    .iter()
                    .map(|n| n.to_string())
                    .collect::<Vec<_>>()
                    .join(" "),
                stats["tests_skipped_last_voxel"].to_string(),
                stats["intersection_tests"].to_string(),
                format!(
                    "{:.3}",
                    stats["intersect_seconds"].as_f64().unwrap_or(f64::NAN)
                ),
            ]);
            data.push(serde_json::json!({
                "res": res, "store": store, "remaining": remaining,
                "store_numbers": stats["store_numbers"][0],
                "intersection_tests": stats["intersection_tests"],
                "intersect_seconds": stats["intersect_seconds"],
            }));
        }
    }
    r.table(
        "fig3_remaining_rays",
        &[
            "res",
            "store number",
            "passes",
            "unfinished rays as each pass begins",
            "skipped (last voxel)",
            "intersection tests",
            "intersect s",
        ],
        &rows,
    )?;
    r.json("fig3", &serde_json::Value::Array(data))?;
    let file = "remaining_rays_per_pass_rings.svg";
    chart::lines(
        &r.path(file),
        "Unfinished eye rays at each pass (rings)",
        "pass",
        "remaining rays",
        &series,
        chart::Scale::LogY,
    )?;
    r.chart(file, "remaining rays per pass");
    Ok(())
}

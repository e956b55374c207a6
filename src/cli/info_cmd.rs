//! `sray info`: what a scene file holds.

use super::bar::Bar;
use clap::Args;
use sray_engine::info::{SceneInfo, aggregate_info, scene_info_with};
use sray_engine::mesh::MeshOptions;
use sray_engine::shapes::ShapeKind;
use std::path::PathBuf;

/// `println!` into a String.
macro_rules! outln {
    ($out:expr, $($arg:tt)*) => {{
        use std::fmt::Write as _;
        let _ = writeln!($out, $($arg)*);
    }};
}

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// A scene file (.nff, .ply, .obj, .off, .gltf, .glb, any of them .gz or .zst
    /// compressed) or an .sdb file
    pub file: PathBuf,
    /// Print one JSON object on stdout
    #[arg(long)]
    pub json: bool,
    /// Memory budget for reading a mesh (default: half of the available
    /// memory)
    #[arg(long, value_parser = parse_memory)]
    pub memory: Option<u64>,
    /// Directory for temporary files (default: the system's)
    #[arg(long)]
    pub tmp_dir: Option<PathBuf>,
    /// Object database only: count the groups of objects the
    /// breadth-first tracer holds as aggregates in its default grids
    /// (reads the whole file)
    #[arg(long)]
    pub aggregates: bool,
    /// No progress bar (errors are still printed)
    #[arg(short, long)]
    pub quiet: bool,
}

fn parse_memory(s: &str) -> Result<u64, String> {
    sray_engine::units::parse_bytes(s)
}

pub fn run(a: InfoArgs) -> anyhow::Result<()> {
    super::bar::set_quiet(a.quiet);
    let bar = Bar::bytes("info");
    let opts = MeshOptions {
        memory: match a.memory {
            Some(m) => sray_engine::job::mesh_memory(m)?,
            None => sray_engine::sys::default_memory_budget(),
        },
        spill_dir: a.tmp_dir.clone(),
        camera_index: None,
    };
    let info = scene_info_with(&a.file, &bar, &opts)?;
    bar.finish();
    let aggregates = if a.aggregates {
        if info.format != "sdb" {
            anyhow::bail!(
                "--aggregates is for an object database (.sdb); convert {} first",
                a.file.display()
            );
        }
        let bar = Bar::new("aggregates", "");
        let found = aggregate_info(&a.file, &bar)?;
        bar.finish();
        Some(found)
    } else {
        None
    };
    let mut out = String::new();
    if a.json {
        let mut v = serde_json::to_value(&info)?;
        if let (Some(found), Some(map)) = (aggregates, v.as_object_mut()) {
            map.insert("aggregates".into(), found.aggregates.into());
            map.insert("aggregate_objects".into(), found.aggregate_objects.into());
        }
        outln!(out, "{}", serde_json::to_string_pretty(&v)?);
    } else {
        human(&mut out, &a.file, &info);
        if let Some(f) = aggregates {
            outln!(
                out,
                "  aggregates   {} groups of {} objects ({} objects) in the breadth-first grids",
                f.aggregates,
                sray_engine::grid::aggregate::SIZE,
                f.aggregate_objects
            );
        }
    }
    super::print_stdout(&out)?;
    Ok(())
}

fn human(out: &mut String, path: &std::path::Path, i: &SceneInfo) {
    outln!(out, "{} ({})", path.display(), i.format);
    outln!(out, "  objects      {}", i.objects);
    let by_kind: Vec<String> = i
        .counts
        .named()
        .map(|(kind, n)| format!("{kind} {n}"))
        .collect();
    outln!(out, "    {}", by_kind.join(", "));
    outln!(out, "  lights       {}", i.lights);
    outln!(
        out,
        "  materials    {} distinct ({} statements)",
        i.materials,
        i.material_statements
    );
    outln!(out, "  triangles    {}", i.triangles);
    outln!(out, "  vertices     {}", i.vertices);
    if let Some(d) = i.degenerate_faces {
        outln!(out, "  degenerate   {d} faces skipped");
    }
    match (i.bbox_min, i.bbox_max) {
        (Some(a), Some(b)) => outln!(out, "  bounds       {a:?} .. {b:?}"),
        _ => outln!(out, "  bounds       (no objects)"),
    }
    outln!(
        out,
        "  file         {} bytes, compression {}",
        i.file_bytes,
        i.compression
    );
    if let (Some(raw), Some(blocks)) = (i.raw_bytes, i.blocks) {
        let per = raw as f64 / i.objects.max(1) as f64;
        outln!(
            out,
            "  records      {raw} bytes in {blocks} blocks ({per:.1} bytes per object)"
        );
    }
    if let (Some(raw), Some(decoded)) = (i.raw_bytes, i.decoded_bytes) {
        // Per triangle only where every object is one or more of them.
        let faces = i.counts.get(ShapeKind::Polygon) + i.counts.get(ShapeKind::Patch);
        if i.triangles >= i.objects && faces == i.objects {
            let per = raw as f64 / i.triangles as f64;
            outln!(
                out,
                "               {per:.1} bytes per triangle; {decoded} bytes expanded"
            );
        }
    }
    if let Some(layout) = i.layout {
        let order = match i.order {
            Some("spatial") => "objects in spatial order, each with its input id",
            _ => "objects in input order",
        };
        match (i.runs, i.run_triangles) {
            (Some(r), Some(t)) => outln!(
                out,
                "  layout       {layout}: {t} of {} triangles in {r} runs, {order}",
                i.triangles
            ),
            _ => outln!(out, "  layout       {layout}, {order}"),
        }
    }
    if let Some(v) = i.version {
        outln!(out, "  version      {v}");
    }
    if let Some(models) = &i.models {
        outln!(
            out,
            "  models       {} stored once, {} triangles placed by {} instances",
            models.len(),
            i.placed_triangles.unwrap_or(0),
            i.counts.get(ShapeKind::Instance)
        );
        for (k, m) in models.iter().enumerate() {
            outln!(
                out,
                "    model {k}: {} triangles, {} vertices, {} bytes ({:.1} per triangle), {} instances",
                m.triangles,
                m.vertices,
                m.bytes,
                m.bytes as f64 / m.triangles.max(1) as f64,
                m.instances
            );
        }
    }
    match (&i.density_entries, &i.dense_regions) {
        (Some(n), Some(regions)) => {
            outln!(
                out,
                "  density      {n} occupied cells and size classes; {} dense regions",
                regions.len()
            );
            for r in regions {
                outln!(
                    out,
                    "    {} objects in {:?} .. {:?}",
                    r.objects,
                    r.bbox_min,
                    r.bbox_max
                );
            }
        }
        _ if i.format == "sdb" => {
            outln!(out, "  density      no summary (written before version 3)")
        }
        _ => {}
    }
}

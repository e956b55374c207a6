//! `sray info`: what a scene file holds.

use super::bar::Bar;
use clap::Args;
use sray_engine::info::{SceneInfo, scene_info};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// An .nff or .sdb file
    pub file: PathBuf,
    /// Print one JSON object on stdout
    #[arg(long)]
    pub json: bool,
    /// No progress bar (errors are still printed)
    #[arg(short, long)]
    pub quiet: bool,
}

pub fn run(a: InfoArgs) -> anyhow::Result<()> {
    super::bar::set_quiet(a.quiet);
    let bar = Bar::bytes("info");
    let info = scene_info(&a.file, &bar)?;
    bar.finish();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&info)?);
    } else {
        print_human(&a.file, &info);
    }
    Ok(())
}

fn print_human(path: &std::path::Path, i: &SceneInfo) {
    println!("{} ({})", path.display(), i.format);
    println!("  objects      {}", i.objects);
    let by_kind: Vec<String> = i
        .counts
        .named()
        .map(|(kind, n)| format!("{kind} {n}"))
        .collect();
    println!("    {}", by_kind.join(", "));
    println!("  lights       {}", i.lights);
    println!(
        "  materials    {} distinct ({} statements)",
        i.materials, i.material_statements
    );
    match (i.bbox_min, i.bbox_max) {
        (Some(a), Some(b)) => println!("  bounds       {a:?} .. {b:?}"),
        _ => println!("  bounds       (no objects)"),
    }
    println!(
        "  file         {} bytes, compression {}",
        i.file_bytes, i.compression
    );
    if let (Some(raw), Some(blocks)) = (i.raw_bytes, i.blocks) {
        println!("  records      {raw} bytes in {blocks} blocks");
    }
}

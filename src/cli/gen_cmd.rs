//! `sray gen`: SPD scenes of any size factor, streamed to disk.

use super::bar::Bar;
use super::convert::write_scene;
use super::parse_compression;
use clap::Args;
use sray_engine::sdb::Compression;
use sray_engine::source::SceneSource;
use sray_engine::spd::SpdScene;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct GenArgs {
    /// balls, gears, mount, rings, tetra, tree or teapot
    pub name: SpdScene,
    /// Size factor (default: the paper's, e.g. balls 4, tetra 6)
    #[arg(short, long)]
    pub size: Option<u32>,
    /// Output file: .sdb for an object database, .nff for NFF text
    #[arg(short, long)]
    pub output: PathBuf,
    /// Compress the object database: none, zstd or zstd:LEVEL (1-22)
    #[arg(long, value_parser = parse_compression, default_value = "none")]
    pub compress: Compression,
    /// The order the database stores objects in: spatial (along a
    /// Z-order curve, each keeping its input id for ties: blocks that
    /// passes can skip, meshes stored compactly), input (as listed), or
    /// auto (input: generators emit their objects
    /// in a spatial order already)
    #[arg(long, value_parser = sray_engine::job::ObjectOrder::parse, default_value = "auto", value_name = "auto|spatial|input")]
    pub order: sray_engine::job::ObjectOrder,
    /// No progress bar (errors are still printed)
    #[arg(short, long)]
    pub quiet: bool,
}

pub fn run(a: GenArgs) -> anyhow::Result<()> {
    super::bar::set_quiet(a.quiet);
    let size = a.size.unwrap_or_else(|| a.name.default_size());
    let max = a.name.max_size();
    if size == 0 || size > max {
        anyhow::bail!("{} size factor {size} is out of range 1..={max}", a.name);
    }
    let bar = Bar::new(&format!("gen {}:{size}", a.name), "objects");
    write_scene(
        &SceneSource::Spd {
            scene: a.name,
            size,
        },
        &a.output,
        a.compress,
        &sray_engine::job::PrepareOptions {
            tmp_dir: None,
            memory: sray_engine::sys::default_memory_budget(),
            setup: &super::convert::no_setup(),
            order: a.order,
        },
        &bar,
    )?;
    bar.finish();
    Ok(())
}

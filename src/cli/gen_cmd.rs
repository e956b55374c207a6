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
        &bar,
    )?;
    bar.finish();
    Ok(())
}

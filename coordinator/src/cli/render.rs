//! `sray render`: a scene to a PNG.

use super::bar::Bar;
use crate::job::{RenderRequest, Stages, render, write_outputs};
use clap::Args;
use sray_engine::bf::StoreNumber;
use sray_engine::progress::Progress;
use sray_engine::render::{GridRes, Mode, Precision, RenderOptions};
use sray_engine::source::SceneSource;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// The scene: an .nff file, an .sdb file, or spd:NAME:SIZE (e.g. spd:balls:4)
    pub scene: String,
    /// Output image (PNG)
    #[arg(short, long)]
    pub output: PathBuf,
    /// Tracer: df (depth-first, in memory), bf (breadth-first) or auto
    #[arg(long, default_value = "auto")]
    pub mode: Mode,
    /// Image width in pixels
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    /// Image height in pixels
    #[arg(long, default_value_t = 512)]
    pub height: u32,
    /// Maximum depth of the ray tree (the eye ray is depth 1)
    #[arg(long, default_value_t = 5)]
    pub depth: u8,
    /// Grid resolution: auto, N (per axis) or NxMxK
    #[arg(long, default_value = "auto")]
    pub grid_res: GridRes,
    /// Voxels per object when the grid resolution is auto
    #[arg(long, default_value_t = sray_engine::df::GRID_DENSITY)]
    pub grid_density: f64,
    /// Grids: auto (set huge objects apart in their own grid) or 1
    #[arg(long, value_enum, default_value_t = Grids::Auto)]
    pub grids: Grids,
    /// Worker threads (default: all cores)
    #[arg(long)]
    pub threads: Option<usize>,
    /// Memory budget for everything the render holds (e.g. 64MiB, 2GiB;
    /// default: half of the available memory)
    #[arg(long, value_parser = parse_memory)]
    pub memory: Option<u64>,
    /// Breadth-first store number: adaptive, or a fixed number of voxels
    #[arg(long, default_value = "adaptive", value_parser = parse_store)]
    pub store_number: StoreNumber,
    /// Intersection arithmetic: double or single
    #[arg(long, default_value = "double")]
    pub precision: Precision,
    /// Time the depth-first tracer's intersection queries, to split its
    /// trace time into intersection and shading (costs a little time)
    #[arg(long)]
    pub profile: bool,
    /// Write statistics as JSON to this file
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// Directory for temporary files (default: the system's)
    #[arg(long)]
    pub tmp_dir: Option<PathBuf>,
}

fn parse_memory(s: &str) -> Result<u64, String> {
    sray_engine::bf::parse_bytes(s)
}

fn parse_store(s: &str) -> Result<StoreNumber, String> {
    if s == "adaptive" {
        return Ok(StoreNumber::Adaptive);
    }
    match s.parse::<u32>() {
        Ok(n) if (1..=65_536).contains(&n) => Ok(StoreNumber::Fixed(n)),
        _ => Err(format!(
            "--store-number takes adaptive or a number from 1 to 65536, not '{s}'"
        )),
    }
}

/// `--grids`: how objects are split into grids (Section 2.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Grids {
    /// Huge objects apart in their own grid when the scene is not uniform
    Auto,
    /// Every object in one grid
    #[value(name = "1")]
    One,
}

struct BarStages;

impl Stages for BarStages {
    fn stage(&self, name: &str) -> Box<dyn Progress + '_> {
        Box::new(Bar::new(name, ""))
    }
}

pub fn run(a: RenderArgs) -> anyhow::Result<()> {
    if a.threads == Some(0) {
        anyhow::bail!("--threads must be at least 1");
    }
    let req = RenderRequest {
        scene: SceneSource::parse(&a.scene)?,
        options: RenderOptions {
            width: a.width,
            height: a.height,
            max_depth: a.depth,
            threads: a.threads.unwrap_or(0),
            grid_res: a.grid_res,
            grid_density: a.grid_density,
            multiple_grids: a.grids == Grids::Auto,
            precision: a.precision,
            profile: a.profile,
        },
        mode: a.mode,
        memory: a.memory,
        store: a.store_number,
        tmp_dir: a.tmp_dir,
    };
    let result = render(&req, &BarStages)?;
    write_outputs(&result, &a.output, a.stats.as_deref())?;
    Ok(())
}

//! `sray render`: a scene to an image file (PNG or OpenEXR).

use super::bar::Bar;
use super::outputs::Outputs;
use super::summary;
use clap::Args;
use sray_engine::bf::{ModelHolding, Shading, StoreNumber};
use sray_engine::job::{PrepareOptions, RenderRequest, Stages, render};
use sray_engine::progress::Progress;
use sray_engine::render::{Aggregates, GridRes, Mode, Precision, RenderOptions};
use sray_engine::scene::setup::{CameraOverride, Setup, parse_light, parse_material};
use sray_engine::scene::{Light, Material};
use sray_engine::source::SceneSource;
use std::path::PathBuf;

/// `--camera`, `--light`, `--material`: for `sray render` and `sray
/// convert`, for any scene.
#[derive(Args, Debug, Clone, Default)]
pub struct SetupArgs {
    /// The camera, any of: from=X,Y,Z at=X,Y,Z up=X,Y,Z fov=DEG (separate
    /// words, or one quoted word); the rest stays the scene's (a mesh's:
    /// the default framing, with these parts). Separate words run to the
    /// next option, so put the scene before --camera or quote the parts
    #[arg(long, num_args = 1.., value_name = "KEY=VALUE")]
    pub camera: Vec<String>,
    /// A point light at X,Y,Z with colour R,G,B (white scaled by
    /// 1/sqrt(lights) without one); repeatable; replaces the scene's (or
    /// the default) lights
    #[arg(long, allow_hyphen_values = true, value_name = "X,Y,Z[,R,G,B]", value_parser = parse_light)]
    pub light: Vec<Light>,
    /// The material of every object, as NFF's f line: r,g,b,Kd,Ks,shine,T,ior
    #[arg(long, allow_hyphen_values = true, value_name = "r,g,b,Kd,Ks,shine,T,ior", value_parser = parse_material)]
    pub material: Option<Material>,
    /// The camera of a glTF scene to look through, by its index among the
    /// file's cameras (default: the first one a node places)
    #[arg(long, value_name = "N")]
    pub camera_index: Option<usize>,
    /// Write every placement of a glTF mesh as a copy of its own instead
    /// of storing the mesh once as a model placed by instances
    #[arg(long)]
    pub flatten_instances: bool,
}

impl SetupArgs {
    /// The setup these flags make, framing an image of `image` pixels.
    pub fn setup(&self, image: [u32; 2]) -> anyhow::Result<Setup> {
        let camera = if self.camera.is_empty() {
            CameraOverride::default()
        } else {
            CameraOverride::parse(&self.camera.join(" ")).map_err(anyhow::Error::msg)?
        };
        Ok(Setup {
            camera,
            lights: self.light.clone(),
            material: self.material,
            image,
            camera_index: self.camera_index,
            flatten_instances: self.flatten_instances,
        })
    }
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// The scene: a scene file (.nff, .ply, .obj, .off, .gltf, .glb, any of them .gz or
    /// .zst compressed), an .sdb file, or spd:NAME:SIZE (e.g. spd:balls:4)
    pub scene: String,
    /// Output image: .png (8-bit RGB) or .exr (OpenEXR, linear 32-bit float
    /// RGB, unclamped)
    #[arg(short, long)]
    pub output: PathBuf,
    /// Tracer: df (depth-first, in memory), bf (breadth-first) or auto
    #[arg(long, default_value = "auto")]
    pub mode: Mode,
    /// Image width in pixels
    #[arg(long, allow_negative_numbers = true, default_value_t = 512)]
    pub width: u32,
    /// Image height in pixels
    #[arg(long, allow_negative_numbers = true, default_value_t = 512)]
    pub height: u32,
    /// Maximum depth of the ray tree (the eye ray is depth 1)
    #[arg(long, allow_negative_numbers = true, default_value_t = 5)]
    pub depth: u8,
    /// Grid resolution: auto, N (per axis) or NxMxK
    #[arg(long, default_value = "auto")]
    pub grid_res: GridRes,
    /// Voxels per object when the grid resolution is auto
    #[arg(long, allow_negative_numbers = true, default_value_t = sray_engine::grid::DEFAULT_DENSITY)]
    pub grid_density: f64,
    /// Grids: auto (set huge objects apart in their own grid) or 1
    #[arg(long, value_enum, default_value_t = Grids::Auto)]
    pub grids: Grids,
    /// Crowded groups of objects as aggregates, each with a hierarchy of
    /// its own: auto (breadth-first), on (both tracers), off (objects one
    /// by one, as the paper does). The image is the same
    #[arg(long, value_enum, default_value_t = AggregatesArg::Auto)]
    pub aggregates: AggregatesArg,
    /// Worker threads (default: all cores)
    #[arg(long, allow_negative_numbers = true)]
    pub threads: Option<usize>,
    /// Memory budget for everything the render holds (e.g. 64MiB, 2GiB;
    /// default: half of the available memory)
    #[arg(long, value_parser = parse_memory)]
    pub memory: Option<u64>,
    /// Breadth-first store number: adaptive (the paper's), budget (the
    /// adaptive one, and a round's last pass gives the walks it cut short
    /// what its rays left of the memory: fewer scans for a round's last
    /// few rays, the same image; the work counts then depend on the
    /// budget), or a fixed number of voxels
    #[arg(long, default_value = "adaptive", value_parser = parse_store)]
    pub store_number: StoreNumber,
    /// Breadth-first shading: carry (surfaces found with the hits) or join
    /// (the paper's sort-and-scan of the objects)
    #[arg(long, default_value = "carry")]
    pub shading: Shading,
    /// Breadth-first: hold the models a scene's instances place for the
    /// whole render (held), or read each in the passes that need it, one
    /// at a time (per-pass: the memory of the largest model, not of all);
    /// auto holds them when they take at most a quarter of --memory
    #[arg(long, default_value = "auto", value_name = "auto|held|per-pass")]
    pub models: ModelHolding,
    /// Breadth-first: read every block of the database in every pass, as
    /// the paper does, instead of passing over the blocks no ray is near
    /// (slower; the same image; for reproducing the paper's figures; a
    /// depth-first render reads the database once anyway)
    #[arg(long)]
    pub full_scans: bool,
    /// The order a database made for the render stores objects in: spatial (along a
    /// Z-order curve, each keeping its input id for ties: blocks that
    /// passes can skip, meshes stored compactly), input (as listed), or
    /// auto (spatial for scene files, input for SPD generators, whose
    /// order is spatial already)
    #[arg(long, value_parser = sray_engine::job::ObjectOrder::parse, default_value = "auto", value_name = "auto|spatial|input")]
    pub order: sray_engine::job::ObjectOrder,
    /// Intersection arithmetic: double or single
    #[arg(long, default_value = "double")]
    pub precision: Precision,
    /// Eye rays per pixel: 1 traces the pixel corners (the SPD's sampling);
    /// 4, 9, 16, ... take that many jittered samples per pixel
    #[arg(long, allow_negative_numbers = true, default_value_t = 1)]
    pub samples: u32,
    /// SIMD width of the intersection kernels: auto (the widest this CPU
    /// has, or the one the SRAY_SIMD environment variable names),
    /// portable, sse, avx2, avx512 or neon. The image and every count are
    /// the same with each
    #[arg(
        long,
        default_value = "auto",
        value_name = "auto|portable|sse|avx2|avx512|neon"
    )]
    pub simd: SimdWidth,
    /// Time the depth-first tracer's intersection queries, to split its
    /// trace time into intersection and shading (costs a little time)
    #[arg(long)]
    pub profile: bool,
    /// Write statistics as JSON to this file
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// No progress bars, and no summary line at the end (errors are still
    /// printed)
    #[arg(short, long)]
    pub quiet: bool,
    /// Directory for temporary files (default: the system's)
    #[arg(long)]
    pub tmp_dir: Option<PathBuf>,
    /// Render on the cluster whose coordinator is at URL (http://HOST:PORT,
    /// or https:// with --tls-ca)
    #[arg(long, conflicts_with = "local_workers")]
    pub coordinator: Option<String>,
    /// Start N worker processes on this machine, render on them, stop them
    #[arg(long, allow_negative_numbers = true)]
    pub local_workers: Option<usize>,
    /// Rays per shard on a cluster (default: the coordinator's, 65536)
    #[arg(long, allow_negative_numbers = true)]
    pub shard_rays: Option<u64>,
    #[command(flatten)]
    pub conn: super::cluster::conn::ClientConn,
    #[command(flatten)]
    pub setup: SetupArgs,
}

fn parse_memory(s: &str) -> Result<u64, String> {
    sray_engine::units::parse_bytes(s)
}

fn parse_store(s: &str) -> Result<StoreNumber, String> {
    match s {
        "adaptive" => return Ok(StoreNumber::Adaptive),
        "budget" => return Ok(StoreNumber::Budget),
        _ => {}
    }
    match s.parse::<u32>() {
        Ok(n) if (1..=65_536).contains(&n) => Ok(StoreNumber::Fixed(n)),
        _ => Err(format!(
            "--store-number takes budget, adaptive or a number from 1 to 65536, not '{s}'"
        )),
    }
}

/// `--aggregates`: which tracers hold crowded groups of objects as
/// aggregates (Section 2.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum AggregatesArg {
    /// Breadth-first
    Auto,
    /// Both tracers
    On,
    /// Neither
    Off,
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

/// `--simd`: `auto` (no forced width) or an instruction set's name.
#[derive(Clone, Copy, Debug)]
pub struct SimdWidth(pub Option<sray_engine::simd::Isa>);

impl std::str::FromStr for SimdWidth {
    type Err = String;
    fn from_str(s: &str) -> Result<SimdWidth, String> {
        match s {
            "auto" => Ok(SimdWidth(None)),
            s => s.parse().map(|i| SimdWidth(Some(i))),
        }
    }
}

pub fn run(a: RenderArgs) -> anyhow::Result<()> {
    super::bar::set_quiet(a.quiet);
    if a.threads == Some(0) {
        anyhow::bail!("--threads must be at least 1");
    }
    if a.full_scans && (a.coordinator.is_some() || a.local_workers.is_some()) {
        anyhow::bail!(
            "--full-scans is for renders in this process (the paper's experiments), not on a cluster"
        );
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
            aggregates: match a.aggregates {
                AggregatesArg::Auto => Aggregates::Auto,
                AggregatesArg::On => Aggregates::On,
                AggregatesArg::Off => Aggregates::Off,
            },
            precision: a.precision,
            profile: a.profile,
            samples: a.samples,
            simd: a.simd.0,
        },
        mode: a.mode,
        memory: a.memory,
        store: a.store_number,
        shading: a.shading,
        models: a.models,
        full_scans: a.full_scans,
        order: a.order,
        tmp_dir: a.tmp_dir.clone(),
        setup: a.setup.setup([a.width, a.height])?,
    };
    let outputs = Outputs::open(&a.output, a.stats.as_deref())?;
    if a.coordinator.is_some() || a.local_workers.is_some() {
        return run_cluster(&a, &req, outputs);
    }
    let result = render(&req, &BarStages)?;
    let format = outputs.format();
    outputs.write_with(
        |out| Ok(result.frame.write_image(format, out)?),
        &result.stats,
    )?;
    summary::print(&serde_json::to_value(&result.stats)?, &a.output, a.quiet);
    Ok(())
}

/// Renders on a cluster: a remote coordinator, or local worker processes.
fn run_cluster(a: &RenderArgs, req: &RenderRequest, outputs: Outputs) -> anyhow::Result<()> {
    use super::cluster::{client, local};
    if req.mode == Mode::Df {
        anyhow::bail!(
            "a cluster renders breadth-first: --mode df cannot be used with --coordinator or --local-workers"
        );
    }
    if a.profile {
        anyhow::bail!("--profile times the depth-first tracer, which does not run on a cluster");
    }
    req.options.validate()?;
    let t0 = std::time::Instant::now();
    // The camera, lights and material are baked into the database the
    // workers read: nothing of them travels in the render settings.
    let scene = sray_engine::job::prepare(
        &req.scene,
        &PrepareOptions {
            tmp_dir: req.tmp_dir.as_deref(),
            memory: req
                .memory
                .unwrap_or_else(sray_engine::sys::default_memory_budget),
            setup: &req.setup,
            order: req.order,
        },
        &BarStages,
    )?;
    let params = sray_worker::params::to_proto(&req.options, req.store);
    let shard_rays = a.shard_rays.unwrap_or(0);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let bar = Bar::new("cluster", "");
    let db = scene.db.path().to_path_buf();
    let format = outputs.format();
    let result = rt.block_on(async {
        match (&a.coordinator, a.local_workers) {
            (Some(url), _) => {
                let target = a.conn.target(url)?;
                client::render(&target, &db, params, shard_rays, format, &bar).await
            }
            (None, Some(n)) => {
                let plan = local::LocalPlan {
                    workers: n,
                    memory: req
                        .memory
                        .unwrap_or_else(sray_engine::sys::default_memory_budget),
                    threads: req.options.threads,
                    tmp_dir: req.tmp_dir.clone(),
                };
                local::render(&plan, &db, params, shard_rays, format, &bar).await
            }
            (None, None) => unreachable!("checked by the caller"),
        }
    });
    bar.finish();
    let mut result = result?;
    result.stats["convert_seconds"] = scene.convert_seconds.into();
    result.stats["client_seconds"] = t0.elapsed().as_secs_f64().into();
    outputs.write(&result.image, &result.stats)?;
    summary::print(&result.stats, &a.output, a.quiet);
    Ok(())
}

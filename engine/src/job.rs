//! One render, start to finish: resolve the scene into an object database,
//! pick the tracer, trace, write the image and statistics.

use crate::bf::{self, BfOptions, Shading, StoreNumber};
use crate::df;
use crate::error::{Error, IoContext};
use crate::mesh::MeshOptions;
use crate::progress::{Progress, RenderRounds};
use crate::render::{Frame, Mode, RenderOptions, RenderStats};
use crate::scene::setup::{Setup, SetupSink};
use crate::sdb::{Compression, Database, DbWriter};
use crate::source::SceneSource;
use crate::units::fmt_bytes;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What to render and how.
#[derive(Clone, Debug)]
pub struct RenderRequest {
    pub scene: SceneSource,
    pub options: RenderOptions,
    pub mode: Mode,
    /// Memory budget in bytes (default: half of the available memory).
    pub memory: Option<u64>,
    pub store: StoreNumber,
    /// Where the breadth-first tracer's shading gets surfaces.
    pub shading: Shading,
    /// Whether the breadth-first tracer holds the models instances place.
    pub models: crate::bf::ModelHolding,
    /// Where temporary databases and spilled rays go (default: the system's
    /// temp dir).
    pub tmp_dir: Option<PathBuf>,
    /// Camera, lights and material from the command line, and the
    /// defaults of meshes (its image size is the render's).
    pub setup: Setup,
    /// Breadth-first passes read every block, as the paper's do
    /// ([`Database::set_full_scans`]).
    pub full_scans: bool,
    /// The order a database made for the render stores objects in.
    pub order: ObjectOrder,
}

/// The order a new database stores its objects in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ObjectOrder {
    /// Spatial for scene files (meshes, NFF, glTF), whose order is
    /// whatever their writer chose, and for databases rewritten (their
    /// objects keep their input ids); the input's for SPD generators, which
    /// emit their objects by recursive subdivision, already in a spatial
    /// order.
    #[default]
    Auto,
    /// Along a Z-order curve through the objects' centres, each keeping
    /// its input id for ties ([`crate::sdb::SpatialSorter`]; version 6).
    Spatial,
    /// As the input lists them (version 4 or 5).
    Input,
}

impl ObjectOrder {
    pub fn parse(s: &str) -> Result<ObjectOrder, String> {
        match s {
            "auto" => Ok(ObjectOrder::Auto),
            "spatial" => Ok(ObjectOrder::Spatial),
            "input" => Ok(ObjectOrder::Input),
            _ => Err(format!("unknown order {s:?}: auto, spatial or input")),
        }
    }

    /// Whether a database of `scene` is written in spatial order.
    pub fn is_spatial_for(self, scene: &SceneSource) -> bool {
        match self {
            ObjectOrder::Spatial => true,
            ObjectOrder::Input => false,
            ObjectOrder::Auto => !matches!(scene, SceneSource::Spd { .. }),
        }
    }
}

/// The share of a conversion's budget the spatial sort gathers records
/// in before it writes them, sorted, to a temporary file.
pub fn sort_memory(budget: u64) -> usize {
    (budget / 4).min(1 << 30) as usize
}

pub struct RenderResult {
    pub frame: Frame,
    pub stats: RenderStats,
}

/// Progress for the stages of a render.
pub trait Stages {
    /// A new stage begins; the returned progress reports within it.
    fn stage(&self, name: &str) -> Box<dyn Progress + '_>;
}

/// A scene as an object database, and the temporary directory holding it
/// when it had to be made (removed when this is dropped).
pub struct PreparedScene {
    pub db: Database,
    _tmp: Option<tempfile::TempDir>,
    pub convert_seconds: f64,
}

/// How [`prepare`] makes a database of a scene.
#[derive(Clone, Copy, Debug)]
pub struct PrepareOptions<'a> {
    /// Where the database and spill files go (the system's temp dir if
    /// `None`).
    pub tmp_dir: Option<&'a Path>,
    /// Memory budget of the conversion (a mesh's tables and sorts).
    pub memory: u64,
    pub setup: &'a Setup,
    /// The order the database stores objects in.
    pub order: ObjectOrder,
}

/// Output buffer of a database written under a memory budget.
pub const BUDGET_WRITE_BUFFER: usize = 1 << 20;

/// Least `--memory` that reads a mesh: the reader's tables and sorts
/// ([`crate::mesh::builder::MIN_MEMORY`]), the input's buffers and the
/// database writer's.
pub const MIN_MESH_MEMORY: u64 = 2 << 20;

/// What a mesh reader may hold of a conversion's budget: the rest after
/// the input's and the database writer's buffers.
pub fn mesh_memory(budget: u64) -> Result<u64, Error> {
    if budget < MIN_MESH_MEMORY {
        return Err(Error::Invalid(format!(
            "--memory {} is too small to read a mesh: at least {}",
            fmt_bytes(budget),
            fmt_bytes(MIN_MESH_MEMORY)
        )));
    }
    let fixed =
        crate::input::INPUT_BYTES + BUDGET_WRITE_BUFFER as u64 + DbWriter::HELD_BYTES as u64;
    Ok(budget
        .saturating_sub(fixed)
        .max(crate::mesh::builder::MIN_MEMORY))
}

/// Streams `scene` through `setup` into the database writer `w`; refuses
/// a mesh that leaves nothing to render.
pub fn write_database(
    scene: &SceneSource,
    w: &mut DbWriter,
    opts: &PrepareOptions<'_>,
    progress: &dyn crate::progress::Progress,
) -> Result<(), Error> {
    let spatial = opts.order.is_spatial_for(scene);
    // A database in spatial order rewritten in input order goes back to
    // the order of its input ids.
    let restore = !spatial
        && match scene {
            SceneSource::Database(p) => Database::open(p)?.is_spatial(),
            _ => false,
        };
    // The sort's chunk comes out of the budget before the reader's share.
    let budget = if spatial || restore {
        let sort = sort_memory(opts.memory);
        if spatial {
            w.sort_spatially(sort, opts.tmp_dir);
        } else {
            w.sort_by_id(sort, opts.tmp_dir);
        }
        let rest = opts
            .memory
            .saturating_sub(crate::sdb::SpatialSorter::held_bytes(sort) as u64);
        // Below the least a mesh needs, the reader's own error says so.
        if opts.memory < MIN_MESH_MEMORY {
            opts.memory
        } else {
            rest.max(MIN_MESH_MEMORY)
        }
    } else {
        opts.memory
    };
    let mesh_opts = MeshOptions {
        memory: if scene.is_mesh() {
            mesh_memory(budget)?
        } else {
            budget
        },
        spill_dir: opts.tmp_dir.map(Path::to_path_buf),
        camera_index: opts.setup.camera_index,
    };
    let mut s = SetupSink::new(w, opts.setup);
    let summary = scene.stream_into_with(&mut s, progress, &mesh_opts)?;
    s.finish()?;
    if spatial || restore {
        // The sorted chunks are merged when the writer finishes: say so,
        // rather than sit at the last object.
        progress.set_message(if spatial {
            "putting objects in spatial order"
        } else {
            "putting objects back in input order"
        });
    }
    if let Some(m) = summary.mesh
        && m.objects == 0
    {
        return Err(Error::Scene(if m.faces == 0 {
            format!(
                "{scene}: nothing to render: the mesh has no faces (a point cloud of {} vertices)",
                m.vertices
            )
        } else {
            format!(
                "{scene}: nothing to render: all {} faces of the mesh are degenerate",
                m.faces
            )
        }));
    }
    Ok(())
}

/// Opens a database directly (unless the setup changes it), or streams a
/// scene file or an SPD generator into a temporary one.
pub fn prepare(
    scene: &SceneSource,
    opts: &PrepareOptions<'_>,
    stages: &dyn Stages,
) -> Result<PreparedScene, Error> {
    let tmp_dir = opts.tmp_dir;
    if let SceneSource::Database(p) = scene
        && opts.setup.overrides_nothing()
    {
        return Ok(PreparedScene {
            db: Database::open(p)?,
            _tmp: None,
            convert_seconds: 0.0,
        });
    }
    let t = Instant::now();
    let dir = match tmp_dir {
        Some(d) => tempfile::Builder::new()
            .prefix("sray-")
            .tempdir_in(d)
            .at(d)?,
        None => tempfile::Builder::new()
            .prefix("sray-")
            .tempdir()
            .at(std::env::temp_dir())?,
    };
    let path = dir.path().join("scene.sdb");
    let progress = stages.stage("preparing scene");
    let mut w = DbWriter::create_with_buffer(&path, Compression::None, BUDGET_WRITE_BUFFER)?;
    write_database(scene, &mut w, opts, &*progress)?;
    w.finish()?;
    drop(progress);
    Ok(PreparedScene {
        db: Database::open(&path)?,
        _tmp: Some(dir),
        convert_seconds: t.elapsed().as_secs_f64(),
    })
}

/// Picks the tracer: as asked, or for `auto` depth-first when the scene
/// and the frame (`frame_slots` slots) fit in the budget (the paper's
/// Fig. 1). Returns the mode and why.
pub fn choose_mode(mode: Mode, db: &Database, frame_slots: u64, memory: u64) -> (Mode, String) {
    match mode {
        Mode::Df => (Mode::Df, "requested with --mode df".into()),
        Mode::Bf => (Mode::Bf, "requested with --mode bf".into()),
        Mode::Auto => {
            let need = df::estimate_bytes(db) + Frame::memory_bytes(frame_slots);
            if need <= memory {
                (
                    Mode::Df,
                    format!(
                        "auto: the scene needs about {} in memory, within the budget of {}",
                        fmt_bytes(need),
                        fmt_bytes(memory)
                    ),
                )
            } else {
                (
                    Mode::Bf,
                    format!(
                        "auto: the scene would need about {} in memory, more than the budget of {}",
                        fmt_bytes(need),
                        fmt_bytes(memory)
                    ),
                )
            }
        }
    }
}

/// Renders a request.
pub fn render(req: &RenderRequest, stages: &dyn Stages) -> Result<RenderResult, Error> {
    let t0 = Instant::now();
    req.options.validate()?;
    let memory = req.memory.unwrap_or_else(crate::sys::default_memory_budget);
    let setup = Setup {
        image: [req.options.width, req.options.height],
        ..req.setup.clone()
    };
    let mut scene = prepare(
        &req.scene,
        &PrepareOptions {
            tmp_dir: req.tmp_dir.as_deref(),
            memory,
            setup: &setup,
            order: req.order,
        },
        stages,
    )?;
    scene.db.set_full_scans(req.full_scans);
    let (mode, reason) = choose_mode(req.mode, &scene.db, req.options.frame_slots(), memory);
    let progress = stages.stage("rendering");
    let (frame, mut stats) = match mode {
        Mode::Bf => {
            // One count of rays for the whole render, not one per round.
            let rounds = RenderRounds::new(
                &*progress,
                req.options.max_depth,
                scene.db.scene().lights.len(),
            );
            let out = bf::render(
                &scene.db,
                &req.options,
                &BfOptions {
                    memory,
                    store: req.store,
                    spill_dir: req.tmp_dir.clone(),
                    shading: req.shading,
                    models: req.models,
                },
                &rounds,
            )?;
            rounds.finish();
            (out.frame, out.stats)
        }
        _ => {
            // A scene larger than the budget, forced depth-first: in the
            // paging experiment's binary (`sray-paged`, which installs the
            // file-backed allocator), its big arrays go to file-backed
            // memory, which pages as RayShade's heap did through swap,
            // instead of exceeding the budget. Elsewhere they stay in
            // ordinary memory, and the user is told.
            let need = df::estimate_bytes(&scene.db);
            let paged = need > memory && {
                let dir = req.tmp_dir.clone().unwrap_or_else(std::env::temp_dir);
                let on = crate::paging::enable(&dir).at(&dir)?;
                if !on {
                    progress.warn(&format!(
                        "the depth-first tracer needs about {} for this scene, more than the \
                         budget of {}: it renders in memory all the same (sray-paged, the paging \
                         experiment's binary, would page to a file)",
                        fmt_bytes(need),
                        fmt_bytes(memory)
                    ));
                }
                on
            };
            let out = df::render_within(&scene.db, &req.options, memory, &*progress)?;
            let mut stats = out.stats;
            if paged {
                stats.details = Some(serde_json::json!({
                    "df_paged": true,
                    "df_paged_peak_bytes": crate::paging::mapped_bytes().1,
                }));
            }
            (out.frame, stats)
        }
    };
    drop(progress);
    stats.mode_reason = reason;
    stats.convert_seconds = scene.convert_seconds;
    stats.total_seconds = t0.elapsed().as_secs_f64();
    Ok(RenderResult { frame, stats })
}

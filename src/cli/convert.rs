//! `sray convert`: the paper's preprocess into binary form (or back to NFF).

use super::bar::Bar;
use super::render::SetupArgs;
use super::{OutputKind, output_kind, parse_compression};
use anyhow::Context;
use clap::Args;
use sray_engine::job::{BUDGET_WRITE_BUFFER, ObjectOrder, PrepareOptions, write_database};
use sray_engine::mesh::MeshOptions;
use sray_engine::nff::NffWriter;
use sray_engine::progress::Progress;
use sray_engine::scene::setup::{Setup, SetupSink};
use sray_engine::sdb::{Compression, DbWriter};
use sray_engine::source::SceneSource;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct ConvertArgs {
    /// The scene: a scene file (.nff, .ply, .obj, .off, .gltf, .glb, any of them .gz or
    /// .zst compressed), an .sdb file, or spd:NAME:SIZE
    pub scene: String,
    /// Output file: .sdb for an object database, .nff for NFF text
    #[arg(short, long)]
    pub output: PathBuf,
    /// Compress the object database: none, zstd or zstd:LEVEL (1-22)
    #[arg(long, value_parser = parse_compression, default_value = "none")]
    pub compress: Compression,
    /// Memory budget of the conversion (a mesh's vertex and face tables
    /// and sorts; the rest goes to --tmp-dir), e.g. 64MiB (default: half
    /// of the available memory)
    #[arg(long, value_parser = parse_memory)]
    pub memory: Option<u64>,
    /// Directory for temporary files (default: the system's)
    #[arg(long)]
    pub tmp_dir: Option<PathBuf>,
    /// The order the database stores objects in: spatial (along a
    /// Z-order curve, each keeping its input id for ties: blocks that
    /// passes can skip, meshes stored compactly), input (as listed), or
    /// auto (spatial for scene files, input for SPD generators, whose
    /// order is spatial already)
    #[arg(long, value_parser = sray_engine::job::ObjectOrder::parse, default_value = "auto", value_name = "auto|spatial|input")]
    pub order: sray_engine::job::ObjectOrder,
    /// No progress bar (errors are still printed)
    #[arg(short, long)]
    pub quiet: bool,
    #[command(flatten)]
    pub setup: SetupArgs,
}

fn parse_memory(s: &str) -> Result<u64, String> {
    sray_engine::units::parse_bytes(s)
}

pub fn run(a: ConvertArgs) -> anyhow::Result<()> {
    super::bar::set_quiet(a.quiet);
    let source = SceneSource::parse(&a.scene)?;
    let bar = match source {
        SceneSource::File { format, .. } if format.progress_in_bytes() => Bar::bytes("convert"),
        _ => Bar::new("convert", "objects"),
    };
    let setup = a.setup.setup([512, 512])?;
    let memory = a
        .memory
        .unwrap_or_else(sray_engine::sys::default_memory_budget);
    write_scene(
        &source,
        &a.output,
        a.compress,
        &PrepareOptions {
            tmp_dir: a.tmp_dir.as_deref(),
            memory,
            setup: &setup,
            order: a.order,
        },
        &bar,
    )?;
    bar.finish();
    Ok(())
}

/// Streams `source` into `output` (.sdb or .nff, by extension), through
/// `opts.setup` (a mesh's default view and lights, the command line's
/// overrides), atomically.
pub fn write_scene(
    source: &SceneSource,
    output: &Path,
    compress: Compression,
    opts: &PrepareOptions<'_>,
    progress: &dyn Progress,
) -> anyhow::Result<()> {
    match output_kind(output)? {
        OutputKind::Database => {
            let mut w = DbWriter::create_with_buffer(output, compress, BUDGET_WRITE_BUFFER)?;
            write_database(source, &mut w, opts, progress)?;
            w.finish()?;
        }
        OutputKind::Nff => {
            if compress != Compression::None {
                anyhow::bail!("--compress applies to .sdb output only");
            }
            // NFF has no instances: a database that stores models placed
            // by instances cannot be written as NFF (the scene it was made
            // from can: its placements are written as copies).
            let spatial = match source {
                SceneSource::Database(p) => {
                    let db = sray_engine::sdb::Database::open(p)?;
                    let models = db.models().len();
                    if models > 0 {
                        anyhow::bail!(
                            "{}: this object database stores {models} model(s) placed by \
                             instances, which NFF cannot express, so it cannot be converted to \
                             {}; convert the scene it was made from (the .gltf or .glb) to .nff \
                             instead, which writes every placement as a copy",
                            p.display(),
                            output.display()
                        );
                    }
                    db.is_spatial()
                }
                _ => false,
            };
            // NFF numbers objects by their place: a database in spatial
            // order is put back in its input's order first, so that ties
            // (which go by input id) stay as they were.
            if spatial {
                let dir = match opts.tmp_dir {
                    Some(d) => tempfile::Builder::new().prefix("sray-").tempdir_in(d)?,
                    None => tempfile::Builder::new().prefix("sray-").tempdir()?,
                };
                let restored = dir.path().join("input-order.sdb");
                let mut w = DbWriter::create_with_buffer(&restored, compress, BUDGET_WRITE_BUFFER)?;
                let plain = no_setup();
                let restore = PrepareOptions {
                    setup: &plain,
                    order: ObjectOrder::Input,
                    ..*opts
                };
                write_database(source, &mut w, &restore, progress)?;
                w.finish()?;
                return write_scene(
                    &SceneSource::Database(restored),
                    output,
                    compress,
                    opts,
                    progress,
                );
            }
            let tmp = sray_engine::fsutil::temp_beside(output)?;
            let mut w = NffWriter::new(BufWriter::with_capacity(1 << 20, tmp), output);
            let mesh_opts = MeshOptions {
                memory: if source.is_mesh() {
                    sray_engine::job::mesh_memory(opts.memory)?
                } else {
                    opts.memory
                },
                spill_dir: opts.tmp_dir.map(Path::to_path_buf),
                camera_index: opts.setup.camera_index,
            };
            {
                let mut s = SetupSink::new(&mut w, opts.setup);
                source.stream_into_with(&mut s, progress, &mesh_opts)?;
                s.finish()?;
            }
            let mut buf = w.into_inner();
            buf.flush().with_context(|| output.display().to_string())?;
            let tmp = buf
                .into_inner()
                .map_err(|e| e.into_error())
                .with_context(|| output.display().to_string())?;
            sray_engine::fsutil::persist(tmp, output)?;
        }
    }
    Ok(())
}

/// A setup that changes nothing (for generated scenes).
pub fn no_setup() -> Setup {
    Setup::default()
}

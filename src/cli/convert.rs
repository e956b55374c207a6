//! `sray convert`: the paper's preprocess into binary form (or back to NFF).

use super::bar::Bar;
use super::{OutputKind, output_kind, parse_compression};
use anyhow::Context;
use clap::Args;
use sray_engine::nff::NffWriter;
use sray_engine::progress::Progress;
use sray_engine::sdb::{Compression, DbWriter};
use sray_engine::source::SceneSource;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub struct ConvertArgs {
    /// The scene: an .nff file, an .sdb file, or spd:NAME:SIZE
    pub scene: String,
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

pub fn run(a: ConvertArgs) -> anyhow::Result<()> {
    super::bar::set_quiet(a.quiet);
    let source = SceneSource::parse(&a.scene)?;
    let bar = match source {
        SceneSource::File { format, .. } if format.progress_in_bytes() => Bar::bytes("convert"),
        _ => Bar::new("convert", "objects"),
    };
    write_scene(&source, &a.output, a.compress, &bar)?;
    bar.finish();
    Ok(())
}

/// Streams `source` into `output` (.sdb or .nff, by extension), atomically.
pub fn write_scene(
    source: &SceneSource,
    output: &Path,
    compress: Compression,
    progress: &dyn Progress,
) -> anyhow::Result<()> {
    match output_kind(output)? {
        OutputKind::Database => {
            let mut w = DbWriter::create(output, compress)?;
            source.stream_into(&mut w, progress)?;
            w.finish()?;
        }
        OutputKind::Nff => {
            if compress != Compression::None {
                anyhow::bail!("--compress applies to .sdb output only");
            }
            let tmp = sray_engine::fsutil::temp_beside(output)?;
            let mut w = NffWriter::new(BufWriter::with_capacity(1 << 20, tmp), output);
            source.stream_into(&mut w, progress)?;
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

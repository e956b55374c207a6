//! The `sray` command line.

mod bar;
mod cluster;
mod cluster_cmd;
mod convert;
mod gen_cmd;
mod info_cmd;
mod outputs;
mod render;
mod summary;
mod verify;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "sray",
    version,
    about = "Breadth-first ray tracing for scene databases larger than memory",
    long_about = "sray renders NFF scenes, PLY, OBJ and OFF meshes and the Standard Procedural Databases, depth-first in memory \
                  or breadth-first from an object database on disk (Nakamaru & Ohno), on one machine or a cluster."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Render a scene (.nff, .ply, .obj, .off, .gltf, .glb, .sdb or spd:NAME:SIZE) to a PNG or OpenEXR image
    Render(Box<render::RenderArgs>),
    /// Generate an SPD scene (balls, gears, mount, rings, tetra, tree, teapot)
    Gen(gen_cmd::GenArgs),
    /// Convert a scene (.nff, .ply, .obj, .off, .gltf, .glb, .sdb or spd:NAME:SIZE) to an object database or NFF
    Convert(convert::ConvertArgs),
    /// Describe a scene file (.nff, .ply, .obj, .off, .gltf, .glb or .sdb)
    Info(info_cmd::InfoArgs),
    /// Read a whole object database, checking every block, and report the read speed
    Verify(verify::VerifyArgs),
    /// Serve a cluster: workers register here, clients submit renders here
    Coordinator(cluster_cmd::CoordinatorArgs),
    /// Join a cluster: take intersection and shading work from a coordinator
    Worker(cluster_cmd::WorkerArgs),
    /// Get the image of a job submitted to a cluster (again, or after the client lost its connection)
    Fetch(cluster::fetch::FetchArgs),
    /// Show a cluster's workers and jobs (a table, or JSON with --json)
    Status(cluster::status::StatusArgs),
    /// Run the benchmarks (the paper's experiments, POV-Ray, speed against accuracy)
    Bench(sray_bench::BenchArgs),
}

/// Runs the command line; errors are printed and turned into exit code 1.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(a) => render::run(*a),
        Command::Gen(a) => gen_cmd::run(a),
        Command::Convert(a) => convert::run(a),
        Command::Info(a) => info_cmd::run(a),
        Command::Verify(a) => verify::run(a),
        Command::Bench(a) => sray_bench::run(a),
        Command::Coordinator(a) => cluster_cmd::coordinator(a),
        Command::Worker(a) => cluster_cmd::worker(a),
        Command::Fetch(a) => cluster::fetch::run(a),
        Command::Status(a) => cluster::status::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("sray: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Writes `text` to stdout. A reader that has gone (`sray info X | head`,
/// which closes the pipe after ten lines) ends the output quietly: that is
/// not an error, and nothing is left to say.
pub(crate) fn print_stdout(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => Ok(r?),
    }
}

/// Output kinds chosen by file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum OutputKind {
    Database,
    Nff,
}

pub(crate) fn output_kind(path: &std::path::Path) -> anyhow::Result<OutputKind> {
    match path.extension().and_then(|e| e.to_str()) {
        Some("sdb") => Ok(OutputKind::Database),
        Some("nff") => Ok(OutputKind::Nff),
        _ => anyhow::bail!(
            "{}: the output must end in .sdb (object database) or .nff (NFF text)",
            path.display()
        ),
    }
}

/// `--compress` values.
pub(crate) fn parse_compression(s: &str) -> Result<sray_engine::sdb::Compression, String> {
    sray_engine::sdb::Compression::parse(s)
}

//! `sray verify`: read every block of an object database front to back,
//! checking every checksum, and report the sequential read speed.

use super::bar::Bar;
use clap::Args;
use sray_engine::sdb::Database;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct VerifyArgs {
    /// An .sdb file
    pub file: PathBuf,
    /// Print one JSON object on stdout
    #[arg(long)]
    pub json: bool,
    /// No progress bar (errors are still printed)
    #[arg(short, long)]
    pub quiet: bool,
}

pub fn run(a: VerifyArgs) -> anyhow::Result<()> {
    super::bar::set_quiet(a.quiet);
    let db = Database::open(&a.file)?;
    let bar = Bar::bytes("verify");
    bar.0.set_length(db.file_bytes());
    let start = Instant::now();
    let mut objects = 0u64;
    let mut raw = 0u64;
    let mut read = 0u64;
    let mut blocks = 0u64;
    // The world's blocks, then each model's (version 5), as a pass
    // reads them.
    let parts =
        std::iter::once(Ok(db.clone())).chain((0..db.models().len()).map(|m| db.open_model(m)));
    for part in parts {
        let part = part?;
        let mut scan = part.scan_checked()?;
        // In spatial order each input id must occur exactly once.
        let mut seen = part
            .is_spatial()
            .then(|| vec![0u64; (part.object_count() as usize).div_ceil(64)]);
        while let Some(block) = scan.next_block()? {
            if let Some(seen) = seen.as_mut() {
                for &id in block.ids() {
                    let (w, bit) = (id as usize / 64, 1u64 << (id % 64));
                    if seen[w] & bit != 0 {
                        anyhow::bail!(
                            "{}: block {}: input id {id} occurs twice: the database is corrupt",
                            a.file.display(),
                            block.index
                        );
                    }
                    seen[w] |= bit;
                }
            }
            objects += block.object_count as u64;
            raw += block.raw_bytes() as u64;
            bar.0.set_position(read + scan.stats().bytes_read);
        }
        read += scan.stats().bytes_read;
        blocks += scan.stats().blocks_read;
    }
    let secs = start.elapsed().as_secs_f64();
    bar.finish();
    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    if a.json {
        super::print_stdout(&format!(
            "{}\n",
            serde_json::json!({
                "objects": objects,
                "blocks": blocks,
                "bytes_read": read,
                "raw_bytes": raw,
                "seconds": secs,
                "read_mib_per_s": mib(read) / secs,
                "decoded_mib_per_s": mib(raw) / secs,
            })
        ))?;
    } else {
        super::print_stdout(&format!(
            "{}: ok, {objects} objects in {} blocks; read {:.1} MiB in {secs:.3} s ({:.0} MiB/s stored, {:.0} MiB/s decoded)\n",
            a.file.display(),
            blocks,
            mib(read),
            mib(read) / secs,
            mib(raw) / secs
        ))?;
    }
    Ok(())
}

//! Spilling to disk: the directory temporary files go to, files of
//! fixed-size records, and an external merge sort over them (memory-sized
//! runs, sorted and written out, merged with one sequential read of each
//! run). The breadth-first tracer keeps rays and results here when they do
//! not fit its memory budget; the cluster coordinator keeps rounds here.

mod radix;
mod record_file;
mod records;
mod sort;

pub use radix::{Scratch as RadixScratch, sort_by_key as radix_sort_by_key};
pub use record_file::{RecordFile, RecordReader, RecordWriter};
pub use records::{Lease, MemoryShare, Records, RecordsReader, RecordsWriter};
pub use sort::{ExternalSorter, Sorted};

use crate::error::{Error, IoContext};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering as AtomicOrdering};

/// Bytes the radix sort of an [`ExternalSorter`]'s buffer needs per record
/// besides the record (keys and indices, twice): what a sorter holding `n`
/// records takes is `n * (size_of::<T>() + RADIX_BYTES_PER_RECORD)`.
pub const RADIX_BYTES_PER_RECORD: usize = 24;

/// Buffer size of record readers and writers.
pub const IO_BUFFER: usize = 32 << 10;
/// Buffer size of each run's reader while merging, and the most runs merged
/// at once: a merge holds at most `MERGE_FANIN * MERGE_BUFFER` bytes of
/// buffers, however many runs there are.
pub const MERGE_BUFFER: usize = 4 << 10;
pub const MERGE_FANIN: usize = 16;

/// Where temporary files go, and how many bytes have been written there.
#[derive(Clone, Debug)]
pub struct SpillDir {
    dir: Arc<tempfile::TempDir>,
    written: Arc<AtomicU64>,
    next: Arc<AtomicU64>,
}

impl SpillDir {
    pub fn new(parent: Option<&Path>) -> Result<SpillDir, Error> {
        let b = {
            let mut b = tempfile::Builder::new();
            b.prefix("sray-spill-");
            b
        };
        let dir = match parent {
            Some(p) => {
                std::fs::create_dir_all(p).at(p)?;
                b.tempdir_in(p).at(p)?
            }
            None => b.tempdir().at(std::env::temp_dir())?,
        };
        Ok(SpillDir {
            dir: Arc::new(dir),
            written: Arc::new(AtomicU64::new(0)),
            next: Arc::new(AtomicU64::new(0)),
        })
    }

    pub fn path(&self) -> &Path {
        self.dir.path()
    }

    /// A new file name in the directory.
    pub fn fresh(&self, what: &str) -> PathBuf {
        let n = self.next.fetch_add(1, AtomicOrdering::Relaxed);
        self.dir.path().join(format!("{what}-{n}.bin"))
    }

    pub fn bytes_written(&self) -> u64 {
        self.written.load(AtomicOrdering::Relaxed)
    }
}

/// A full spill disk is the commonest failure here; say so plainly.
pub(crate) fn spill_error(path: &Path, e: std::io::Error) -> Error {
    let full = match e.raw_os_error() {
        Some(libc::ENOSPC) => "no space left on the spill device",
        Some(libc::EFBIG) => "the file-size limit (ulimit -f) stops the spill file",
        Some(libc::EDQUOT) => "the disk quota of the spill device is used up",
        _ => return Error::io(path, e),
    };
    Error::Io {
        path: path.to_path_buf(),
        err: std::io::Error::other(format!(
            "{full} (use --tmp-dir, or a larger --memory to spill less)"
        )),
    }
}

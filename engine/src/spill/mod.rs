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

const NO_SPACE: &str = "no space left on the spill device";
const FILE_SIZE_LIMIT: &str = "the file-size limit (ulimit -f) stops the spill file";
const QUOTA: &str = "the disk quota of the spill device is used up";

/// Whether an error's message says that a disk (or a file-size limit or
/// quota) is full: the process lacks room, which freeing space cures,
/// rather than failing. Reads the messages of [`spill_error`] and those of
/// the system's errors (ENOSPC, EFBIG, EDQUOT) as Rust words them.
pub fn is_no_room(message: &str) -> bool {
    [NO_SPACE, FILE_SIZE_LIMIT, QUOTA]
        .iter()
        .any(|m| message.contains(m))
        || [libc::ENOSPC, libc::EFBIG, libc::EDQUOT]
            .iter()
            .any(|n| message.contains(&format!("(os error {n})")))
}

/// A full spill disk is the commonest failure here; say so plainly.
pub(crate) fn spill_error(path: &Path, e: std::io::Error) -> Error {
    let full = match e.raw_os_error() {
        Some(libc::ENOSPC) => NO_SPACE,
        Some(libc::EFBIG) => FILE_SIZE_LIMIT,
        Some(libc::EDQUOT) => QUOTA,
        _ => return Error::io(path, e),
    };
    Error::Io {
        path: path.to_path_buf(),
        err: std::io::Error::other(format!(
            "{full} (use --tmp-dir, or a larger --memory to spill less)"
        )),
    }
}

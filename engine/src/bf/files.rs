//! Files of fixed-size records in the spill directory, and an external
//! merge sort over them: memory-sized runs, sorted and written out, merged
//! with one sequential read of each run.

use crate::error::{Error, IoContext};
use bytemuck::Pod;
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::marker::PhantomData;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering as AtomicOrdering};

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

/// Appends records to a file.
pub struct RecordWriter<T: Pod> {
    out: BufWriter<File>,
    path: PathBuf,
    count: u64,
    spill: SpillDir,
    _t: PhantomData<T>,
}

impl<T: Pod> RecordWriter<T> {
    pub fn create(spill: &SpillDir, what: &str) -> Result<RecordWriter<T>, Error> {
        let path = spill.fresh(what);
        let f = File::create(&path).at(&path)?;
        Ok(RecordWriter {
            out: BufWriter::with_capacity(IO_BUFFER, f),
            path,
            count: 0,
            spill: spill.clone(),
            _t: PhantomData,
        })
    }

    pub fn push(&mut self, r: &T) -> Result<(), Error> {
        self.out
            .write_all(bytemuck::bytes_of(r))
            .map_err(|e| spill_error(&self.path, e))?;
        self.count += 1;
        Ok(())
    }

    pub fn extend(&mut self, rs: &[T]) -> Result<(), Error> {
        self.out
            .write_all(bytemuck::cast_slice(rs))
            .map_err(|e| spill_error(&self.path, e))?;
        self.count += rs.len() as u64;
        Ok(())
    }

    pub fn finish(mut self) -> Result<RecordFile<T>, Error> {
        self.out.flush().map_err(|e| spill_error(&self.path, e))?;
        self.spill.written.fetch_add(
            self.count * std::mem::size_of::<T>() as u64,
            AtomicOrdering::Relaxed,
        );
        // The file now belongs to the `RecordFile`.
        let path = std::mem::take(&mut self.path);
        Ok(RecordFile {
            path,
            count: self.count,
            _t: PhantomData,
        })
    }
}

/// A writer dropped unfinished (an error, an abandoned task) removes its
/// file.
impl<T: Pod> Drop for RecordWriter<T> {
    fn drop(&mut self) {
        if !self.path.as_os_str().is_empty() {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// A full spill disk is the commonest failure here; say so plainly.
fn spill_error(path: &Path, e: std::io::Error) -> Error {
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

/// A finished file of records; removed when dropped.
#[derive(Debug)]
pub struct RecordFile<T: Pod> {
    path: PathBuf,
    count: u64,
    _t: PhantomData<T>,
}

impl<T: Pod> Drop for RecordFile<T> {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

impl<T: Pod> RecordFile<T> {
    pub fn len(&self) -> u64 {
        self.count
    }
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
    pub fn reader(&self) -> Result<RecordReader<T>, Error> {
        self.reader_with(IO_BUFFER)
    }

    /// Reads records `start .. start + count` (clamped to the file).
    pub fn reader_range(&self, start: u64, count: u64) -> Result<RecordReader<T>, Error> {
        use std::io::{Seek, SeekFrom};
        let start = start.min(self.count);
        let mut f = File::open(&self.path).at(&self.path)?;
        f.seek(SeekFrom::Start(start * std::mem::size_of::<T>() as u64))
            .at(&self.path)?;
        Ok(RecordReader {
            input: BufReader::with_capacity(IO_BUFFER, f),
            path: self.path.clone(),
            left: count.min(self.count - start),
            _t: PhantomData,
        })
    }

    pub fn reader_with(&self, buffer: usize) -> Result<RecordReader<T>, Error> {
        let f = File::open(&self.path).at(&self.path)?;
        Ok(RecordReader {
            input: BufReader::with_capacity(buffer, f),
            path: self.path.clone(),
            left: self.count,
            _t: PhantomData,
        })
    }
}

/// Reads records front to back.
pub struct RecordReader<T: Pod> {
    input: BufReader<File>,
    path: PathBuf,
    left: u64,
    _t: PhantomData<T>,
}

impl<T: Pod> RecordReader<T> {
    pub fn remaining(&self) -> u64 {
        self.left
    }

    // Fallible, unlike `Iterator::next`: a read can fail.
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Result<Option<T>, Error> {
        if self.left == 0 {
            return Ok(None);
        }
        let mut r = T::zeroed();
        self.input
            .read_exact(bytemuck::bytes_of_mut(&mut r))
            .at(&self.path)?;
        self.left -= 1;
        Ok(Some(r))
    }
}

/// Sorts records of any number by `key`, holding at most `mem_records` in
/// memory: sorted runs spill to files and are merged. The memory buffer can
/// be handed in and taken back, so that repeated sorts reuse it.
pub struct ExternalSorter<T: Pod + Send, K: Ord + Copy, F: Fn(&T) -> K + Sync> {
    buf: Vec<T>,
    cap: usize,
    runs: Vec<RecordFile<T>>,
    key: F,
    spill: SpillDir,
    what: &'static str,
    scratch: super::radix::Scratch,
    _k: PhantomData<K>,
}

impl<T: Pod + Send, K: Ord + Copy + Send + Into<u64>, F: Fn(&T) -> K + Sync>
    ExternalSorter<T, K, F>
{
    pub fn new(spill: &SpillDir, what: &'static str, mem_records: usize, key: F) -> Self {
        Self::with_buffer(spill, what, mem_records, key, Vec::new())
    }

    /// As [`ExternalSorter::new`], using `buf`'s memory.
    pub fn with_buffer(
        spill: &SpillDir,
        what: &'static str,
        mem_records: usize,
        key: F,
        mut buf: Vec<T>,
    ) -> Self {
        buf.clear();
        ExternalSorter {
            buf,
            cap: mem_records.max(16),
            runs: Vec::new(),
            key,
            spill: spill.clone(),
            what,
            scratch: Default::default(),
            _k: PhantomData,
        }
    }

    pub fn push(&mut self, r: T) -> Result<(), Error> {
        if self.buf.len() == self.cap {
            self.spill_run()?;
        }
        if self.buf.capacity() == self.buf.len() {
            // Grow geometrically, but never past the memory share.
            let want = (self.buf.capacity() * 2).max(1 << 12).min(self.cap);
            self.buf.reserve_exact(want - self.buf.len());
        }
        self.buf.push(r);
        Ok(())
    }

    fn spill_run(&mut self) -> Result<(), Error> {
        let key = &self.key;
        super::radix::sort_by_key(&mut self.buf, |r| key(r).into(), &mut self.scratch);
        let mut w = RecordWriter::create(&self.spill, self.what)?;
        w.extend(&self.buf)?;
        self.runs.push(w.finish()?);
        self.buf.clear();
        Ok(())
    }

    /// Adds records already in key order, as one run of the merge.
    pub fn add_sorted_run(&mut self, run: RecordFile<T>) {
        if !run.is_empty() {
            self.runs.push(run);
        }
    }

    /// Records pushed so far.
    pub fn len(&self) -> u64 {
        self.runs.iter().map(|r| r.len()).sum::<u64>() + self.buf.len() as u64
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// All records in key order. Equal keys come in no particular order;
    /// callers use unique keys.
    pub fn finish(mut self) -> Result<Sorted<T, K, F>, Error> {
        let key = &self.key;
        super::radix::sort_by_key(&mut self.buf, |r| key(r).into(), &mut self.scratch);
        if self.runs.is_empty() {
            return Ok(Sorted(SortedInner::Memory {
                items: std::mem::take(&mut self.buf),
                at: 0,
            }));
        }
        if !self.buf.is_empty() {
            self.spill_run()?;
        }
        self.buf = Vec::new();
        // Merge groups of runs into longer ones until few enough remain.
        while self.runs.len() > MERGE_FANIN {
            let group: Vec<RecordFile<T>> = self.runs.drain(..MERGE_FANIN).collect();
            let mut merged = Merger::new(&group, &self.key)?;
            let mut w = RecordWriter::create(&self.spill, self.what)?;
            while let Some(x) = merged.next(&self.key)? {
                w.push(&x)?;
            }
            drop(merged);
            self.runs.push(w.finish()?);
        }
        let m = Merger::new(&self.runs, &self.key)?;
        let (readers, heap) = (m.readers, m.heap);
        Ok(Sorted(SortedInner::Merge {
            readers,
            heap,
            _runs: std::mem::take(&mut self.runs),
            key: self.key,
        }))
    }
}

/// A k-way merge of sorted runs.
struct Merger<T: Pod, K> {
    readers: Vec<RecordReader<T>>,
    heap: BinaryHeap<Head<T, K>>,
}

impl<T: Pod, K: Ord + Copy> Merger<T, K> {
    fn new(runs: &[RecordFile<T>], key: &impl Fn(&T) -> K) -> Result<Self, Error> {
        let mut readers = Vec::with_capacity(runs.len());
        let mut heap = BinaryHeap::with_capacity(runs.len());
        for (i, run) in runs.iter().enumerate() {
            let mut r = run.reader_with(MERGE_BUFFER)?;
            if let Some(x) = r.next()? {
                heap.push(Head {
                    key: key(&x),
                    run: i,
                    rec: x,
                });
            }
            readers.push(r);
        }
        Ok(Merger { readers, heap })
    }

    fn next(&mut self, key: &impl Fn(&T) -> K) -> Result<Option<T>, Error> {
        let Some(top) = self.heap.pop() else {
            return Ok(None);
        };
        if let Some(x) = self.readers[top.run].next()? {
            self.heap.push(Head {
                key: key(&x),
                run: top.run,
                rec: x,
            });
        }
        Ok(Some(top.rec))
    }
}

struct Head<T, K> {
    key: K,
    run: usize,
    rec: T,
}

impl<T, K: Ord> PartialEq for Head<T, K> {
    fn eq(&self, o: &Self) -> bool {
        self.key == o.key && self.run == o.run
    }
}
impl<T, K: Ord> Eq for Head<T, K> {}
impl<T, K: Ord> PartialOrd for Head<T, K> {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl<T, K: Ord> Ord for Head<T, K> {
    // Reversed: BinaryHeap is a max-heap and the merge wants the smallest.
    fn cmp(&self, o: &Self) -> Ordering {
        o.key.cmp(&self.key).then(o.run.cmp(&self.run))
    }
}

/// The output of an [`ExternalSorter`], read in key order.
pub struct Sorted<T: Pod, K: Ord, F>(SortedInner<T, K, F>);

enum SortedInner<T: Pod, K: Ord, F> {
    Memory {
        items: Vec<T>,
        at: usize,
    },
    Merge {
        readers: Vec<RecordReader<T>>,
        heap: BinaryHeap<Head<T, K>>,
        _runs: Vec<RecordFile<T>>,
        key: F,
    },
}

impl<T: Pod, K: Ord + Copy, F: Fn(&T) -> K> Sorted<T, K, F> {
    // Fallible, unlike `Iterator::next`: a read can fail.
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Result<Option<T>, Error> {
        match &mut self.0 {
            SortedInner::Memory { items, at } => {
                let r = items.get(*at).copied();
                *at += 1;
                Ok(r)
            }
            SortedInner::Merge {
                readers, heap, key, ..
            } => {
                let Some(top) = heap.pop() else {
                    return Ok(None);
                };
                if let Some(x) = readers[top.run].next()? {
                    heap.push(Head {
                        key: key(&x),
                        run: top.run,
                        rec: x,
                    });
                }
                Ok(Some(top.rec))
            }
        }
    }

    /// The whole sorted vector, if the sort never left memory.
    pub fn into_vec(self) -> Result<Vec<T>, Self> {
        match self.0 {
            SortedInner::Memory { items, at: 0 } => Ok(items),
            other => Err(Sorted(other)),
        }
    }
}

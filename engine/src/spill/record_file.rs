//! Files of fixed-size records: written once, read front to back (or from
//! a record on), removed when dropped.

use super::{IO_BUFFER, SpillDir, spill_error};
use crate::error::{Error, IoContext};
use bytemuck::Pod;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::marker::PhantomData;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering as AtomicOrdering;

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

    /// Records written so far.
    pub fn len(&self) -> u64 {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
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
            _dir: self.spill.dir.clone(),
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

/// A finished file of records; removed when dropped.
#[derive(Debug)]
pub struct RecordFile<T: Pod> {
    path: PathBuf,
    count: u64,
    /// Keeps the spill directory (removed with its last handle) alive as
    /// long as a file in it is.
    _dir: Arc<tempfile::TempDir>,
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

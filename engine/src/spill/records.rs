//! Records kept in memory while a shared allowance lasts, else in a spill
//! file. A cluster's coordinator and workers pass a task's records on
//! from process to process; writing each to a file and reading it back
//! cost a small job more than its tracing (one local worker: a third of
//! the render's CPU time in the kernel). Files remain the fallback, so
//! memory stays bounded by the allowance whatever the job's size.

use super::{RecordFile, RecordReader, RecordWriter, SpillDir};
use crate::error::Error;
use bytemuck::Pod;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// Bytes that records kept in memory may take together, shared by every
/// holder; each [`Lease`] gives its bytes back when dropped.
#[derive(Clone, Debug)]
pub struct MemoryShare {
    inner: Arc<ShareInner>,
}

#[derive(Debug)]
struct ShareInner {
    cap: u64,
    used: AtomicU64,
}

impl MemoryShare {
    pub fn new(cap: u64) -> MemoryShare {
        MemoryShare {
            inner: Arc::new(ShareInner {
                cap,
                used: AtomicU64::new(0),
            }),
        }
    }

    pub fn cap(&self) -> u64 {
        self.inner.cap
    }

    /// Bytes leased now.
    pub fn used(&self) -> u64 {
        self.inner.used.load(Ordering::Relaxed)
    }

    /// Bytes still free.
    pub fn available(&self) -> u64 {
        self.cap().saturating_sub(self.used())
    }

    /// An empty lease, to grow as records come.
    pub fn lease(&self) -> Lease {
        Lease {
            share: self.clone(),
            bytes: 0,
        }
    }

    /// A lease of `bytes`, if the share has them.
    pub fn try_lease(&self, bytes: u64) -> Option<Lease> {
        self.try_take(bytes).then(|| Lease {
            share: self.clone(),
            bytes,
        })
    }

    fn try_take(&self, bytes: u64) -> bool {
        let cap = self.inner.cap;
        self.inner
            .used
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |u| {
                u.checked_add(bytes).filter(|&n| n <= cap)
            })
            .is_ok()
    }
}

/// Bytes taken from a [`MemoryShare`]; given back on drop.
#[derive(Debug)]
pub struct Lease {
    share: MemoryShare,
    bytes: u64,
}

impl Lease {
    /// Takes `more` bytes if the share has them.
    pub fn grow(&mut self, more: u64) -> bool {
        let ok = self.share.try_take(more);
        self.bytes += if ok { more } else { 0 };
        ok
    }
}

impl Drop for Lease {
    fn drop(&mut self) {
        self.share
            .inner
            .used
            .fetch_sub(self.bytes, Ordering::AcqRel);
    }
}

/// Finished records: in memory (with the lease that pays for them) or in
/// a spill file.
pub enum Records<T: Pod> {
    Memory { v: Vec<T>, _lease: Lease },
    File(RecordFile<T>),
}

impl<T: Pod> Records<T> {
    /// Records in memory, paid for by `lease`.
    pub fn memory(v: Vec<T>, lease: Lease) -> Records<T> {
        Records::Memory { v, _lease: lease }
    }

    pub fn len(&self) -> u64 {
        match self {
            Records::Memory { v, .. } => v.len() as u64,
            Records::File(f) => f.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes held in memory.
    pub fn memory_bytes(&self) -> u64 {
        match self {
            Records::Memory { v, .. } => (v.capacity() * std::mem::size_of::<T>()) as u64,
            Records::File(_) => 0,
        }
    }

    /// The vector of records in memory (their lease ends: the caller
    /// accounts for them from now on), or the records as they are.
    pub fn into_vec(self) -> Result<Vec<T>, Records<T>> {
        match self {
            Records::Memory { v, .. } => Ok(v),
            f @ Records::File(_) => Err(f),
        }
    }

    /// The records in memory, if that is where they are.
    pub fn as_slice(&self) -> Option<&[T]> {
        match self {
            Records::Memory { v, .. } => Some(v),
            Records::File(_) => None,
        }
    }

    pub fn reader(&self) -> Result<RecordsReader<'_, T>, Error> {
        self.reader_range(0, self.len())
    }

    /// Reads records `start .. start + count` (clamped to the records).
    pub fn reader_range(&self, start: u64, count: u64) -> Result<RecordsReader<'_, T>, Error> {
        Ok(match self {
            Records::Memory { v, .. } => {
                let lo = (start.min(v.len() as u64)) as usize;
                let hi = (start.saturating_add(count).min(v.len() as u64)) as usize;
                RecordsReader::Memory(v[lo..hi].iter())
            }
            Records::File(f) => RecordsReader::File(f.reader_range(start, count)?),
        })
    }
}

/// Reads [`Records`] front to back.
pub enum RecordsReader<'a, T: Pod> {
    Memory(std::slice::Iter<'a, T>),
    File(RecordReader<T>),
}

impl<T: Pod> RecordsReader<'_, T> {
    pub fn remaining(&self) -> u64 {
        match self {
            RecordsReader::Memory(it) => it.len() as u64,
            RecordsReader::File(r) => r.remaining(),
        }
    }

    // Fallible, like `RecordReader::next`.
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Result<Option<T>, Error> {
        match self {
            RecordsReader::Memory(it) => Ok(it.next().copied()),
            RecordsReader::File(r) => r.next(),
        }
    }
}

/// Collects records in memory while its share lasts, then moves them to
/// a spill file and goes on there.
pub enum RecordsWriter<T: Pod> {
    Memory {
        v: Vec<T>,
        lease: Lease,
        spill: SpillDir,
        what: &'static str,
    },
    File(RecordWriter<T>),
}

impl<T: Pod> RecordsWriter<T> {
    pub fn new(share: &MemoryShare, spill: &SpillDir, what: &'static str) -> RecordsWriter<T> {
        RecordsWriter::Memory {
            v: Vec::new(),
            lease: share.lease(),
            spill: spill.clone(),
            what,
        }
    }

    pub fn len(&self) -> u64 {
        match self {
            RecordsWriter::Memory { v, .. } => v.len() as u64,
            RecordsWriter::File(w) => w.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn extend(&mut self, rs: &[T]) -> Result<(), Error> {
        if let RecordsWriter::Memory { v, lease, .. } = self {
            let need = v.len() + rs.len();
            if need <= v.capacity() {
                v.extend_from_slice(rs);
                return Ok(());
            }
            // Grow as a Vec would (doubling), paying for the capacity.
            let cap = need.max(v.capacity() * 2);
            let more = ((cap - v.capacity()) * std::mem::size_of::<T>()) as u64;
            if lease.grow(more) {
                v.reserve_exact(cap - v.len());
                v.extend_from_slice(rs);
                return Ok(());
            }
            self.spill_to_file()?;
        }
        match self {
            RecordsWriter::File(w) => w.extend(rs),
            RecordsWriter::Memory { .. } => unreachable!("moved to a file"),
        }
    }

    fn spill_to_file(&mut self) -> Result<(), Error> {
        if let RecordsWriter::Memory { v, spill, what, .. } = self {
            let mut w = RecordWriter::create(spill, what)?;
            w.extend(v)?;
            *self = RecordsWriter::File(w);
        }
        Ok(())
    }

    pub fn finish(self) -> Result<Records<T>, Error> {
        Ok(match self {
            RecordsWriter::Memory { v, lease, .. } => Records::Memory { v, _lease: lease },
            RecordsWriter::File(w) => Records::File(w.finish()?),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_stay_in_memory_while_the_share_lasts_then_spill_whole() {
        let spill = SpillDir::new(None).unwrap();
        let share = MemoryShare::new(64 * 8);
        let mut a = RecordsWriter::<u64>::new(&share, &spill, "a");
        a.extend(&(0..40).collect::<Vec<u64>>()).unwrap();
        assert!(matches!(a, RecordsWriter::Memory { .. }));
        let a = a.finish().unwrap();
        assert!(a.memory_bytes() > 0 && share.used() == a.memory_bytes());
        // The second writer finds too little left and moves to a file,
        // keeping every record and their order.
        let mut b = RecordsWriter::<u64>::new(&share, &spill, "b");
        for c in (0..100u64).collect::<Vec<_>>().chunks(7) {
            b.extend(c).unwrap();
        }
        let b = b.finish().unwrap();
        assert!(matches!(b, Records::File(_)));
        let mut rd = b.reader_range(95, 10).unwrap();
        assert_eq!(rd.remaining(), 5);
        let mut got = Vec::new();
        while let Some(x) = rd.next().unwrap() {
            got.push(x);
        }
        assert_eq!(got, vec![95, 96, 97, 98, 99]);
        let mut rd = a.reader_range(38, 5).unwrap();
        assert_eq!(
            (rd.next().unwrap(), rd.next().unwrap()),
            (Some(38), Some(39))
        );
        assert_eq!(rd.next().unwrap(), None);
        // Dropping the records gives their bytes back.
        drop(a);
        assert_eq!(share.used(), 0);
    }
}

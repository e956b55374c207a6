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

/// Finished records: in memory (with the lease that pays for them), in
/// a spill file, or several such parts one after the other.
pub enum Records<T: Pod> {
    Memory {
        v: Vec<T>,
        _lease: Lease,
    },
    File(RecordFile<T>),
    /// Parts in order, kept as they came instead of copied into one
    /// buffer: the chunks of a task's output as they were decoded, the
    /// outputs of a round's tasks joined into its rays. At least two
    /// parts, none empty, none a chain (see [`Records::chain`]).
    Chain {
        parts: Vec<Records<T>>,
        len: u64,
    },
}

impl<T: Pod> Records<T> {
    /// Records in memory, paid for by `lease`.
    pub fn memory(v: Vec<T>, lease: Lease) -> Records<T> {
        Records::Memory { v, _lease: lease }
    }

    /// `parts` one after the other, without copying them: `None` when
    /// they hold no record, the part itself when only one does.
    pub fn chain(parts: impl IntoIterator<Item = Records<T>>) -> Option<Records<T>> {
        let mut flat = Vec::new();
        for p in parts {
            match p {
                Records::Chain { parts, .. } => flat.extend(parts),
                p if p.is_empty() => {}
                p => flat.push(p),
            }
        }
        match flat.len() {
            0 => None,
            1 => flat.pop(),
            _ => Some(Records::Chain {
                len: flat.iter().map(Records::len).sum(),
                parts: flat,
            }),
        }
    }

    pub fn len(&self) -> u64 {
        match self {
            Records::Memory { v, .. } => v.len() as u64,
            Records::File(f) => f.len(),
            Records::Chain { len, .. } => *len,
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
            Records::Chain { parts, .. } => parts.iter().map(Records::memory_bytes).sum(),
        }
    }

    /// The vector of records in memory (their lease ends: the caller
    /// accounts for them from now on), or the records as they are.
    pub fn into_vec(self) -> Result<Vec<T>, Records<T>> {
        match self {
            Records::Memory { v, .. } => Ok(v),
            r => Err(r),
        }
    }

    /// The records in memory in one piece, if that is where they are.
    pub fn as_slice(&self) -> Option<&[T]> {
        match self {
            Records::Memory { v, .. } => Some(v),
            Records::File(_) | Records::Chain { .. } => None,
        }
    }

    /// Gives every record to `f`, in order, in slices: the parts in
    /// memory as they are, a file's records a few thousand at a time.
    pub fn for_each_slice(
        &self,
        f: &mut dyn FnMut(&[T]) -> Result<(), Error>,
    ) -> Result<(), Error> {
        match self {
            Records::Memory { v, .. } => f(v),
            Records::Chain { parts, .. } => parts.iter().try_for_each(|p| p.for_each_slice(f)),
            Records::File(file) => {
                let mut rd = RecordsReader::File(file.reader()?);
                let mut buf = Vec::with_capacity(4096);
                while rd.next_chunk(&mut buf, 4096)? {
                    f(&buf)?;
                }
                Ok(())
            }
        }
    }

    /// Record `i`, if there is one.
    pub fn get(&self, i: u64) -> Result<Option<T>, Error> {
        self.reader_range(i, 1)?.next()
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
            Records::Chain { parts, len } => {
                let (start, end) = (start.min(*len), start.saturating_add(count).min(*len));
                // The part holding record `start`, and where in it.
                let (mut at, mut skip) = (0, start);
                while at + 1 < parts.len() && skip >= parts[at].len() {
                    skip -= parts[at].len();
                    at += 1;
                }
                RecordsReader::Chain {
                    rest: &parts[at + 1..],
                    part: Box::new(parts[at].reader_range(skip, end - start)?),
                    left: end - start,
                }
            }
        })
    }
}

/// Reads [`Records`] front to back.
pub enum RecordsReader<'a, T: Pod> {
    Memory(std::slice::Iter<'a, T>),
    File(RecordReader<T>),
    /// A chain's records: the part being read, the parts after it, and
    /// how many records are still to read in all.
    Chain {
        part: Box<RecordsReader<'a, T>>,
        rest: &'a [Records<T>],
        left: u64,
    },
}

impl<T: Pod> RecordsReader<'_, T> {
    /// Refills `buf` with the next records, at most `max`; false once
    /// there are none left.
    pub fn next_chunk(&mut self, buf: &mut Vec<T>, max: usize) -> Result<bool, Error> {
        buf.clear();
        while buf.len() < max {
            match self.next()? {
                Some(x) => buf.push(x),
                None => break,
            }
        }
        Ok(!buf.is_empty())
    }

    pub fn remaining(&self) -> u64 {
        match self {
            RecordsReader::Memory(it) => it.len() as u64,
            RecordsReader::File(r) => r.remaining(),
            RecordsReader::Chain { left, .. } => *left,
        }
    }

    // Fallible, like `RecordReader::next`.
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Result<Option<T>, Error> {
        match self {
            RecordsReader::Memory(it) => Ok(it.next().copied()),
            RecordsReader::File(r) => r.next(),
            RecordsReader::Chain { part, rest, left } => loop {
                if *left == 0 {
                    return Ok(None);
                }
                if let Some(x) = part.next()? {
                    *left -= 1;
                    return Ok(Some(x));
                }
                let Some((p, more)) = rest.split_first() else {
                    return Ok(None);
                };
                **part = p.reader_range(0, *left)?;
                *rest = more;
            },
        }
    }
}

/// Collects records in memory while its share lasts, then moves them to
/// a spill file and goes on there.
pub enum RecordsWriter<T: Pod> {
    Memory {
        /// Whole vectors taken as they are ([`RecordsWriter::push_vec`]),
        /// in order, before `v`.
        done: Vec<Vec<T>>,
        /// Where [`RecordsWriter::extend`] copies to.
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
            done: Vec::new(),
            v: Vec::new(),
            lease: share.lease(),
            spill: spill.clone(),
            what,
        }
    }

    pub fn len(&self) -> u64 {
        match self {
            RecordsWriter::Memory { done, v, .. } => {
                done.iter().map(|d| d.len() as u64).sum::<u64>() + v.len() as u64
            }
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

    /// Appends the records of `rs`, keeping the vector itself when the
    /// share pays for it (no copy: a decoded chunk stays where it was
    /// decoded), else writing them to the file.
    pub fn push_vec(&mut self, rs: Vec<T>) -> Result<(), Error> {
        if rs.is_empty() {
            return Ok(());
        }
        if let RecordsWriter::Memory { done, v, lease, .. } = self {
            if lease.grow((rs.capacity() * std::mem::size_of::<T>()) as u64) {
                if !v.is_empty() {
                    done.push(std::mem::take(v));
                }
                done.push(rs);
                return Ok(());
            }
            self.spill_to_file()?;
        }
        self.extend(&rs)
    }

    fn spill_to_file(&mut self) -> Result<(), Error> {
        if let RecordsWriter::Memory {
            done,
            v,
            spill,
            what,
            ..
        } = self
        {
            let mut w = RecordWriter::create(spill, what)?;
            for d in done.iter() {
                w.extend(d)?;
            }
            w.extend(v)?;
            *self = RecordsWriter::File(w);
        }
        Ok(())
    }

    pub fn finish(self) -> Result<Records<T>, Error> {
        Ok(match self {
            RecordsWriter::Memory {
                mut done, v, lease, ..
            } => {
                if done.is_empty() {
                    return Ok(Records::Memory { v, _lease: lease });
                }
                if !v.is_empty() {
                    done.push(v);
                }
                // The first part carries the whole lease.
                let share = lease.share.clone();
                let empty = move || share.lease();
                let mut leases = std::iter::once(lease).chain(std::iter::repeat_with(empty));
                let parts = done.into_iter().map(|v| Records::Memory {
                    v,
                    _lease: leases.next().expect("endless"),
                });
                Records::chain(parts.collect::<Vec<_>>()).expect("not empty")
            }
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

    fn all<T: Pod>(r: &Records<T>, start: u64, count: u64) -> Vec<T> {
        let mut rd = r.reader_range(start, count).unwrap();
        let n = rd.remaining();
        let mut got = Vec::new();
        while let Some(x) = rd.next().unwrap() {
            got.push(x);
        }
        assert_eq!(got.len() as u64, n, "remaining() counts what is read");
        got
    }

    #[test]
    fn vectors_taken_whole_and_chains_read_as_one() {
        let spill = SpillDir::new(None).unwrap();
        let share = MemoryShare::new(1 << 20);
        // Copied, taken whole, copied again: three parts, one order.
        let mut w = RecordsWriter::<u64>::new(&share, &spill, "w");
        w.extend(&[0, 1, 2]).unwrap();
        w.push_vec((3..10).collect()).unwrap();
        w.push_vec(Vec::new()).unwrap();
        w.extend(&[10, 11]).unwrap();
        assert_eq!(w.len(), 12);
        let r = w.finish().unwrap();
        assert!(matches!(&r, Records::Chain { parts, .. } if parts.len() == 3));
        assert_eq!(all(&r, 0, 100), (0..12).collect::<Vec<u64>>());
        // Ranges that start, end and cross anywhere.
        for start in 0..13 {
            for count in 0..14 {
                let want: Vec<u64> = (start..(start + count).min(12)).collect();
                assert_eq!(all(&r, start, count), want, "{start}+{count}");
            }
        }
        assert_eq!(r.get(11).unwrap(), Some(11));
        assert_eq!(r.get(12).unwrap(), None);
        // A chain of a chain, a file and nothing flattens; slices come in
        // order.
        let mut f = RecordsWriter::<u64>::new(&MemoryShare::new(0), &spill, "f");
        f.extend(&[12, 13]).unwrap();
        let f = f.finish().unwrap();
        assert!(matches!(f, Records::File(_)));
        let empty = RecordsWriter::<u64>::new(&share, &spill, "e")
            .finish()
            .unwrap();
        let c = Records::chain([r, empty, f]).unwrap();
        assert!(matches!(&c, Records::Chain { parts, .. } if parts.len() == 4));
        assert_eq!(all(&c, 10, 3), vec![10, 11, 12]);
        let mut seen = Vec::new();
        c.for_each_slice(&mut |s| {
            seen.extend_from_slice(s);
            Ok(())
        })
        .unwrap();
        assert_eq!(seen, (0..14).collect::<Vec<u64>>());
        assert!(share.used() > 0);
        drop(c);
        assert_eq!(share.used(), 0, "every part's lease is given back");
        assert!(Records::<u64>::chain([]).is_none());
    }

    #[test]
    fn a_vector_the_share_cannot_pay_for_goes_to_the_file() {
        let spill = SpillDir::new(None).unwrap();
        let share = MemoryShare::new(8 * 8);
        let mut w = RecordsWriter::<u64>::new(&share, &spill, "w");
        w.push_vec(vec![1, 2, 3]).unwrap();
        w.push_vec((4..20).collect()).unwrap();
        assert!(matches!(w, RecordsWriter::File(_)));
        w.extend(&[20]).unwrap();
        let r = w.finish().unwrap();
        assert_eq!(all(&r, 0, 100), (1..21).collect::<Vec<u64>>());
    }
}

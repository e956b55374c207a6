//! External merge sort of records by an integer key.

use super::record_file::{RecordFile, RecordReader, RecordWriter};
use super::{MERGE_BUFFER, MERGE_FANIN, SpillDir};
use crate::error::Error;
use bytemuck::Pod;
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::marker::PhantomData;

/// Sorts records of any number by `key`, holding at most `mem_records` in
/// memory: sorted runs spill to files and are merged. The memory buffer can
/// be handed in and taken back, so that repeated sorts reuse it. Records
/// pushed already in key order (as often happens) are neither sorted nor
/// merged: the runs are read one after the other.
pub struct ExternalSorter<T: Pod + Send, K: Ord + Copy, F: Fn(&T) -> K + Sync> {
    buf: Vec<T>,
    cap: usize,
    runs: Vec<RecordFile<T>>,
    /// Whether every record so far came in key order, and the last key.
    in_order: bool,
    last: Option<K>,
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
            in_order: true,
            last: None,
            key,
            spill: spill.clone(),
            what,
            scratch: Default::default(),
            _k: PhantomData,
        }
    }

    pub fn push(&mut self, r: T) -> Result<(), Error> {
        if self.in_order {
            let k = (self.key)(&r);
            if self.last.is_some_and(|l| k < l) {
                self.in_order = false;
            }
            self.last = Some(k);
        }
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

    /// [`ExternalSorter::extend_from_slice`] of `parts` one after the
    /// other, copied by the threads of the current rayon pool when they fit
    /// in the buffer. The copy into a buffer the size of a round (its page
    /// faults above all) was a twentieth of a two-thread render's samples,
    /// all on one thread while the others waited.
    pub fn extend_from_slices(&mut self, parts: &[&[T]]) -> Result<(), Error>
    where
        T: Sync,
    {
        use rayon::prelude::*;
        let total: usize = parts.iter().map(|p| p.len()).sum();
        let len = self.buf.len();
        if parts.len() < 2 || len + total > self.cap {
            for p in parts {
                self.extend_from_slice(p)?;
            }
            return Ok(());
        }
        if self.in_order {
            let key = &self.key;
            let sorted = parts
                .par_iter()
                .all(|p| p.windows(2).all(|w| key(&w[0]) <= key(&w[1])));
            // And across the parts' boundaries, from the last key so far.
            let mut last = self.last;
            let mut ok = sorted;
            for p in parts.iter().filter(|p| !p.is_empty()) {
                if last.is_some_and(|l| key(&p[0]) < l) {
                    ok = false;
                    break;
                }
                last = Some(key(&p[p.len() - 1]));
            }
            self.in_order = ok;
            self.last = last;
        }
        if self.buf.capacity() - len < total {
            // Grow geometrically, but never past the memory share.
            let want = (self.buf.capacity() * 2)
                .max(len + total)
                .max(1 << 12)
                .min(self.cap);
            self.buf.reserve_exact(want - len);
        }
        let mut rest = &mut self.buf.spare_capacity_mut()[..total];
        let mut dsts = Vec::with_capacity(parts.len());
        for p in parts {
            let (d, r) = rest.split_at_mut(p.len());
            dsts.push(d);
            rest = r;
        }
        dsts.into_par_iter()
            .zip(parts.par_iter())
            .for_each(|(d, s)| {
                for (x, y) in d.iter_mut().zip(s.iter()) {
                    x.write(*y);
                }
            });
        // SAFETY: the `total` slots after `len` are within the capacity
        // (reserved above) and every one of them was written just now: the
        // destinations split them exactly (their lengths are the parts'
        // lengths, which sum to `total`) and each was filled from its part
        // of equal length. `T: Pod` has no drop glue and every bit pattern
        // written is a valid `T`.
        unsafe { self.buf.set_len(len + total) };
        Ok(())
    }

    /// Pushes `records` in order, as [`ExternalSorter::push`] would one by
    /// one, copying them in bulk where the buffer has room.
    pub fn extend_from_slice(&mut self, mut records: &[T]) -> Result<(), Error> {
        while !records.is_empty() {
            if self.buf.len() == self.cap {
                self.spill_run()?;
            }
            let room = self.cap - self.buf.len();
            let (now, rest) = records.split_at(room.min(records.len()));
            if self.in_order {
                for r in now {
                    let k = (self.key)(r);
                    if self.last.is_some_and(|l| k < l) {
                        self.in_order = false;
                        break;
                    }
                    self.last = Some(k);
                }
            }
            if self.buf.capacity() - self.buf.len() < now.len() {
                // Grow geometrically, but never past the memory share.
                let want = (self.buf.capacity() * 2)
                    .max(self.buf.len() + now.len())
                    .max(1 << 12)
                    .min(self.cap);
                self.buf.reserve_exact(want - self.buf.len());
            }
            self.buf.extend_from_slice(now);
            records = rest;
        }
        Ok(())
    }

    fn spill_run(&mut self) -> Result<(), Error> {
        if !self.in_order {
            let key = &self.key;
            super::radix::sort_by_key(&mut self.buf, |r| key(r).into(), &mut self.scratch);
        }
        let mut w = RecordWriter::create(&self.spill, self.what)?;
        w.extend(&self.buf)?;
        self.runs.push(w.finish()?);
        self.buf.clear();
        Ok(())
    }

    /// Adds records already in key order, as one run of the merge.
    pub fn add_sorted_run(&mut self, run: RecordFile<T>) {
        if !run.is_empty() {
            self.in_order = false;
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
        if !self.in_order {
            let key = &self.key;
            super::radix::sort_by_key(&mut self.buf, |r| key(r).into(), &mut self.scratch);
        }
        if self.runs.is_empty() {
            return Ok(Sorted(SortedInner::Memory {
                items: std::mem::take(&mut self.buf),
                at: 0,
            }));
        }
        if self.in_order {
            // The runs, then what is still in memory, are already in order.
            return Ok(Sorted(SortedInner::Chain {
                runs: std::mem::take(&mut self.runs),
                next: 0,
                reader: None,
                tail: std::mem::take(&mut self.buf),
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
    /// Runs that follow each other in key order, then records in memory.
    Chain {
        runs: Vec<RecordFile<T>>,
        next: usize,
        // Boxed: the variant would otherwise dwarf the others.
        reader: Option<Box<RecordReader<T>>>,
        tail: Vec<T>,
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
            SortedInner::Chain {
                runs,
                next,
                reader,
                tail,
                at,
            } => loop {
                if let Some(r) = reader {
                    if let Some(x) = r.next()? {
                        return Ok(Some(x));
                    }
                    *reader = None;
                }
                if *next < runs.len() {
                    *reader = Some(Box::new(runs[*next].reader_with(super::IO_BUFFER)?));
                    *next += 1;
                    continue;
                }
                let x = tail.get(*at).copied();
                *at += 1;
                return Ok(x);
            },
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

#[cfg(test)]
mod tests {
    use super::*;

    fn sorted_back(keys: &[u64], mem: usize) -> Vec<u64> {
        let one_by_one = sorted_back_in(keys, mem, 1);
        // Pushed in bulk, in slices of several sizes: the same records.
        for slice in [7, 100, 3000] {
            assert_eq!(
                sorted_back_in(keys, mem, slice),
                one_by_one,
                "slices of {slice}"
            );
            // Several slices at once (copied in parallel where they fit),
            // an empty one among them.
            assert_eq!(
                sorted_back_in_parts(keys, mem, slice),
                one_by_one,
                "parts of {slice}"
            );
        }
        one_by_one
    }

    fn sorted_back_in_parts(keys: &[u64], mem: usize, slice: usize) -> Vec<u64> {
        let spill = SpillDir::new(None).unwrap();
        let mut s = ExternalSorter::new(&spill, "t", mem, (|k: &u64| *k) as fn(&u64) -> u64);
        let chunks: Vec<&[u64]> = keys.chunks(slice).collect();
        for group in chunks.chunks(3) {
            let mut parts = group.to_vec();
            parts.insert(1, &[]);
            s.extend_from_slices(&parts).unwrap();
        }
        let mut out = Vec::new();
        let mut r = s.finish().unwrap();
        while let Some(k) = r.next().unwrap() {
            out.push(k);
        }
        out
    }

    fn sorted_back_in(keys: &[u64], mem: usize, slice: usize) -> Vec<u64> {
        let spill = SpillDir::new(None).unwrap();
        let mut s = ExternalSorter::new(&spill, "t", mem, (|k: &u64| *k) as fn(&u64) -> u64);
        if slice == 1 {
            for &k in keys {
                s.push(k).unwrap();
            }
        } else {
            for c in keys.chunks(slice) {
                s.extend_from_slice(c).unwrap();
            }
        }
        let mut out = Vec::new();
        let mut r = s.finish().unwrap();
        while let Some(k) = r.next().unwrap() {
            out.push(k);
        }
        out
    }

    #[test]
    fn sorts_in_memory_and_through_runs_in_order_or_not() {
        let ordered: Vec<u64> = (0..1000).map(|i| i * 3).collect();
        let mut shuffled = ordered.clone();
        // A fixed permutation: multiply by a unit modulo the length.
        for (i, k) in shuffled.iter_mut().enumerate() {
            *k = ordered[(i * 337) % ordered.len()];
        }
        for mem in [16, 100, 5000] {
            assert_eq!(sorted_back(&ordered, mem), ordered, "in order, {mem}");
            assert_eq!(sorted_back(&shuffled, mem), ordered, "shuffled, {mem}");
        }
        // Out of order only at the very end still sorts.
        let mut late = ordered.clone();
        late.push(1);
        let mut want = late.clone();
        want.sort();
        assert_eq!(sorted_back(&late, 16), want);
        // Sorted within slices of 7 and 100, but not across them.
        let blocks: Vec<u64> = (0..30u64)
            .rev()
            .flat_map(|b| (0..700).map(move |i| b * 1000 + i))
            .collect();
        let mut want = blocks.clone();
        want.sort();
        for mem in [16, 100_000] {
            assert_eq!(sorted_back(&blocks, mem), want, "blocks, {mem}");
        }
    }
}

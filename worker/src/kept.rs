//! What a worker keeps of finished tasks for later ones: an
//! intersection's input rays and its results (with the surfaces found
//! with them), a shading's spawned rays. The coordinator names what a
//! worker keeps instead of sending it again. Records stay in memory while
//! the worker's share lasts (a quarter of its `--memory`), else in spill
//! files; the oldest go first.

use sray_engine::bf::{Outcome, RayRec, ResultRec};
use sray_engine::spill::{MemoryShare, Records, RecordsReader};
use std::collections::{HashMap, VecDeque};
use std::sync::Arc;

/// Records `start .. start + count` of some records in memory or in a
/// file (shared: a kept output may be a task's input as it is).
pub struct Slice<T: bytemuck::Pod> {
    pub records: Arc<Records<T>>,
    pub start: u64,
    pub count: u64,
}

impl<T: bytemuck::Pod> Slice<T> {
    pub fn whole(r: Records<T>) -> Slice<T> {
        let count = r.len();
        Slice {
            records: Arc::new(r),
            start: 0,
            count,
        }
    }
    pub fn len(&self) -> u64 {
        self.count
    }
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
    pub fn reader(&self) -> Result<RecordsReader<'_, T>, sray_engine::Error> {
        self.records.reader_range(self.start, self.count)
    }
    /// The records, if they are in memory.
    pub(crate) fn as_slice(&self) -> Option<&[T]> {
        let v = self.records.as_slice()?;
        Some(&v[self.start as usize..(self.start + self.count) as usize])
    }
    /// The records as a vector of their own, if this slice is all of
    /// them, in memory, and held by nothing else (their memory then leaves
    /// the share: the caller accounts for it).
    pub(crate) fn whole_vec(self) -> Result<Vec<T>, Slice<T>> {
        if self.start != 0 || self.count != self.records.len() {
            return Err(self);
        }
        let (start, count) = (self.start, self.count);
        match Arc::try_unwrap(self.records) {
            Ok(r) => r.into_vec().map_err(|r| Slice {
                records: Arc::new(r),
                start,
                count,
            }),
            Err(records) => Err(Slice {
                records,
                start,
                count,
            }),
        }
    }
    /// Records `offset .. offset + count` of this slice.
    pub(crate) fn sub(&self, offset: u64, count: u64) -> Option<Slice<T>> {
        (offset.checked_add(count)? <= self.count).then(|| Slice {
            records: self.records.clone(),
            start: self.start + offset,
            count,
        })
    }
    pub(crate) fn bytes(&self) -> u64 {
        self.count * std::mem::size_of::<T>() as u64
    }
    /// In memory, and held by this slice alone.
    pub(crate) fn in_memory_alone(&self) -> bool {
        self.records.memory_bytes() > 0 && Arc::strong_count(&self.records) == 1
    }
}

/// An intersection's results: as they travel (ray, object, distance), or
/// in memory with the surfaces the tracer found with them, which spare
/// the shading its pass over the objects (the paper's join).
pub enum ResultSlice {
    Bare(Slice<ResultRec>),
    Carried(Slice<Outcome>),
}

impl ResultSlice {
    pub fn len(&self) -> u64 {
        match self {
            ResultSlice::Bare(s) => s.len(),
            ResultSlice::Carried(s) => s.len(),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub(crate) fn sub(&self, offset: u64, count: u64) -> Option<ResultSlice> {
        Some(match self {
            ResultSlice::Bare(s) => ResultSlice::Bare(s.sub(offset, count)?),
            ResultSlice::Carried(s) => ResultSlice::Carried(s.sub(offset, count)?),
        })
    }
    pub(crate) fn bytes(&self) -> u64 {
        match self {
            ResultSlice::Bare(s) => s.bytes(),
            ResultSlice::Carried(s) => s.bytes(),
        }
    }
    pub(crate) fn in_memory_alone(&self) -> bool {
        match self {
            ResultSlice::Bare(s) => s.in_memory_alone(),
            ResultSlice::Carried(s) => s.in_memory_alone(),
        }
    }
}

/// What the executor keeps of a finished task: an intersection's input
/// rays (none for eye rays) and results; a shading's spawned rays.
#[derive(Default)]
pub struct Kept {
    pub rays: Option<Slice<RayRec>>,
    pub results: Option<ResultSlice>,
    /// Set for a task whose output the coordinator did not take
    /// (`Task.keep_output`): these records are nowhere else, so they are
    /// never dropped to make room, only once their job has gone two rounds
    /// past them or has ended (see [`KeptStore::release`]).
    pub pin: Option<Pin>,
}

/// The job and round of pinned records, and when they were pinned.
#[derive(Clone, Debug)]
pub struct Pin {
    pub job: String,
    pub round: u32,
    pub at: std::time::Instant,
}

/// A worker's records kept in memory (and tasks' inputs received there)
/// may take this part of its `--memory`; its tracers take the rest.
pub const KEPT_MEMORY_PART: u64 = 4;

/// Most bytes of records kept (in memory or in the spill directory), and
/// most tasks' worth; the oldest go first.
const KEPT_BYTES: u64 = 1 << 30;
const KEPT_TASKS: usize = 4096;

/// The tasks' records an executor keeps, by task id, oldest first.
#[derive(Default)]
pub(crate) struct KeptStore {
    pub(crate) by_task: HashMap<u64, Kept>,
    order: VecDeque<u64>,
    bytes: u64,
}

impl KeptStore {
    fn size(k: &Kept) -> u64 {
        k.rays.as_ref().map_or(0, Slice::bytes) + k.results.as_ref().map_or(0, ResultSlice::bytes)
    }

    /// Whether dropping the entry gives memory back: it holds records in
    /// memory that nothing else holds (and nowhere else has them).
    fn frees_memory(k: &Kept) -> bool {
        k.pin.is_none()
            && (k.rays.as_ref().is_some_and(Slice::in_memory_alone)
                || k.results.as_ref().is_some_and(ResultSlice::in_memory_alone))
    }

    /// Whether any records are pinned.
    pub(crate) fn has_pins(&self) -> bool {
        self.by_task.values().any(|k| k.pin.is_some())
    }

    /// Drops the pinned records of `job` that a task of round `round`
    /// no longer needs: a round reads the rays the round before spawned,
    /// and nothing older; records of a later round are from an attempt
    /// of the job that was given up (it started again). Returns what it
    /// dropped (its buffers may serve again).
    pub(crate) fn release(&mut self, job: &str, round: u32) -> Vec<Kept> {
        self.unpin(|p| p.job == job && (p.round.saturating_add(1) < round || p.round > round))
    }

    /// Drops the pinned records of jobs that have ended: those pinned
    /// before `asked`, when the coordinator was asked which jobs run, of a
    /// job not among `running` (a job pinned to later may be newer than
    /// the answer).
    pub(crate) fn release_ended(&mut self, running: &[String], asked: std::time::Instant) {
        self.unpin(|p| p.at < asked && !running.contains(&p.job));
    }

    /// Drops the pinned entries whose pin `done` says are done with, and
    /// returns them.
    fn unpin(&mut self, done: impl Fn(&Pin) -> bool) -> Vec<Kept> {
        let old: Vec<u64> = self
            .order
            .iter()
            .copied()
            .filter(|t| self.by_task[t].pin.as_ref().is_some_and(&done))
            .collect();
        old.into_iter().filter_map(|t| self.remove(t)).collect()
    }

    /// Drops the oldest records held in memory until `share` has `bytes`
    /// free (or none are left): records kept longest are the least likely
    /// to be asked for, and a new task's output pays for its memory only
    /// while the share lasts (else it goes to a file).
    /// Only records held by nothing else are dropped (a slice shared with
    /// a task's input or another entry would stay in memory anyway).
    pub(crate) fn make_room(&mut self, share: &MemoryShare, bytes: u64) {
        if bytes > share.cap() {
            return;
        }
        while share.available() < bytes {
            let Some(pos) = self
                .order
                .iter()
                .position(|t| self.by_task.get(t).is_some_and(Self::frees_memory))
            else {
                break;
            };
            let t = self.order.remove(pos).expect("in range");
            if let Some(old) = self.by_task.remove(&t) {
                self.bytes -= Self::size(&old);
            }
        }
    }

    pub(crate) fn insert(&mut self, task: u64, k: Kept) {
        if let Some(old) = self.by_task.remove(&task) {
            self.bytes -= Self::size(&old);
            self.order.retain(|&t| t != task);
        }
        self.bytes += Self::size(&k);
        self.by_task.insert(task, k);
        self.order.push_back(task);
        while self.bytes > KEPT_BYTES || self.order.len() > KEPT_TASKS {
            // The oldest that is kept elsewhere too.
            let Some(pos) = self
                .order
                .iter()
                .position(|t| self.by_task[t].pin.is_none())
            else {
                break;
            };
            let t = self.order.remove(pos).expect("in range");
            if let Some(old) = self.by_task.remove(&t) {
                self.bytes -= Self::size(&old);
            }
        }
    }

    pub(crate) fn remove(&mut self, task: u64) -> Option<Kept> {
        let k = self.by_task.remove(&task)?;
        self.bytes -= Self::size(&k);
        self.order.retain(|&t| t != task);
        Some(k)
    }

    pub(crate) fn ids(&self) -> Vec<u64> {
        self.order.iter().copied().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytemuck::Zeroable;

    /// Bare results `n` long, in memory and paid for by `share`.
    fn results(share: &MemoryShare, n: usize) -> Slice<ResultRec> {
        let v = vec![ResultRec::zeroed(); n];
        let bytes = (v.capacity() * std::mem::size_of::<ResultRec>()) as u64;
        let lease = share.try_lease(bytes).expect("room in the share");
        Slice::whole(Records::memory(v, lease))
    }

    fn kept(s: Slice<ResultRec>) -> Kept {
        Kept {
            rays: None,
            results: Some(ResultSlice::Bare(s)),
            pin: None,
        }
    }

    #[test]
    fn pinned_records_stay_until_their_job_is_two_rounds_on() {
        let size = std::mem::size_of::<ResultRec>() as u64;
        let share = MemoryShare::new(20 * size);
        let mut store = KeptStore::default();
        let pinned = |s, job: &str, round| Kept {
            pin: Some(Pin {
                job: job.to_string(),
                round,
                at: std::time::Instant::now(),
            }),
            ..kept(s)
        };
        store.insert(1, pinned(results(&share, 10), "a", 1));
        store.insert(2, kept(results(&share, 10)));
        // Room is made from the unpinned only.
        store.make_room(&share, 20 * size);
        assert_eq!(store.ids(), vec![1]);
        store.insert(3, pinned(results(&share, 5), "a", 2));
        store.insert(4, pinned(results(&share, 5), "b", 1));
        store.release("a", 2);
        assert_eq!(store.ids(), vec![1, 3, 4]);
        // Round 3 reads round 2's records, not round 1's; other jobs'
        // stay.
        store.release("a", 3);
        assert_eq!(store.ids(), vec![3, 4]);
        // Job b started again: its round-1 task drops what the given-up
        // attempt left from later rounds.
        store.insert(6, pinned(results(&share, 1), "b", 3));
        store.release("b", 1);
        assert_eq!(store.ids(), vec![3, 4]);
        // Job b ended before the coordinator was asked, a later one not.
        let asked = std::time::Instant::now();
        store.insert(5, pinned(results(&share, 1), "c", 1));
        store.release_ended(&["a".to_string()], asked);
        assert_eq!(store.ids(), vec![3, 5]);
    }

    #[test]
    fn making_room_drops_the_oldest_records_only_they_hold() {
        let size = std::mem::size_of::<ResultRec>() as u64;
        let share = MemoryShare::new(30 * size);
        let mut store = KeptStore::default();
        let a = results(&share, 10);
        // A task's input still holds b's records: dropping b's entry
        // would free nothing.
        let b = results(&share, 10);
        let b_input = b.sub(0, 10).unwrap();
        store.insert(1, kept(b));
        store.insert(2, kept(a));
        store.insert(3, kept(results(&share, 10)));
        assert_eq!(share.available(), 0);
        // More than the whole share: nothing is dropped for nothing.
        store.make_room(&share, 31 * size);
        assert_eq!(store.ids(), vec![1, 2, 3]);
        // Room for 15: task 1 is oldest but shared, so 2 then 3 go.
        store.make_room(&share, 15 * size);
        assert_eq!(store.ids(), vec![1]);
        assert_eq!(share.available(), 20 * size);
        drop(b_input);
        store.make_room(&share, 30 * size);
        assert!(store.ids().is_empty());
        assert_eq!(share.used(), 0);
    }
}

use super::pyramid::Pyramid;
use crate::error::Error;
use crate::grid::GridSpec;
use crate::grid::aggregate;
use crate::grid::nested::{Boxes, Entry, Hierarchies, MIN_OBJECTS, NESTED};
use crate::objects::ObjectStore;
use crate::scene::Aabb;
use rayon::prelude::*;
use std::sync::atomic::AtomicU32;
use std::sync::atomic::AtomicU64;
use std::sync::atomic::Ordering::Relaxed;

impl Boxes for ObjectStore {
    fn count(&self) -> usize {
        self.len()
    }

    #[inline]
    fn bbox(&self, id: u32) -> Aabb {
        ObjectStore::bbox(self, id)
    }

    fn each_in(&self, ids: std::ops::Range<u32>, f: impl FnMut(u32, Aabb)) {
        self.each_bbox_in(ids, f)
    }

    #[inline]
    fn rank(&self, id: u32) -> u32 {
        self.ranks().get(id as usize).copied().unwrap_or(id)
    }

    fn ranked(&self) -> bool {
        !self.ranks().is_empty()
    }
}

/// A uniform grid listing, per voxel, the objects whose bounding box
/// overlaps it: one flat array of object ids and the start of each
/// listing voxel's run (mark, count, prefix-sum, fill), in object id order
/// within a voxel (input id order, for a database in spatial order, so
/// that objects are met, and shadow rays stop, as in the input's order). A voxel listing more than [`MIN_OBJECTS`] objects lists
/// instead one entry tagged [`NESTED`], a hierarchy of boxes over them
/// (see [`crate::grid::nested`]).
///
/// Only voxels that list something have a start: a bit per voxel says
/// which, and a count per 64 voxels ranks them. A grid sized for a
/// surface is mostly empty voxels; a start for each of them cost the
/// dragon 16 bytes per triangle, more than its triangles.
pub struct ObjectGrid {
    pub spec: GridSpec,
    /// A bit per voxel, set if it lists anything.
    occupied: Vec<u64>,
    /// Listing voxels before each word of `occupied`.
    before: Vec<u32>,
    /// Start in `items` of each listing voxel's entries, and their end.
    start: Vec<u32>,
    items: Vec<u32>,
    pub objects: u64,
    nested: Hierarchies,
    /// Voxels with a hierarchy, and the object entries they replace.
    pub nested_voxels: u64,
    pub nested_entries: u64,
    /// Groups of objects held as aggregates ([`crate::grid::aggregate`]).
    pub aggregates: u64,
    /// Coarser copies of `occupied`, for walks that skip empty space.
    pub pyramid: Pyramid,
    /// The lowest id of the grid's objects whose box it does not hold
    /// (a database whose summaries lie), found by the build's first pass
    /// over the boxes rather than by a pass of its own.
    pub outside: Option<u32>,
}

/// The share of listing voxels above which a grid is [`ObjectGrid::dense`]:
/// measured (instructions of 256x256 renders), the SPD's balls (37 %),
/// gears (50 %) and rings (22 %) gain from lone rays walking voxel by
/// voxel; teapot (13 %), mount (14 %), tetra (17 %), tree (8 %) and the
/// Stanford dragon (5 %) lose.
const DENSE: f64 = 0.2;

impl ObjectGrid {
    /// Builds the grid over `bounds` for the objects (by id) `member` selects,
    /// holding crowded groups as aggregates if `aggregates`; `pool` builds
    /// the crowded voxels' hierarchies.
    pub fn build(
        boxes: &(impl Boxes + ?Sized),
        bounds: &Aabb,
        res: [u32; 3],
        pool: &rayon::ThreadPool,
        aggregates: bool,
        member: impl Fn(usize) -> bool + Sync,
    ) -> Result<ObjectGrid, Error> {
        let spec = GridSpec::new(bounds, res);
        let cells = spec.cells();
        let (nested, groups) = if aggregates {
            find_aggregates(boxes, &spec, &member, pool)?
        } else {
            Default::default()
        };
        // The objects in consecutive stretches of ids, one a thread: each
        // pass covers them side by side. A voxel lists its objects in id
        // order whatever the threads, the stretches' in turn (the
        // groups' entries, after every object, with the last stretch).
        let threads = pool.current_num_threads();
        let parts = id_stretches(boxes.count(), threads);
        let mut covers = Covers {
            boxes,
            spec: &spec,
            parts: &parts,
            member: &member,
            groups: &groups,
            ranges: &[],
            packing: Packing::of(&spec),
        };
        // Mark: a bit per voxel an object covers. Each object's voxels
        // are found from its box once, and kept packed for the passes
        // after: finding them again in each pass was about a quarter of
        // the dragon's build (callgrind: 1,034 M -> 763 M instructions),
        // for four bytes an object held while the grid is built.
        let marks: Vec<AtomicU64> = (0..cells.div_ceil(64)).map(|_| AtomicU64::new(0)).collect();
        let mut ranges = vec![NOT_LISTED; boxes.count()];
        let firsts = per_part(pool, split_by(&mut ranges, &parts), |k, kept| {
            let mut total = 0u64;
            let outside = covers.first(k, kept, &mut |_, row, len| {
                for c in row..row + len {
                    let (word, bit) = (&marks[c >> 6], 1u64 << (c & 63));
                    // Most covers find their voxel marked: a load, no
                    // write.
                    if word.load(Relaxed) & bit == 0 {
                        word.fetch_or(bit, Relaxed);
                    }
                }
                total += len as u64;
            });
            (total, outside)
        });
        let total: u64 = firsts.iter().map(|f| f.0).sum();
        // The stretches come in id order.
        let outside = firsts.iter().find_map(|f| f.1);
        let occupied: Vec<u64> = marks.into_iter().map(AtomicU64::into_inner).collect();
        if total > u32::MAX as u64 {
            return Err(Error::Invalid(format!(
                "the grid would list {total} object-voxel pairs; choose a coarser --grid-res"
            )));
        }
        let mut listing = 0u32;
        let before: Vec<u32> = occupied
            .iter()
            .map(|w| {
                let b = listing;
                listing += w.count_ones();
                b
            })
            .collect();
        // A voxel's place among the listing voxels. Every voxel of a
        // cover's row is marked, so the row's voxels follow each other
        // there: one rank a row, not a count of bits per voxel.
        let rank = |c: usize| {
            let w = occupied[c >> 6];
            before[c >> 6] as usize + (w & ((1 << (c & 63)) - 1)).count_ones() as usize
        };
        let row_rank = |row: usize, len: usize| {
            debug_assert!((row..row + len).all(|c| occupied[c >> 6] >> (c & 63) & 1 != 0));
            rank(row)
        };
        // Count: each stretch's objects per listing voxel. A count per
        // listing voxel for each stretch: no more stretches than voxels
        // list objects on average, so that the counts take no more room
        // than the lists.
        let parts = id_stretches(
            boxes.count(),
            threads.min(total as usize / listing.max(1) as usize),
        );
        covers.parts = &parts;
        covers.ranges = &ranges;
        let mut counts: Vec<Vec<u32>> = per_part(pool, vec![(); parts.len()], |k, ()| {
            let mut n = vec![0u32; listing as usize];
            covers.of(k, &mut |_, row, len| {
                let r = row_rank(row, len);
                for v in &mut n[r..r + len] {
                    *v += 1;
                }
            });
            n
        });
        // Each listing voxel's start, and where each stretch's objects
        // go in it: the counts become those places.
        let mut start = vec![0u32; listing as usize + 1];
        let mut acc = 0u32;
        for (k, s) in start[..listing as usize].iter_mut().enumerate() {
            *s = acc;
            for n in counts.iter_mut() {
                (n[k], acc) = (acc, acc + n[k]);
            }
        }
        start[listing as usize] = acc;
        // Fill: each stretch writes its places, which no other writes.
        let mut items = vec![0u32; total as usize];
        let shared = atomic(&mut items);
        let n: u64 = per_part(pool, counts, |k, mut place| {
            let (mut n, mut last) = (0u64, u32::MAX);
            covers.of(k, &mut |id, row, len| {
                let r = row_rank(row, len);
                for p in &mut place[r..r + len] {
                    shared[*p as usize].store(id, Relaxed);
                    *p += 1;
                }
                if id != last {
                    last = id;
                    n += if id & NESTED == 0 {
                        1
                    } else {
                        aggregate::SIZE as u64
                    };
                }
            });
            n
        })
        .into_iter()
        .sum();
        // Not held through the sort and the hierarchies' build.
        drop(ranges);
        if boxes.ranked() {
            sort_by_rank(boxes, &start, &mut items, pool);
        }
        let mut grid = ObjectGrid {
            spec,
            occupied,
            before,
            start,
            items,
            objects: n,
            nested,
            nested_voxels: 0,
            nested_entries: 0,
            aggregates: groups.len() as u64,
            pyramid: Pyramid::default(),
            outside,
        };
        grid.nest(boxes, pool)?;
        grid.pyramid = Pyramid::build(grid.spec.res, &grid.occupied);
        Ok(grid)
    }

    /// Gives each voxel of more than [`MIN_OBJECTS`] objects a hierarchy,
    /// the voxels shared out among the threads of `pool`.
    fn nest(
        &mut self,
        boxes: &(impl Boxes + ?Sized),
        pool: &rayon::ThreadPool,
    ) -> Result<(), Error> {
        // By listing voxel (the index of its start).
        let crowded: Vec<usize> = (0..self.start.len() - 1)
            .filter(|&k| self.list(k).len() > MIN_OBJECTS)
            .collect();
        if crowded.is_empty() {
            return Ok(());
        }
        let (start, items) = (&self.start, &self.items);
        // A crowded voxel's aggregates are boxes of its hierarchy, with
        // their own hierarchies below them.
        let listed = Entries {
            boxes,
            aggregates: &self.nested,
        };
        let built: Vec<Hierarchies> = pool.install(|| {
            crowded
                .par_iter()
                .map(|&c| {
                    let ids = &items[start[c] as usize..start[c + 1] as usize];
                    let mut h = Hierarchies::default();
                    h.build(ids, &listed);
                    h
                })
                .collect()
        });
        // Each built piece is freed once copied, so the hierarchies are
        // not held twice over (the reserved room is touched as it fills).
        let nodes = built.iter().map(Hierarchies::nodes).sum();
        let listed = built.iter().map(Hierarchies::len).sum();
        self.nested.reserve(nodes, listed);
        let mut entries = Vec::with_capacity(built.len());
        for h in built {
            self.nested_entries += h.len() as u64;
            entries.push(self.nested.append(h).ok_or_else(|| {
                Error::Invalid(format!(
                    "the crowded voxels' hierarchies need {nodes} nodes, more than 2^31; \
                     choose a finer --grid-res"
                ))
            })?);
        }
        self.nested_voxels = crowded.len() as u64;
        // Each crowded voxel's list shrinks to its one entry: compact the
        // lists in place, front to back (nothing is written past what has
        // been read), moving the runs between crowded voxels whole.
        let (mut removed, mut moved_to, mut shifted) = (0usize, 0usize, 0usize);
        for (&k, &e) in crowded.iter().zip(&entries) {
            let (a, b) = (self.start[k] as usize, self.start[k + 1] as usize);
            for s in &mut self.start[shifted..=k] {
                *s -= removed as u32;
            }
            shifted = k + 1;
            self.items.copy_within(moved_to..a, moved_to - removed);
            self.items[a - removed] = e;
            removed += b - a - 1;
            moved_to = b;
        }
        for s in &mut self.start[shifted..] {
            *s -= removed as u32;
        }
        let n = self.items.len();
        self.items.copy_within(moved_to..n, moved_to - removed);
        self.items.truncate(n - removed);
        self.items.shrink_to_fit();
        Ok(())
    }

    #[inline(always)]
    pub fn single_cell(&self) -> bool {
        self.spec.res == [1, 1, 1]
    }

    /// The entries of the `k`th listing voxel.
    #[inline(always)]
    fn list(&self, k: usize) -> &[u32] {
        &self.items[self.start[k] as usize..self.start[k + 1] as usize]
    }

    /// The entries of voxel `index`: object ids, and hierarchies tagged
    /// [`NESTED`] (see [`ObjectGrid::visit`]).
    #[inline(always)]
    pub fn cell(&self, index: usize) -> &[u32] {
        let (w, bit) = (self.occupied[index >> 6], 1u64 << (index & 63));
        if w & bit == 0 {
            return &[];
        }
        self.list(self.before[index >> 6] as usize + (w & (bit - 1)).count_ones() as usize)
    }

    /// The hierarchies of the crowded voxels (the entries tagged
    /// [`NESTED`]).
    #[inline(always)]
    pub fn hierarchies(&self) -> &Hierarchies {
        &self.nested
    }

    /// Whether voxel `index` lists anything.
    #[inline(always)]
    pub fn occupied(&self, index: usize) -> bool {
        self.occupied[index >> 6] >> (index & 63) & 1 != 0
    }

    /// Whether enough of the grid's voxels list something that a lone
    /// ray walks it faster voxel by voxel than by skipping empty blocks.
    #[inline(always)]
    pub fn dense(&self) -> bool {
        let cells = self.spec.res.iter().map(|&r| r as f64).product::<f64>();
        (self.start.len() - 1) as f64 >= DENSE * cells
    }

    /// Entries listed, and voxels listing any.
    pub fn sizes(&self) -> (usize, usize) {
        (self.items.len(), self.start.len() - 1)
    }

    /// Bytes held.
    pub fn bytes(&self) -> u64 {
        (8 * self.occupied.len()
            + 4 * (self.before.len() + self.start.len() + self.items.len())
            + self.nested.bytes()
            + self.pyramid.bytes()) as u64
    }

    /// Gives `f` the objects of voxel `index` with state `state`: listed
    /// ones directly; those of a hierarchy as [`Hierarchies::visit`] does
    /// (`f` decides which boxes to descend into and with what state;
    /// `high_first` orders the children). Returns `false` if `f` stopped
    /// it (returned `None` for an object).
    #[inline(always)]
    pub fn visit<S: Copy>(
        &self,
        index: usize,
        high_first: u8,
        state: S,
        f: &mut impl FnMut(Entry<'_, S>) -> Option<S>,
    ) -> bool {
        for &e in self.cell(index) {
            let go = if e & NESTED == 0 {
                f(Entry::Object(e, state)).is_some()
            } else {
                self.nested.visit(e, high_first, state, f)
            };
            if !go {
                return false;
            }
        }
        true
    }
}

/// A voxel's entries as boxes: objects, and aggregates (tagged
/// [`NESTED`]) by the box of their hierarchy.
struct Entries<'a, B: ?Sized> {
    boxes: &'a B,
    aggregates: &'a Hierarchies,
}

impl<B: Boxes + ?Sized> Boxes for Entries<'_, B> {
    fn count(&self) -> usize {
        self.boxes.count()
    }

    fn bbox(&self, e: u32) -> Aabb {
        if e & NESTED == 0 {
            self.boxes.bbox(e)
        } else {
            self.aggregates.bbox(e)
        }
    }

    /// Objects by input id; an aggregate by its entry, above them all.
    fn rank(&self, e: u32) -> u32 {
        if e & NESTED == 0 {
            self.boxes.rank(e)
        } else {
            e
        }
    }
}

/// A group of objects held as an aggregate: its first object, the entry
/// of its hierarchy, and its voxel box.
struct Group {
    first: u32,
    entry: u32,
    lo: [u32; 3],
    hi: [u32; 3],
}

/// What a grid's passes cover, in stretches of ids side by side.
struct Covers<'a, B: ?Sized, M> {
    boxes: &'a B,
    spec: &'a GridSpec,
    parts: &'a [std::ops::Range<u32>],
    member: &'a M,
    groups: &'a [Group],
    /// Each object's voxels as the first pass found them, packed.
    ranges: &'a [u32],
    packing: Packing,
}

impl<B: Boxes + ?Sized, M: Fn(usize) -> bool> Covers<'_, B, M> {
    /// [`each_cover`] of stretch `k`, the groups' entries with the last
    /// stretch (they follow every object in a voxel's list), keeping
    /// each object's voxels in `kept` (the stretch's part of the ranges);
    /// the stretch's first object whose box the grid does not hold.
    #[inline]
    fn first(
        &self,
        k: usize,
        kept: &mut [u32],
        f: &mut impl FnMut(u32, usize, usize),
    ) -> Option<u32> {
        let ids = self.parts[k].clone();
        let base = ids.start;
        let outside = each_cover(
            self.boxes,
            self.spec,
            ids,
            self.member,
            self.groups,
            &mut |id, lo, hi| {
                kept[(id - base) as usize] = self.packing.pack(self.spec, lo, hi);
                cover(self.spec, id, lo, hi, f);
            },
        );
        self.groups_of(k, f);
        outside
    }

    /// The covers of stretch `k` again, from the ranges the first pass
    /// kept.
    #[inline]
    fn of(&self, k: usize, f: &mut impl FnMut(u32, usize, usize)) {
        let ids = self.parts[k].clone();
        let spec = self.spec;
        for (id, &w) in ids
            .clone()
            .zip(&self.ranges[ids.start as usize..ids.end as usize])
        {
            match w {
                NOT_LISTED => {}
                WIDE => {
                    let (lo, hi) = spec.cell_range(&self.boxes.bbox(id)).expect("listed");
                    cover(spec, id, lo, hi, f);
                }
                w => self.packing.cover(spec, id, w, f),
            }
        }
        self.groups_of(k, f);
    }

    /// The groups' covers, with the last stretch.
    #[inline]
    fn groups_of(&self, k: usize, f: &mut impl FnMut(u32, usize, usize)) {
        if k + 1 == self.parts.len() {
            for g in self.groups {
                cover(self.spec, g.entry, g.lo, g.hi, f);
            }
        }
    }
}

/// `v` split in the stretches `parts` (consecutive from 0, covering it).
fn split_by<'a, T>(mut v: &'a mut [T], parts: &[std::ops::Range<u32>]) -> Vec<&'a mut [T]> {
    parts
        .iter()
        .map(|p| {
            let (head, rest) = std::mem::take(&mut v).split_at_mut(p.len());
            v = rest;
            head
        })
        .collect()
}

/// A packed range for an object the grid does not list (not a member,
/// in a group, or outside).
const NOT_LISTED: u32 = 0;
/// A packed range for an object whose voxels do not fit a word: they are
/// found again from its box.
const WIDE: u32 = u32::MAX;

/// How a grid packs an object's voxels `lo..=hi` in 32 bits (four bytes
/// an object while the grid is built): the first voxel's index plus one
/// in the low bits, as many as the grid's voxels need, then the range's
/// extent less one along each axis in a third each of the bits left. An
/// extent whose bits would all be set does not fit, so no packed range
/// is [`WIDE`]. (The dragon's grid leaves three bits an axis: ranges of
/// up to seven voxels.)
#[derive(Clone, Copy)]
struct Packing {
    index_bits: u32,
    extent_bits: u32,
}

impl Packing {
    fn of(spec: &GridSpec) -> Packing {
        let index_bits = u64::BITS - (spec.cells() as u64).leading_zeros();
        Packing {
            index_bits: index_bits.min(32),
            extent_bits: 32u32.saturating_sub(index_bits) / 3,
        }
    }

    #[inline(always)]
    fn pack(self, spec: &GridSpec, lo: [u32; 3], hi: [u32; 3]) -> u32 {
        let limit = (1u32 << self.extent_bits) - 1;
        let e = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        if e.iter().any(|&x| x >= limit) {
            return WIDE;
        }
        let (i, b) = (self.index_bits, self.extent_bits);
        (spec.index(lo) as u32 + 1) | e[0] << i | e[1] << (i + b) | e[2] << (i + 2 * b)
    }

    /// [`cover`] of the voxels packed in `w`: the same rows in the same
    /// order.
    #[inline(always)]
    fn cover(self, spec: &GridSpec, entry: u32, w: u32, f: &mut impl FnMut(u32, usize, usize)) {
        let (i, b) = (self.index_bits, self.extent_bits);
        let field = |at: u32, bits: u32| (w >> at & ((1u64 << bits) - 1) as u32) as usize;
        let first = field(0, i) - 1;
        let e = [field(i, b), field(i + b, b), field(i + 2 * b, b)];
        let (sy, sz) = (
            spec.res[0] as usize,
            spec.res[0] as usize * spec.res[1] as usize,
        );
        for z in 0..e[2] + 1 {
            for y in 0..e[1] + 1 {
                f(entry, first + y * sy + z * sz, e[0] + 1);
            }
        }
    }
}

/// Gives `f` the voxel range `(id, lo, hi)` of `spec` that each of the
/// objects of `ids` that `member` selects covers, the objects of
/// `groups` aside; returns the first of those objects (groups' too)
/// whose box `spec` does not hold. Generic, not through `dyn` calls:
/// making the calls (of this, of the walk over the objects and of
/// `GridSpec::cell_range`) static cut the dragon's preprocessing by 13 %
/// of its instructions (callgrind), when the passes each ran it.
#[inline]
fn each_cover(
    boxes: &(impl Boxes + ?Sized),
    spec: &GridSpec,
    ids: std::ops::Range<u32>,
    member: &impl Fn(usize) -> bool,
    groups: &[Group],
    f: &mut impl FnMut(u32, [u32; 3], [u32; 3]),
) -> Option<u32> {
    // Groups come in id order: the one that may hold `id`.
    let grouped = |id: u32| {
        let k = groups.partition_point(|g| g.first + aggregate::SIZE as u32 <= id);
        groups.get(k).is_some_and(|g| g.first <= id)
    };
    let mut outside = None;
    boxes.each_in(ids, |id, b| {
        if !member(id as usize) {
            return;
        }
        if outside.is_none() && !spec.holds(&b) {
            outside = Some(id);
        }
        if grouped(id) {
            return;
        }
        if let Some((lo, hi)) = spec.cell_range(&b) {
            f(id, lo, hi);
        }
    });
    outside
}

/// Gives `f` the voxels of `spec` from `lo` to `hi`, with `entry`, a
/// row along x at a time: `f(entry, first, len)` for the voxels `first..
/// first + len`, which follow each other in the grid's order. A function
/// always inlined, not a closure: as a closure, called per object, it was
/// left a call in some of the grid's passes. (Exclusive ranges, which
/// compile to plainer loops than inclusive ones: a voxel coordinate is
/// far below `u32::MAX`.)
#[inline(always)]
fn cover(
    spec: &GridSpec,
    entry: u32,
    lo: [u32; 3],
    hi: [u32; 3],
    f: &mut impl FnMut(u32, usize, usize),
) {
    let len = (hi[0] - lo[0] + 1) as usize;
    for z in lo[2]..hi[2] + 1 {
        for y in lo[1]..hi[1] + 1 {
            f(entry, spec.index([lo[0], y, z]), len);
        }
    }
}

/// `f(k, state)` for each stretch `k` and its state, side by side on
/// `pool`'s threads; on the caller's thread if there is one stretch (a
/// hand-over to the pool's thread made a one-thread build slower).
pub(super) fn per_part<S: Send, T: Send>(
    pool: &rayon::ThreadPool,
    states: Vec<S>,
    f: impl Fn(usize, S) -> T + Sync,
) -> Vec<T> {
    if states.len() == 1 {
        return states.into_iter().map(|s| f(0, s)).collect();
    }
    pool.install(|| {
        states
            .into_par_iter()
            .enumerate()
            .map(|(k, s)| f(k, s))
            .collect()
    })
}

/// `v` as atomics, for threads that each write places of it no other
/// thread writes. Not a `Vec` of atomics: that is written through once to
/// make it, where `vec![0; n]` takes pages the system has zeroed.
fn atomic(v: &mut [u32]) -> &[AtomicU32] {
    const { assert!(align_of::<AtomicU32>() == align_of::<u32>()) };
    // SAFETY: `AtomicU32` has the size and bit validity of `u32` (std's
    // documentation) and, asserted above, its alignment, so `v`'s memory
    // is a valid `[AtomicU32]` of the same length (what the unstable
    // `AtomicU32::from_mut_slice` does). The shared borrow returned keeps
    // `v` exclusively borrowed while it lives, so nothing reaches the
    // memory other than through the atomics meanwhile.
    unsafe { &*(v as *mut [u32] as *const [AtomicU32]) }
}

/// Ids `0..count` in at most `threads` consecutive stretches of about
/// the same length (one, empty, if there are no objects).
pub(super) fn id_stretches(count: usize, threads: usize) -> Vec<std::ops::Range<u32>> {
    // A stretch of fewer objects is not worth a thread's wake-up (the
    // unit tests split even a few objects, to build as many threads do).
    const LEAST: usize = if cfg!(test) { 1 } else { 1 << 14 };
    let n = threads.min(count / LEAST).max(1);
    (0..n)
        .map(|k| (count * k / n) as u32..(count * (k + 1) / n) as u32)
        .collect()
}

/// Sorts each listing voxel's objects (its entries before any aggregate)
/// by input id: voxels in stretches of about [`SORT_STRETCH`] entries,
/// side by side on `pool`'s threads.
fn sort_by_rank(
    boxes: &(impl Boxes + ?Sized),
    start: &[u32],
    items: &mut [u32],
    pool: &rayon::ThreadPool,
) {
    // A stretch's voxels: their starts (the last one ends them), and
    // their entries.
    let sort = |keys: &mut Vec<u64>, (starts, list): (&[u32], &mut [u32])| {
        let base = starts[0];
        for w in starts.windows(2) {
            let list = &mut list[(w[0] - base) as usize..(w[1] - base) as usize];
            let objects = list.partition_point(|&e| e & NESTED == 0);
            if objects < 2 {
                continue;
            }
            // Each object's input id looked up once and sorted with it
            // (input ids are distinct): looked up in every comparison,
            // this sort was a tenth of the dragon's preprocessing.
            keys.clear();
            keys.extend(
                list[..objects]
                    .iter()
                    .map(|&id| (boxes.rank(id) as u64) << 32 | id as u64),
            );
            keys.sort_unstable();
            for (e, &k) in list.iter_mut().zip(keys.iter()) {
                *e = k as u32;
            }
        }
    };
    if pool.current_num_threads() == 1 {
        return sort(&mut Vec::new(), (start, items));
    }
    let mut stretches: Vec<(&[u32], &mut [u32])> = Vec::new();
    let (mut rest, mut first) = (items, 0usize);
    while first + 1 < start.len() {
        let from = start[first];
        let mut last = first + 1;
        while last + 1 < start.len() && start[last] - from < SORT_STRETCH {
            last += 1;
        }
        let (these, after) = std::mem::take(&mut rest).split_at_mut((start[last] - from) as usize);
        stretches.push((&start[first..=last], these));
        (rest, first) = (after, last);
    }
    pool.install(|| stretches.into_par_iter().for_each_init(Vec::new, sort));
}

/// Entries a stretch of voxels sorted by one thread holds, at least (a
/// few in the unit tests, to sort in many stretches).
const SORT_STRETCH: u32 = if cfg!(test) { 8 } else { 1 << 16 };

/// The groups of [`aggregate::SIZE`] consecutive objects, all `member`s,
/// that crowd their voxels of `spec`, in id order, and their hierarchies:
/// found in stretches of whole groups side by side on `pool`'s threads,
/// each stretch's hierarchies appended to the first's in turn (the very
/// arrays one pass over the objects makes).
fn find_aggregates(
    boxes: &(impl Boxes + ?Sized),
    spec: &GridSpec,
    member: &(impl Fn(usize) -> bool + Sync),
    pool: &rayon::ThreadPool,
) -> Result<(Hierarchies, Vec<Group>), Error> {
    let n = boxes.count();
    let whole =
        |id: u32| (id.div_ceil(aggregate::SIZE as u32) * aggregate::SIZE as u32).min(n as u32);
    let parts: Vec<std::ops::Range<u32>> = id_stretches(n, pool.current_num_threads())
        .into_iter()
        .map(|r| whole(r.start)..whole(r.end))
        .collect();
    let mut found = per_part(pool, parts, |_, ids| {
        aggregates_in(boxes, spec, member, ids)
    })
    .into_iter();
    let (mut nested, mut groups) = found.next().unwrap_or_default();
    for (h, more) in found {
        let at = nested.append(h).ok_or_else(|| {
            Error::Invalid(
                "the aggregates' hierarchies need more than 2^31 nodes; \
                 render with --aggregates off or a finer --grid-res"
                    .into(),
            )
        })? & !NESTED;
        groups.extend(more.into_iter().map(|g| Group {
            entry: NESTED | (at + (g.entry & !NESTED)),
            ..g
        }));
    }
    Ok((nested, groups))
}

/// [`find_aggregates`] over the objects `ids_in` (whole groups), in one
/// pass.
fn aggregates_in(
    boxes: &(impl Boxes + ?Sized),
    spec: &GridSpec,
    member: &impl Fn(usize) -> bool,
    ids_in: std::ops::Range<u32>,
) -> (Hierarchies, Vec<Group>) {
    let mut nested = Hierarchies::default();
    let mut groups = Vec::new();
    let (mut ids, mut group, mut order) = (Vec::new(), Vec::new(), Vec::new());
    let mut close = |ids: &mut Vec<u32>, group: &mut Vec<Aabb>| {
        let mut bounds = Aabb::EMPTY;
        for b in group.iter() {
            bounds.union(b);
        }
        if let Some((lo, hi)) = aggregate::crowded(
            spec,
            &bounds,
            group.len(),
            aggregate::pairs(spec, group.iter()),
        ) {
            let entry = nested.build_aggregate(ids, boxes, &mut order);
            groups.push(Group {
                first: ids[0],
                entry,
                lo,
                hi,
            });
        }
        ids.clear();
        group.clear();
    };
    boxes.each_in(ids_in, &mut |id, b| {
        if ids
            .first()
            .is_some_and(|&f| f as usize / aggregate::SIZE != id as usize / aggregate::SIZE)
        {
            close(&mut ids, &mut group);
        }
        if member(id as usize) {
            ids.push(id);
            group.push(b);
        }
    });
    close(&mut ids, &mut group);
    (nested, groups)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Small boxes spread thinly, some wide ones, and a crowd of 160 in
    /// one corner (ids 300 to 459: groups 5 and 6 of 64 whole, the tail of
    /// group 4 before them and the head of group 7 after).
    fn scattered_and_crowded() -> Vec<Aabb> {
        let mut x: u64 = 5;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut boxes: Vec<Aabb> = (0..300)
            .map(|i| {
                let c = [next(), next(), next()];
                let r = if i % 50 == 0 { 0.3 } else { 0.01 };
                Aabb {
                    min: c.map(|v| v - r),
                    max: c.map(|v| v + r),
                }
            })
            .collect();
        boxes.extend((0..160).map(|_| Aabb {
            min: [0.001; 3],
            max: [0.002; 3],
        }));
        boxes
    }

    /// The grid of resolution `res` over the unit cube for `boxes`, with
    /// aggregates if `aggregates`, built on three threads (in three
    /// stretches of ids).
    fn unit_grid(boxes: &[Aabb], res: [u32; 3], aggregates: bool) -> ObjectGrid {
        built_on(3, boxes, res, aggregates, |_| true)
    }

    fn built_on(
        threads: usize,
        boxes: &(impl Boxes + ?Sized),
        res: [u32; 3],
        aggregates: bool,
        member: impl Fn(usize) -> bool + Sync,
    ) -> ObjectGrid {
        let bounds = Aabb {
            min: [0.0; 3],
            max: [1.0; 3],
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        ObjectGrid::build(boxes, &bounds, res, &pool, aggregates, member).unwrap()
    }

    /// `boxes` in a spatial order: input ids a permutation of the ids.
    struct Ranked<'a>(&'a [Aabb]);

    impl Boxes for Ranked<'_> {
        fn count(&self) -> usize {
            self.0.len()
        }

        fn bbox(&self, id: u32) -> Aabb {
            self.0[id as usize]
        }

        fn rank(&self, id: u32) -> u32 {
            (id * 7 + 3) % self.0.len() as u32
        }

        fn ranked(&self) -> bool {
            true
        }
    }

    /// A grid is the same built on one thread or on several (its objects
    /// covered in stretches of ids side by side, its lists sorted in
    /// stretches of voxels), with aggregates or without, its objects in
    /// id order or in a spatial order, of all objects or of some (as each
    /// of several grids is).
    #[test]
    fn grids_built_on_many_threads_are_those_built_on_one() {
        let boxes = scattered_and_crowded();
        // Every third object left out.
        let some = |id: usize| id % 3 != 1;
        let fields = |g: &ObjectGrid| {
            (
                g.occupied.clone(),
                g.before.clone(),
                g.start.clone(),
                g.items.clone(),
                [g.objects, g.nested_voxels, g.nested_entries, g.aggregates],
            )
        };
        let mut reordered = false;
        // Coarse grids too: fill passes split only where voxels list
        // several objects on average.
        for res in [
            [1, 1, 1],
            [2, 3, 2],
            [4, 4, 4],
            [7, 9, 10],
            [13, 13, 13],
            [600, 2, 3],
        ] {
            for aggregates in [false, true] {
                let one = fields(&built_on(1, &boxes[..], res, aggregates, some));
                let ranked = fields(&built_on(1, &Ranked(&boxes), res, aggregates, some));
                reordered |= one.3 != ranked.3;
                for threads in [2, 3, 5] {
                    let case = format!("{res:?}, aggregates {aggregates}, {threads} threads");
                    let many = built_on(threads, &boxes[..], res, aggregates, some);
                    assert!(fields(&many) == one, "{case}");
                    assert!(
                        fields(&built_on(threads, &Ranked(&boxes), res, aggregates, some))
                            == ranked,
                        "{case}, ranked"
                    );
                }
            }
        }
        assert!(reordered, "the spatial order changed no list");
    }

    /// A grid names the lowest id among its objects whose box it does
    /// not hold, whatever the threads (the wide boxes stick out of the
    /// unit cube; every third object, and the first hundred, are not the
    /// grid's).
    #[test]
    fn a_grid_names_its_first_object_outside() {
        let boxes = scattered_and_crowded();
        // None of the first hundred either: the first stretches find none.
        let some = |id: usize| id % 3 != 1 && id >= 100;
        let spec = built_on(1, &boxes[..], [4, 4, 4], false, some).spec;
        let want = (0..boxes.len()).find(|&id| some(id) && !spec.holds(&boxes[id]));
        assert!(want.is_some());
        for threads in [1, 2, 3, 5] {
            for aggregates in [false, true] {
                let g = built_on(threads, &boxes[..], [4, 4, 4], aggregates, some);
                assert_eq!(g.outside.map(|id| id as usize), want, "{threads} threads");
            }
        }
        let inside: Vec<Aabb> = boxes.iter().filter(|b| spec.holds(b)).copied().collect();
        assert_eq!(
            built_on(3, &inside[..], [4, 4, 4], true, |_| true).outside,
            None
        );
    }

    /// The objects whose box overlaps voxel `index` of `spec`.
    fn overlapping(spec: &GridSpec, boxes: &[Aabb], index: usize) -> Vec<u32> {
        (0..boxes.len() as u32)
            .filter(|&id| {
                let (rx, ry) = (spec.res[0] as usize, spec.res[1] as usize);
                let c = [index % rx, index / rx % ry, index / (rx * ry)].map(|v| v as u32);
                spec.cell_range(&boxes[id as usize])
                    .is_some_and(|(lo, hi)| (0..3).all(|a| lo[a] <= c[a] && c[a] <= hi[a]))
            })
            .collect()
    }

    /// Every voxel lists exactly the objects whose box overlaps it, in id
    /// order, whether it is the first or last of its word of 64 voxels,
    /// and an empty voxel lists none; a crowded voxel lists one
    /// hierarchy. In the grid of 600 voxels along x the wide boxes span
    /// 360, more than a packed range holds ([`Packing`]).
    #[test]
    fn each_voxel_lists_the_objects_overlapping_it() {
        let boxes = scattered_and_crowded();
        let wide = GridSpec::new(
            &Aabb {
                min: [0.0; 3],
                max: [1.0; 3],
            },
            [600, 2, 3],
        );
        assert!(boxes.iter().any(|b| {
            let (lo, hi) = wide.cell_range(b).unwrap();
            Packing::of(&wide).pack(&wide, lo, hi) == WIDE
        }));
        for res in [[1, 1, 1], [7, 9, 10], [64, 3, 2], [13, 13, 13], [600, 2, 3]] {
            let g = unit_grid(&boxes, res, false);
            let mut listing = 0;
            for index in 0..g.spec.cells() {
                let want = overlapping(&g.spec, &boxes, index);
                listing += !want.is_empty() as usize;
                let got = g.cell(index);
                if want.len() > MIN_OBJECTS {
                    assert!(
                        got.len() == 1 && got[0] & NESTED != 0,
                        "{res:?} voxel {index}"
                    );
                } else {
                    assert_eq!(got, want.as_slice(), "{res:?} voxel {index}");
                }
            }
            assert_eq!(g.sizes().1, listing, "{res:?}");
            assert!(
                res == [1, 1, 1] || listing < g.spec.cells(),
                "{res:?}: no empty voxel"
            );
        }
    }

    /// With aggregates, the crowd's two whole groups (at least) are each
    /// held by their box, and a walk of a voxel (every box entered) meets every
    /// object overlapping it exactly once, through a crowded voxel's
    /// hierarchy and the aggregates' below it alike.
    #[test]
    fn a_walk_meets_each_object_of_a_voxel_once_through_aggregates() {
        let boxes = scattered_and_crowded();
        for res in [[1, 1, 1], [7, 9, 10], [13, 13, 13]] {
            let g = unit_grid(&boxes, res, true);
            assert!(g.aggregates >= 2, "{res:?}: {} aggregates", g.aggregates);
            assert_eq!(g.objects, boxes.len() as u64, "{res:?}");
            for index in 0..g.spec.cells() {
                let want = overlapping(&g.spec, &boxes, index);
                let mut got = Vec::new();
                g.visit(index, 0, (), &mut |e| {
                    if let Entry::Object(id, ()) = e {
                        got.push(id);
                    }
                    Some(())
                });
                got.sort_unstable();
                let mut once = got.clone();
                once.dedup();
                assert_eq!(once, got, "{res:?} voxel {index}: met twice");
                // An aggregate is met whole wherever its box is: in the
                // crowd's corner voxel, its objects all overlap it.
                assert_eq!(got, want, "{res:?} voxel {index}");
            }
        }
    }
}

use super::pyramid::Pyramid;
use crate::error::Error;
use crate::grid::GridSpec;
use crate::grid::aggregate;
use crate::grid::nested::{Boxes, Entry, Hierarchies, MIN_OBJECTS, NESTED};
use crate::objects::ObjectStore;
use crate::scene::Aabb;
use rayon::prelude::*;

impl Boxes for ObjectStore {
    fn count(&self) -> usize {
        self.len()
    }

    #[inline]
    fn bbox(&self, id: u32) -> Aabb {
        ObjectStore::bbox(self, id)
    }

    fn each(&self, f: impl FnMut(u32, Aabb)) {
        self.each_bbox(f)
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
        member: impl Fn(usize) -> bool,
    ) -> Result<ObjectGrid, Error> {
        let spec = GridSpec::new(bounds, res);
        let cells = spec.cells();
        let (nested, groups) = if aggregates {
            find_aggregates(boxes, &spec, &member)
        } else {
            Default::default()
        };
        let mut occupied = vec![0u64; cells.div_ceil(64)];
        let mut total: u64 = 0;
        each_cover(boxes, &spec, &member, &groups, &mut |_, c| {
            occupied[c >> 6] |= 1 << (c & 63);
            total += 1;
        });
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
        let rank = |c: usize| {
            let w = occupied[c >> 6];
            before[c >> 6] as usize + (w & ((1 << (c & 63)) - 1)).count_ones() as usize
        };
        let mut start = vec![0u32; listing as usize + 1];
        each_cover(boxes, &spec, &member, &groups, &mut |_, c| {
            start[rank(c)] += 1
        });
        // Exclusive prefix sum: counts become each listing voxel's start.
        let mut acc = 0u32;
        for c in start.iter_mut() {
            let k = *c;
            *c = acc;
            acc += k;
        }
        let mut fill = start.clone();
        let mut items = vec![0u32; total as usize];
        let (mut n, mut last) = (0u64, u32::MAX);
        each_cover(boxes, &spec, &member, &groups, &mut |id, c| {
            let k = rank(c);
            items[fill[k] as usize] = id;
            fill[k] += 1;
            if id != last {
                last = id;
                n += if id & NESTED == 0 {
                    1
                } else {
                    aggregate::SIZE as u64
                };
            }
        });
        drop(fill);
        if boxes.ranked() {
            // Objects by input id; aggregates after them, as listed. Each
            // object's input id is looked up once and sorted with it (input
            // ids are distinct): looked up in every comparison, this sort
            // was a tenth of the dragon's preprocessing.
            let mut keys: Vec<u64> = Vec::new();
            for w in start.windows(2) {
                let list = &mut items[w[0] as usize..w[1] as usize];
                let objects = list.partition_point(|&e| e & NESTED == 0);
                if objects < 2 {
                    continue;
                }
                keys.clear();
                keys.extend(
                    list[..objects]
                        .iter()
                        .map(|&id| (boxes.rank(id) as u64) << 32 | id as u64),
                );
                keys.sort_unstable();
                for (e, &k) in list.iter_mut().zip(&keys) {
                    *e = k as u32;
                }
            }
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

/// Gives `f` each voxel of `spec` that each of the objects `member`
/// selects covers, the objects of `groups` aside, as `(id, voxel)`; then
/// each group's voxels, with its entry (which follows the objects in
/// every voxel's list). Generic, not through `dyn` calls: it runs three
/// times over every object of a grid, and making the calls (of this, of
/// the walk over the objects and of `GridSpec::cell_range`) static cut
/// the dragon's preprocessing by 13 % of its instructions (callgrind).
#[inline]
fn each_cover(
    boxes: &(impl Boxes + ?Sized),
    spec: &GridSpec,
    member: &impl Fn(usize) -> bool,
    groups: &[Group],
    f: &mut impl FnMut(u32, usize),
) {
    let mut cover = |entry: u32, lo: [u32; 3], hi: [u32; 3]| {
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                let row = spec.index([lo[0], y, z]);
                for x in 0..=(hi[0] - lo[0]) as usize {
                    f(entry, row + x);
                }
            }
        }
    };
    // Groups come in id order: the one that may hold `id`.
    let grouped = |id: u32| {
        let k = groups.partition_point(|g| g.first + aggregate::SIZE as u32 <= id);
        groups.get(k).is_some_and(|g| g.first <= id)
    };
    boxes.each(|id, b| {
        if !member(id as usize) || grouped(id) {
            return;
        }
        if let Some((lo, hi)) = spec.cell_range(&b) {
            cover(id, lo, hi);
        }
    });
    for g in groups {
        cover(g.entry, g.lo, g.hi);
    }
}

/// The groups of [`aggregate::SIZE`] consecutive objects, all `member`s,
/// that crowd their voxels of `spec`, in id order, and their hierarchies.
fn find_aggregates(
    boxes: &(impl Boxes + ?Sized),
    spec: &GridSpec,
    member: &impl Fn(usize) -> bool,
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
    boxes.each(&mut |id, b| {
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
    /// aggregates if `aggregates`.
    fn unit_grid(boxes: &[Aabb], res: [u32; 3], aggregates: bool) -> ObjectGrid {
        let bounds = Aabb {
            min: [0.0; 3],
            max: [1.0; 3],
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        ObjectGrid::build(boxes, &bounds, res, &pool, aggregates, |_| true).unwrap()
    }

    /// The objects whose box overlaps voxel `index` of `spec`.
    fn overlapping(spec: &GridSpec, boxes: &[Aabb], index: usize) -> Vec<u32> {
        (0..boxes.len() as u32)
            .filter(|&id| {
                spec.cell_range(&boxes[id as usize])
                    .is_some_and(|(lo, hi)| {
                        (lo[0]..=hi[0]).any(|x| {
                            (lo[1]..=hi[1])
                                .any(|y| (lo[2]..=hi[2]).any(|z| spec.index([x, y, z]) == index))
                        })
                    })
            })
            .collect()
    }

    /// Every voxel lists exactly the objects whose box overlaps it, in id
    /// order, whether it is the first or last of its word of 64 voxels,
    /// and an empty voxel lists none; a crowded voxel lists one
    /// hierarchy.
    #[test]
    fn each_voxel_lists_the_objects_overlapping_it() {
        let boxes = scattered_and_crowded();
        for res in [[1, 1, 1], [7, 9, 10], [64, 3, 2], [13, 13, 13]] {
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

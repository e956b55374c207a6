use super::nested::{Entry, Hierarchies, MIN_OBJECTS, NESTED};
use crate::error::Error;
use crate::grid::GridSpec;
use crate::scene::Aabb;
use rayon::prelude::*;

/// A uniform grid listing, per voxel, the objects whose bounding box
/// overlaps it: one flat array of object ids and the start of each voxel's
/// run (count, prefix-sum, fill), in object id order within a voxel. A
/// voxel listing more than [`MIN_OBJECTS`] objects lists instead one entry
/// tagged [`NESTED`], a hierarchy of boxes over them (see [`super::nested`]).
pub struct ObjectGrid {
    pub spec: GridSpec,
    pub start: Vec<u32>,
    pub items: Vec<u32>,
    pub objects: u64,
    nested: Hierarchies,
    /// Voxels with a hierarchy, and the object entries they replace.
    pub nested_voxels: u64,
    pub nested_entries: u64,
}

impl ObjectGrid {
    /// Builds the grid over `bounds` for the objects (by id) `member` selects;
    /// `pool` builds the crowded voxels' hierarchies.
    pub fn build(
        bboxes: &[Aabb],
        bounds: &Aabb,
        res: [u32; 3],
        pool: &rayon::ThreadPool,
        member: impl Fn(usize) -> bool,
    ) -> Result<ObjectGrid, Error> {
        let spec = GridSpec::new(bounds, res);
        let cells = spec.cells();
        let mut count = vec![0u32; cells + 1];
        let mut total: u64 = 0;
        let mut n = 0u64;
        let each = |f: &mut dyn FnMut(u32, usize)| {
            for (id, b) in bboxes.iter().enumerate() {
                let id = id as u32;
                if !member(id as usize) {
                    continue;
                }
                if let Some((lo, hi)) = spec.cell_range(b) {
                    for z in lo[2]..=hi[2] {
                        for y in lo[1]..=hi[1] {
                            let row = spec.index([lo[0], y, z]);
                            for x in 0..=(hi[0] - lo[0]) as usize {
                                f(id, row + x);
                            }
                        }
                    }
                }
            }
        };
        each(&mut |_, c| {
            count[c] += 1;
            total += 1;
        });
        if total > u32::MAX as u64 {
            return Err(Error::Invalid(format!(
                "the grid would list {total} object-voxel pairs; choose a coarser --grid-res"
            )));
        }
        // Exclusive prefix sum: count becomes each voxel's start.
        let mut acc = 0u32;
        for c in count.iter_mut() {
            let k = *c;
            *c = acc;
            acc += k;
        }
        let mut fill = count.clone();
        let mut items = vec![0u32; total as usize];
        let mut last = u32::MAX;
        each(&mut |id, c| {
            items[fill[c] as usize] = id;
            fill[c] += 1;
            if id != last {
                last = id;
                n += 1;
            }
        });
        let mut grid = ObjectGrid {
            spec,
            start: count,
            items,
            objects: n,
            nested: Hierarchies::default(),
            nested_voxels: 0,
            nested_entries: 0,
        };
        grid.nest(bboxes, pool)?;
        Ok(grid)
    }

    /// Gives each voxel of more than [`MIN_OBJECTS`] objects a hierarchy,
    /// the voxels shared out among the threads of `pool`.
    fn nest(&mut self, bboxes: &[Aabb], pool: &rayon::ThreadPool) -> Result<(), Error> {
        let cells = self.start.len() - 1;
        let crowded: Vec<usize> = (0..cells)
            .filter(|&c| self.cell(c).len() > MIN_OBJECTS)
            .collect();
        if crowded.is_empty() {
            return Ok(());
        }
        let (start, items) = (&self.start, &self.items);
        let built: Vec<Hierarchies> = pool.install(|| {
            crowded
                .par_iter()
                .map(|&c| {
                    let ids = &items[start[c] as usize..start[c + 1] as usize];
                    let mut h = Hierarchies::default();
                    h.build(ids, bboxes);
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
        self.start.len() == 2
    }

    /// The entries of voxel `index`: object ids, and hierarchies tagged
    /// [`NESTED`] (see [`ObjectGrid::visit`]).
    #[inline(always)]
    pub fn cell(&self, index: usize) -> &[u32] {
        &self.items[self.start[index] as usize..self.start[index + 1] as usize]
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

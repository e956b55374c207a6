//! The breadth-first tracer's grids: per voxel one byte of flags, marked in
//! one sequential scan of the objects (the paper's Pseudocode 3): whether
//! any object's bounding box overlaps the voxel, and which of its six faces
//! lie on the boundary of some object's voxel box.

use super::skip::CellBox;
use crate::error::Error;
use crate::grid::{GridSpec, GridStat, MAX_GROUPS, Partition, aggregate};
use crate::progress::Progress;
use crate::scene::Aabb;
use crate::sdb::{BoxRef, Database, DbStats};

/// Some object's box overlaps the voxel.
pub const OCCUPIED: u8 = 1;

/// The flag of the voxel face on `axis`, at the low (`high = false`) or
/// high end.
#[inline(always)]
pub fn face_bit(axis: usize, high: bool) -> u8 {
    1 << (1 + 2 * axis + high as usize)
}

/// The face a ray enters a voxel through when it steps along `axis` in
/// direction `step`: stepping up enters through the low face.
#[inline(always)]
pub fn entry_face(axis: usize, step_up: bool) -> u8 {
    face_bit(axis, !step_up)
}

pub struct VoxelGrid {
    pub spec: GridSpec,
    pub flags: Vec<u8>,
    /// Which blocks of voxels have an occupied voxel (see [`BusyBlocks`]);
    /// empty for grids of fewer than [`SKIP_FROM_CELLS`] voxels.
    pub busy: BusyBlocks,
    /// A bit per voxel, set while a pass has rays registered in it: read
    /// for every object of every scan, so kept apart from `flags`, in an
    /// eighth of their bytes (mount11: 3.6 MiB, where the flags take 29
    /// and miss the cache).
    pub registered: Vec<u64>,
    pub objects: u64,
    /// Groups of objects the passes hold as aggregates.
    pub aggregates: u64,
}

/// Voxels a side of a [`BusyBlocks`] block, as a shift: 16 x 16 x 16.
/// Walks cross a block with no occupied voxel in one move
/// ([`crate::grid::Dda::leave_block`]), looking at a block once, as they
/// enter it. Measured with callgrind (mount9 from zstd, 256x256, `--memory
/// 32MiB`, one thread): 4 x 4 x 4 blocks looked at every step 11.20 G
/// instructions, those and 16 x 16 x 16 blocks 10.86 G, both looked at on
/// entry 10.73 G, 16 x 16 x 16 alone on entry 10.56 G.
pub const BLOCK_SHIFT: u32 = 4;
/// Grids of fewer voxels than this walk voxel by voxel, as before the
/// blocks: their flags stay in a core's cache, walks through them are
/// short, and the look on each block's entry cost more than it saved
/// (mount6 in memory, 32^3 voxels: 1.85 G -> 1.93 G instructions).
pub const SKIP_FROM_CELLS: usize = 1 << 20;

/// A bit per block of voxels ([`BLOCK_SHIFT`]): whether some voxel of it
/// is occupied. A walk reads it before a voxel's flags: mount11's rays
/// cross hundreds of empty voxels each, and their flags (a byte each,
/// 29 MiB) missed the cache at every step, a third of registration's time.
#[derive(Clone, Debug, Default)]
pub struct BusyBlocks {
    bits: Vec<u64>,
    /// Blocks along x, and along x and y.
    row: usize,
    slab: usize,
}

impl BusyBlocks {
    /// The blocks of `spec`'s voxels `flags`.
    pub fn of(spec: &GridSpec, flags: &[u8]) -> BusyBlocks {
        let shift = BLOCK_SHIFT;
        let b = spec.res.map(|r| (r as usize).div_ceil(1 << shift));
        let mut busy = BusyBlocks {
            bits: vec![0; (b[0] * b[1] * b[2]).div_ceil(64)],
            row: b[0],
            slab: b[0] * b[1],
        };
        let res = spec.res.map(|r| r as usize);
        for z in 0..res[2] {
            for y in 0..res[1] {
                let row = spec.index([0, y as u32, z as u32]);
                for (x, &f) in flags[row..row + res[0]].iter().enumerate() {
                    if f & OCCUPIED != 0 {
                        let i = (x >> shift) + busy.row * (y >> shift) + busy.slab * (z >> shift);
                        busy.bits[i / 64] |= 1 << (i % 64);
                    }
                }
            }
        }
        busy
    }

    /// Whether the block of voxel `cell` has an occupied voxel.
    #[inline(always)]
    pub fn any(&self, cell: [i32; 3]) -> bool {
        let i = (cell[0] as usize >> BLOCK_SHIFT)
            + self.row * (cell[1] as usize >> BLOCK_SHIFT)
            + self.slab * (cell[2] as usize >> BLOCK_SHIFT);
        self.bits[i / 64] >> (i % 64) & 1 != 0
    }

    /// Bytes of a grid's blocks, for the budget (none below
    /// [`SKIP_FROM_CELLS`], where they are not built).
    pub fn bytes_for(spec: &GridSpec) -> u64 {
        if spec.cells() < SKIP_FROM_CELLS {
            return 0;
        }
        let b = spec.res.map(|r| (r as u64).div_ceil(1 << BLOCK_SHIFT));
        (b[0] * b[1] * b[2]).div_ceil(64) * 8
    }

    /// Whether the grid has blocks (see [`SKIP_FROM_CELLS`]).
    #[inline(always)]
    pub fn is_empty(&self) -> bool {
        self.bits.is_empty()
    }
}

impl VoxelGrid {
    /// Whether a pass has rays registered in voxel `v`.
    #[inline(always)]
    pub fn is_registered(&self, v: usize) -> bool {
        self.registered[v / 64] >> (v % 64) & 1 != 0
    }

    /// Marks voxel `v` as holding registered rays, or not.
    #[inline(always)]
    pub fn set_registered(&mut self, v: usize, on: bool) {
        let bit = 1u64 << (v % 64);
        if on {
            self.registered[v / 64] |= bit;
        } else {
            self.registered[v / 64] &= !bit;
        }
    }
}

pub struct VoxelGrids {
    pub grids: Vec<VoxelGrid>,
    pub partition: Partition,
    /// Each block's voxel box in each grid (block-major, one box per
    /// grid): what a pass needs to know to leave the block unread.
    pub blocks: Vec<CellBox>,
    /// A bit per group of [`aggregate::SIZE`] objects (by index): whether
    /// it is an aggregate, as the build found it (empty when the passes
    /// hold none). A pass reads it rather than judge the group again
    /// from its objects' voxels, which it placed one by one in every scan
    /// (mount11: a tenth of its samples).
    pub(super) aggregate_groups: Vec<u64>,
}

/// The threads a grid build may use: a pool to place a batch of blocks'
/// objects on every core, and a reader thread to read and decompress
/// blocks ahead of them.
#[derive(Clone, Copy)]
pub struct BuildThreads<'p> {
    pub pool: Option<&'p rayon::ThreadPool>,
    /// Blocks a batch on the reader thread (0: no reader thread).
    pub read_ahead: usize,
}

/// What one block's objects mark in the grids.
struct BlockMarks {
    /// Per object, its grid and voxel box.
    cells: Vec<(u8, [u32; 3], [u32; 3])>,
    /// The block's voxel box per grid.
    boxes: [CellBox; MAX_GROUPS],
    objects: [u64; MAX_GROUPS],
    /// Groups the passes will hold as aggregates, per grid.
    aggregates: [u64; MAX_GROUPS],
    /// And their numbers (first object's index / [`aggregate::SIZE`]).
    aggregate_groups: Vec<u32>,
    /// The first object that lies outside its grid.
    outside: Option<u64>,
}

impl Default for BlockMarks {
    fn default() -> BlockMarks {
        BlockMarks {
            cells: Vec::new(),
            boxes: [CellBox::EMPTY; MAX_GROUPS],
            objects: [0; MAX_GROUPS],
            aggregates: [0; MAX_GROUPS],
            aggregate_groups: Vec::new(),
            outside: None,
        }
    }
}

impl BlockMarks {
    fn place(
        &mut self,
        block: &crate::sdb::Block<'_>,
        specs: &[GridSpec],
        partition: &Partition,
        aggregates: bool,
    ) {
        self.cells.clear();
        self.boxes = [CellBox::EMPTY; MAX_GROUPS];
        self.objects = [0; MAX_GROUPS];
        self.aggregates = [0; MAX_GROUPS];
        self.aggregate_groups.clear();
        self.outside = None;
        // One pass over the records' boxes (their geometry is not
        // decoded): each object's grid and voxel box, which the groups
        // that may be aggregates take as they are (each is placed once).
        let grid = |g: usize| specs.get(g);
        let mut group = [BoxRef::EMPTY; aggregate::SIZE];
        let mut placed: [aggregate::Placed; aggregate::SIZE] = [(0, None); aggregate::SIZE];
        let mut n = 0;
        let mut bounds = Aabb::EMPTY;
        for b in block.boxes() {
            let gi = partition.group(&b.bbox);
            let spec = &specs[gi];
            if !spec.holds(&b.bbox) {
                self.outside = Some(b.index as u64);
                return;
            }
            self.objects[gi] += 1;
            let cells = spec.cell_range(&b.bbox);
            if let Some((lo, hi)) = cells {
                self.boxes[gi].add(lo, hi);
                self.cells.push((gi as u8, lo, hi));
            }
            if !aggregates {
                continue;
            }
            // Only a whole group may be an aggregate.
            if aggregate::starts_group(b.index) {
                n = 0;
                bounds = Aabb::EMPTY;
            }
            group[n] = b;
            placed[n] = (gi, cells);
            bounds.union(&b.bbox);
            n += 1;
            // The groups the passes will hold as aggregates (counted for
            // the statistics; the passes find them again from the block).
            if n == aggregate::SIZE
                && aggregate::may_be(grid(placed[0].0), &bounds)
                && let Some((g, ..)) = aggregate::of_grids(&group, &placed, &bounds, grid)
            {
                self.aggregates[g] += 1;
                self.aggregate_groups.push(b.index / aggregate::SIZE as u32);
            }
        }
    }
}

impl VoxelGrids {
    /// Marks occupancy and face flags with one scan of `db`, counting the
    /// groups of objects that are aggregates if the passes will hold
    /// them (`aggregates`).
    pub fn build(
        db: &Database,
        specs: Vec<GridSpec>,
        partition: Partition,
        aggregates: bool,
        work: BuildThreads<'_>,
        progress: &dyn Progress,
    ) -> Result<(VoxelGrids, DbStats), Error> {
        let mut grids: Vec<VoxelGrid> = specs
            .iter()
            .map(|spec| VoxelGrid {
                flags: vec![0u8; spec.cells()],
                busy: BusyBlocks::default(),
                registered: vec![0; spec.cells().div_ceil(64)],
                spec: spec.clone(),
                objects: 0,
                aggregates: 0,
            })
            .collect();
        let n = grids.len();
        let mut blocks = Vec::with_capacity(db.block_count() as usize * n);
        progress.set_total(db.object_count());
        // Per block of a batch, what its objects mark, worked out on every
        // core; the marks are then made in file order on this thread (a
        // few bytes per object; the rest, decoding and placing the
        // objects, was nine tenths of the time on one core).
        let mut marks: Vec<BlockMarks> = Vec::new();
        let mut aggregate_groups = if aggregates {
            vec![0u64; Self::aggregate_words(db.object_count())]
        } else {
            Vec::new()
        };
        let stats = crate::sdb::scan_blocks::<()>(
            db.scan()?,
            work.read_ahead,
            &|_| false,
            &|_, _| {},
            &mut |batch| {
                if marks.len() < batch.len() {
                    marks.resize_with(batch.len(), BlockMarks::default);
                }
                let marks = &mut marks[..batch.len()];
                let place = |((block, ()), m): (&(crate::sdb::Block<'_>, &()), &mut BlockMarks)| {
                    m.place(block, &specs, &partition, aggregates)
                };
                match work.pool {
                    Some(pool) => {
                        use rayon::prelude::*;
                        pool.install(|| batch.par_iter().zip(marks.par_iter_mut()).for_each(place))
                    }
                    None => batch.iter().zip(marks.iter_mut()).for_each(place),
                }
                for ((block, ()), m) in batch.iter().zip(marks.iter()) {
                    if let Some(id) = m.outside {
                        return Err(crate::grid::outside_its_grid(db, id));
                    }
                    for &(g, lo, hi) in &m.cells {
                        let g = &mut grids[g as usize];
                        mark_box(&g.spec, &mut g.flags, lo, hi);
                    }
                    blocks.extend_from_slice(&m.boxes[..n]);
                    for (g, grid) in grids.iter_mut().enumerate() {
                        grid.objects += m.objects[g];
                        grid.aggregates += m.aggregates[g];
                    }
                    for &k in &m.aggregate_groups {
                        aggregate_groups[k as usize / 64] |= 1 << (k % 64);
                    }
                    progress.inc(block.object_count as u64);
                }
                Ok(())
            },
        )?;
        for g in grids.iter_mut() {
            if g.spec.cells() >= SKIP_FROM_CELLS {
                g.busy = BusyBlocks::of(&g.spec, &g.flags);
            }
        }
        let grids = VoxelGrids {
            grids,
            partition,
            blocks,
            aggregate_groups,
        };
        Ok((grids, stats))
    }

    /// Words of the bitmap of which groups of `objects` objects are
    /// aggregates (a bit per group), for the build and the budget.
    pub fn aggregate_words(objects: u64) -> usize {
        objects.div_ceil(64 * aggregate::SIZE as u64) as usize
    }

    /// Whether the group of objects whose first has index `first` is an
    /// aggregate (see [`crate::grid::aggregate::of_grids`]).
    #[inline]
    pub fn is_aggregate(&self, first: u32) -> bool {
        let k = first as usize / aggregate::SIZE;
        self.aggregate_groups
            .get(k / 64)
            .is_some_and(|w| w >> (k % 64) & 1 != 0)
    }

    /// The voxel boxes of block `index`, one per grid (`None` for a block
    /// the build did not see).
    pub fn block_boxes(&self, index: u64) -> Option<&[CellBox]> {
        let n = self.grids.len();
        let at = usize::try_from(index).ok()?.checked_mul(n)?;
        self.blocks.get(at..at + n)
    }

    pub fn stats(&self) -> Vec<GridStat> {
        self.grids
            .iter()
            .map(|g| GridStat {
                objects: g.objects,
                resolution: g.spec.res,
                lo: g.spec.lo,
                hi: g.spec.hi,
                nested_voxels: 0,
                nested_objects: 0,
                aggregates: g.aggregates,
            })
            .collect()
    }

    pub fn bytes(&self) -> u64 {
        self.grids
            .iter()
            .map(|g| {
                g.flags.len() as u64
                    + BusyBlocks::bytes_for(&g.spec)
                    + 8 * g.registered.len() as u64
            })
            .sum::<u64>()
            + (self.blocks.len() * std::mem::size_of::<CellBox>()) as u64
            + 8 * self.aggregate_groups.len() as u64
    }
}

/// Marks the voxels of one object's box: all occupied, and on the box's
/// boundary the faces that are part of it.
fn mark_box(spec: &GridSpec, flags: &mut [u8], lo: [u32; 3], hi: [u32; 3]) {
    for z in lo[2]..=hi[2] {
        let fz = if z == lo[2] { face_bit(2, false) } else { 0 }
            | if z == hi[2] { face_bit(2, true) } else { 0 };
        for y in lo[1]..=hi[1] {
            let fy = if y == lo[1] { face_bit(1, false) } else { 0 }
                | if y == hi[1] { face_bit(1, true) } else { 0 };
            let row = spec.index([0, y, z]);
            for x in lo[0]..=hi[0] {
                let fx = if x == lo[0] { face_bit(0, false) } else { 0 }
                    | if x == hi[0] { face_bit(0, true) } else { 0 };
                flags[row + x as usize] |= OCCUPIED | fx | fy | fz;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Aabb;

    /// The bit the build sets for a group is what the groups' own rule
    /// ([`aggregate::of_grids`]) says of it, group by group: crowded
    /// patches, a group spread over the scene, and groups cut by a
    /// block's end (which a pass tests one by one).
    #[test]
    fn the_build_marks_the_groups_the_rule_makes_aggregates() {
        use std::fmt::Write;
        let mut nff = String::from(
            "v\nfrom 0 0 -5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 0.01\nresolution 8 8\n\
             b 0 0 0\nl 0 5 -5\nf 1 1 1 1 0 0 0 1\n",
        );
        // Groups of tiny triangles, each crowded into a voxel or two (ten
        // groups a patch), and every eleventh group spread across the
        // scene.
        let tri = |s: &mut String, c: [f64; 3], r: f64| {
            writeln!(
                s,
                "p 3\n{} {} {}\n{} {} {}\n{} {} {}",
                c[0],
                c[1],
                c[2],
                c[0] + r,
                c[1],
                c[2],
                c[0],
                c[1] + r,
                c[2]
            )
            .unwrap();
        };
        for g in 0..44 {
            for i in 0..64 {
                let c = if g % 11 == 5 {
                    [(i % 8) as f64 * 0.5 - 2.0, (i / 8) as f64 * 0.5 - 2.0, 1.0]
                } else {
                    let p = (g / 10) as f64;
                    [p - 1.0, (i % 7) as f64 * 0.01, (i % 5) as f64 * 0.01]
                };
                tri(&mut nff, c, 0.01);
            }
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("groups.sdb");
        // Records of their own, not runs: more blocks, whose ends cut
        // groups.
        let mut w = crate::sdb::DbWriter::create(&path, crate::sdb::Compression::None)
            .unwrap()
            .without_runs();
        crate::nff::read_nff_from(
            nff.as_bytes(),
            std::path::Path::new("groups.nff"),
            &mut w,
            &crate::progress::NoProgress,
        )
        .unwrap();
        w.finish().unwrap();
        let db = crate::sdb::Database::open(&path).unwrap();
        assert!(db.block_count() > 1);
        let spec = GridSpec::new(&db.bbox(), [20, 20, 20]);
        let threads = BuildThreads {
            pool: None,
            read_ahead: 0,
        };
        let (grids, _) = VoxelGrids::build(
            &db,
            vec![spec.clone()],
            Partition::one(),
            true,
            threads,
            &crate::progress::NoProgress,
        )
        .unwrap();
        let (mut held, mut not, mut cut) = (0, 0, 0);
        let mut scan = db.scan().unwrap();
        let mut placed = [(0, None); aggregate::SIZE];
        while let Some(block) = scan.next_block().unwrap() {
            aggregate::each_group(&block, |group, bounds| {
                let first = group[0].index;
                if group.len() < aggregate::SIZE {
                    cut += 1;
                    // A cut group's bit is its whole group's: never set.
                    assert!(!grids.is_aggregate(first), "cut group at {first}");
                    return;
                }
                aggregate::place(group, &grids.partition, |_| Some(&spec), &mut placed);
                let rule = aggregate::of_grids(group, &placed, bounds, |_| Some(&spec)).is_some();
                assert_eq!(grids.is_aggregate(first), rule, "group at {first}");
                if rule {
                    held += 1;
                } else {
                    not += 1;
                }
            });
        }
        assert_eq!(grids.grids[0].aggregates, held as u64);
        assert!(held >= 20 && not >= 1 && cut >= 2, "{held} {not} {cut}");
    }

    #[test]
    fn boxes_mark_occupancy_and_their_boundary_faces() {
        let spec = GridSpec::new(
            &Aabb {
                min: [0.0; 3],
                max: [4.0; 3],
            },
            [4, 4, 4],
        );
        let mut flags = vec![0u8; spec.cells()];
        mark_box(&spec, &mut flags, [1, 1, 1], [2, 1, 1]);
        let f = |x, y, z| flags[spec.index([x, y, z])];
        assert_eq!(f(0, 1, 1), 0);
        let left = f(1, 1, 1);
        let right = f(2, 1, 1);
        assert!(left & OCCUPIED != 0 && right & OCCUPIED != 0);
        assert!(left & face_bit(0, false) != 0 && left & face_bit(0, true) == 0);
        assert!(right & face_bit(0, true) != 0 && right & face_bit(0, false) == 0);
        // One voxel thick in y and z: both faces are boundary.
        for v in [left, right] {
            for axis in [1, 2] {
                assert!(v & face_bit(axis, false) != 0 && v & face_bit(axis, true) != 0);
            }
        }
        // Stepping +x into (2,1,1) crosses its low-x face, which is inside
        // the box: not a boundary.
        assert_eq!(right & entry_face(0, true), 0);
        assert_ne!(left & entry_face(0, true), 0);
    }
}

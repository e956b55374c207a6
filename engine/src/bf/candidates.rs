//! Which objects of a block a pass tests: those whose voxel box meets a
//! voxel holding registered rays, one by one or as aggregates (crowded
//! groups walked through a hierarchy of their own). Worked out once per
//! block for every shard (see [`super::intersect`]).

use super::MAX_GRIDS;
use super::voxels::{VoxelGrid, VoxelGrids};
use crate::grid::aggregate;
use crate::grid::nested::Hierarchies;
use crate::math::Aabb;
use crate::sdb::{Block, BoxRef};

/// Voxel box holding every registration of a pass, per grid.
#[derive(Clone, Copy, Debug)]
pub(super) struct Region {
    pub(super) lo: [u32; 3],
    pub(super) hi: [u32; 3],
}

pub(super) const NO_REGION: Region = Region {
    lo: [u32::MAX; 3],
    hi: [0; 3],
};

impl Region {
    pub(super) fn add(&mut self, c: [u32; 3]) {
        for i in 0..3 {
            self.lo[i] = self.lo[i].min(c[i]);
            self.hi[i] = self.hi[i].max(c[i]);
        }
    }
    pub(super) fn union(&mut self, o: &Region) {
        for i in 0..3 {
            self.lo[i] = self.lo[i].min(o.lo[i]);
            self.hi[i] = self.hi[i].max(o.hi[i]);
        }
    }
    #[inline]
    pub(super) fn overlaps(&self, lo: [u32; 3], hi: [u32; 3]) -> bool {
        (0..3).all(|i| lo[i] <= self.hi[i] && hi[i] >= self.lo[i])
    }
}

/// An object of the block being scanned that some registered voxel may
/// hold: where its record is, its group and its voxel box. Worked out once
/// per block for every shard.
#[derive(Clone, Copy, Debug)]
pub(super) struct Candidate {
    pub(super) at: u32,
    pub(super) index: u32,
    /// The object's input id: its place in the tie order.
    pub(super) rank: u32,
    pub(super) group: u8,
    pub(super) lo: [u16; 3],
    pub(super) hi: [u16; 3],
}

impl Candidate {
    /// Object `b` of grid `g`, over voxels `lo..=hi` there.
    fn new(b: &BoxRef, g: usize, lo: [u32; 3], hi: [u32; 3]) -> Candidate {
        Candidate {
            at: b.at,
            index: b.index,
            rank: b.rank,
            group: g as u8,
            lo: lo.map(|c| c as u16),
            hi: hi.map(|c| c as u16),
        }
    }
}

/// An object of an aggregate: where its record is.
#[derive(Clone, Copy, Debug)]
pub(super) struct Member {
    pub(super) at: u32,
    pub(super) index: u32,
    /// Its input id: its place in the tie order.
    pub(super) rank: u32,
}

/// What a pass does with one block, worked out once for every shard (the
/// blocks of a batch in parallel, before the shards test them): the
/// objects some registered voxel may hold, and the aggregates among them
/// ([`crate::grid::aggregate`]).
///
/// A group of the block's objects that crowds its voxels is stored in the
/// voxels of its box like one object, and a ray met there walks a
/// hierarchy of boxes over its objects, built when the block is read,
/// instead of testing each. Groups are the objects whose index divided by
/// [`aggregate::SIZE`] is the same, as in the depth-first tracer (which
/// also takes a group with instances, or one a block boundary cuts: here
/// those are tested one by one). Every group is
/// first judged by its box: one that meets no registered voxel of any
/// grid is passed over without looking at its objects one by one (their
/// grid, their voxels). Which groups are aggregates depends on the
/// database and the grids alone, not on the rays of the pass, so every
/// count is still the same whatever the threads, slots or memory. The
/// paper's passes (`--full-scans`) test objects one by one.
#[derive(Default)]
pub(super) struct Found {
    /// Objects tested one by one.
    pub(super) singles: Vec<Candidate>,
    /// The aggregates' objects, each aggregate's together, and their boxes
    /// (what their hierarchies are built over).
    pub(super) members: Vec<Member>,
    pub(super) member_boxes: Vec<Aabb>,
    pub(super) aggregates: Vec<Aggregate>,
    pub(super) trees: Hierarchies,
    /// Room to build in.
    pub(super) ids: Vec<u32>,
    pub(super) order: Vec<(u32, u32)>,
}

impl Found {
    pub(super) fn clear(&mut self) {
        self.singles.clear();
        self.members.clear();
        self.member_boxes.clear();
        self.aggregates.clear();
        self.trees.clear();
    }

    pub(super) fn is_empty(&self) -> bool {
        self.singles.is_empty() && self.aggregates.is_empty()
    }
}

/// A crowded group of a block's objects, traced through its hierarchy.
#[derive(Clone, Copy, Debug)]
pub(super) struct Aggregate {
    /// Its objects: `members[first..first + len]`.
    pub(super) first: u32,
    pub(super) len: u32,
    /// The entry of its hierarchy in `Found::trees` (over member indices).
    pub(super) tree: u32,
    /// The database index of its first object, which names it in a ray's
    /// mailbox.
    pub(super) index: u32,
    pub(super) group: u8,
    pub(super) lo: [u16; 3],
    pub(super) hi: [u16; 3],
}

/// The objects of `block` whose voxel box meets `region`, the box of the
/// voxels rays are registered in this pass, one by one or in aggregates
/// (when `aggregates`).
pub(super) fn candidates(
    block: &Block<'_>,
    grids: &VoxelGrids,
    region: &[Region; MAX_GRIDS],
    aggregates: bool,
    out: &mut Found,
) {
    out.clear();
    let spec = |g: usize| grids.grids.get(g).map(|v| &v.spec);
    // Each object's voxels in its own grid lie within its group's voxels
    // in that grid: passing over a group whose box holds no registered
    // voxel in any grid drops no candidate, and no aggregate a ray would
    // walk.
    let near = |bounds: &Aabb| {
        grids.grids.iter().zip(region).any(|(grid, r)| {
            grid.spec
                .cell_range(bounds)
                .is_some_and(|(lo, hi)| r.overlaps(lo, hi) && may_be_registered(grid, lo, hi))
        })
    };
    aggregate::each_group(block, |group, bounds| {
        if !near(bounds) {
            return;
        }
        if aggregates && group.len() == aggregate::SIZE && grids.is_aggregate(group[0].index) {
            // Judged by the build ([`aggregate::of_grids`]): of its first
            // object's grid, over its box's voxels there. An aggregate no
            // registered ray is stored in gets no hierarchy.
            let g = grids.partition.group(&group[0].bbox);
            if let Some((lo, hi)) = spec(g).and_then(|s| s.cell_range(bounds))
                && region[g].overlaps(lo, hi)
                && may_be_registered(&grids.grids[g], lo, hi)
            {
                add_aggregate(group, g, lo, hi, out);
            }
            return;
        }
        // One by one, each half of the group judged by its box first.
        for half in group.chunks(aggregate::SIZE / 2) {
            let mut bounds = Aabb::EMPTY;
            for b in half {
                bounds.union(&b.bbox);
            }
            if near(&bounds) {
                candidates_in(half, grids, region, &mut out.singles);
            }
        }
    });
}

/// [`candidates`] among `boxes`, one by one.
fn candidates_in(
    boxes: &[BoxRef],
    grids: &VoxelGrids,
    region: &[Region; MAX_GRIDS],
    out: &mut Vec<Candidate>,
) {
    let mut placed = [(0, None); aggregate::SIZE];
    aggregate::place(
        boxes,
        &grids.partition,
        |g| grids.grids.get(g).map(|v| &v.spec),
        &mut placed,
    );
    push_placed(boxes, &placed[..boxes.len()], grids, region, out);
}

/// The objects `boxes`, placed in the grids as `placed` says, whose voxel
/// box meets `region`, as candidates.
fn push_placed(
    boxes: &[BoxRef],
    placed: &[aggregate::Placed],
    grids: &VoxelGrids,
    region: &[Region; MAX_GRIDS],
    out: &mut Vec<Candidate>,
) {
    for (b, &(g, cells)) in boxes.iter().zip(placed) {
        if let Some((lo, hi)) = cells
            && region[g].overlaps(lo, hi)
            && may_be_registered(&grids.grids[g], lo, hi)
        {
            out.push(Candidate::new(b, g, lo, hi));
        }
    }
}

/// Voxel boxes larger than this are candidates without looking at their
/// voxels (the shards look at each anyway).
const LOOK_AT_MOST: u64 = 64;

/// Whether some voxel of box `lo..=hi` of `grid` holds a registered ray
/// (or the box is too large to look). Looked at once for every shard, by
/// the reader: an object with no registered voxel was a candidate for
/// each shard, which each found out voxel by voxel, a cache miss each,
/// in every scan (most of mount11's 8.4 million triangles, 18 times).
#[inline]
fn may_be_registered(grid: &VoxelGrid, lo: [u32; 3], hi: [u32; 3]) -> bool {
    let n = (0..3).map(|i| (hi[i] - lo[i] + 1) as u64).product::<u64>();
    if n > LOOK_AT_MOST {
        return true;
    }
    for z in lo[2]..=hi[2] {
        for y in lo[1]..=hi[1] {
            let row = grid.spec.index([0, y, z]);
            if (row + lo[0] as usize..=row + hi[0] as usize).any(|v| grid.is_registered(v)) {
                return true;
            }
        }
    }
    false
}

/// Adds the group `boxes`, an aggregate of grid `g` over voxels
/// `lo..=hi`, to `out`, with its hierarchy. Its objects' own voxels are
/// not worked out: the scan needs them only for a ray in its second pass
/// or later (the last-voxel rule), and finds them from their boxes then.
fn add_aggregate(boxes: &[BoxRef], g: usize, lo: [u32; 3], hi: [u32; 3], out: &mut Found) {
    let first = out.members.len();
    for b in boxes {
        out.members.push(Member {
            at: b.at,
            index: b.index,
            rank: b.rank,
        });
        out.member_boxes.push(b.bbox);
    }
    out.ids.clear();
    out.ids.extend(first as u32..out.members.len() as u32);
    let tree = out
        .trees
        .build_aggregate(&out.ids, &out.member_boxes[..], &mut out.order);
    out.aggregates.push(Aggregate {
        first: first as u32,
        len: (out.members.len() - first) as u32,
        tree,
        index: boxes[0].index,
        group: g as u8,
        lo: lo.map(|c| c as u16),
        hi: hi.map(|c| c as u16),
    });
}

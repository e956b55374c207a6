//! Aggregates: the paper's Section 2.4 proposal, "primitives located
//! roughly at the same position are associated with an aggregate object,
//! the acceleration structure which is handled as one object".
//!
//! An aggregate is a group of [`SIZE`] consecutive objects of one grid
//! (in a database in spatial order, a patch of a surface) that crowd the
//! voxels of their box: on average at least [`CROWD`] objects overlap each
//! of those voxels. A grid holds it by its box, like one object, and a ray
//! there walks a hierarchy of boxes over its objects instead of testing
//! them one by one. Groups are fixed by the objects' places (a group is the
//! objects whose index divided by [`SIZE`] is the same), so which groups are
//! aggregates depends on the database and the grid alone.
//!
//! A uniform grid sized for a whole scene puts a dense model that fills
//! a small part of it into a handful of voxels of thousands of objects
//! each: aggregates make that model a region of a few hundred objects of
//! the grid, each with a small structure of its own.

use super::{GridSpec, Partition};
use crate::scene::Aabb;
use crate::sdb::{Block, BoxRef};
use crate::shapes::ShapeKind;

/// Objects in a group.
pub const SIZE: usize = crate::sdb::AGGREGATE_SIZE;

/// Object-voxel pairs per voxel of a group's box at which the group is an
/// aggregate. A ray crossing a box of n voxels a side visits about n + 1
/// of its voxels; at two objects a voxel, a ray through a box of 4 x 4 x 4
/// would test about ten of its objects one by one, where a walk of the
/// hierarchy costs a few tests and leads it to the few it may hit.
/// Measured (`--memory 256MiB`, 9a6dc84's tracer): at 16 (the first
/// choice) with boxes of at most 8 voxels, mount11's rays made 92 M tests;
/// at 4, 2 and 1 with boxes of 64, 29.8 M, 24.7 M and 24.3 M, the
/// render taking 0.80, 0.74 and 0.73 of its time.
pub const CROWD: usize = 2;

/// Most voxels an aggregate's box may span: a group spread wider is taken
/// as objects (whose boxes a pass judges in halves first, so that a wide
/// group near few rays costs little). 64 is a box of 4 x 4 x 4: a patch of
/// 64 of mount11's triangles spans up to 64 of its grid's voxels, a
/// fractal mountain's slope is steep. Wider boxes gave rings80, whose
/// groups are strings of spheres and cylinders, a third more tests.
pub const MAX_VOXELS: usize = 64;

/// Voxels of the box from `lo` to `hi`.
#[inline]
pub fn volume(lo: [u32; 3], hi: [u32; 3]) -> usize {
    (0..3).map(|i| (hi[i] - lo[i] + 1) as usize).product()
}

/// The voxel box of a group of `n` objects of box `bounds` in grid `spec`
/// if the group is an aggregate there: a whole group whose objects
/// overlap `pairs` voxels in all (each counting every voxel of its own
/// box), crowding the voxels of its box, which are at most
/// [`MAX_VOXELS`].
pub fn crowded(
    spec: &GridSpec,
    bounds: &Aabb,
    n: usize,
    pairs: usize,
) -> Option<([u32; 3], [u32; 3])> {
    if n != SIZE {
        return None;
    }
    let (lo, hi) = spec.cell_range(bounds)?;
    let v = volume(lo, hi);
    (v <= MAX_VOXELS && pairs >= CROWD * v).then_some((lo, hi))
}

/// Whether a group of box `bounds` whose first object is in grid `spec`
/// may be an aggregate: its box spans at most [`MAX_VOXELS`] voxels there
/// (a cheap test before its objects are placed one by one).
pub fn may_be(spec: Option<&GridSpec>, bounds: &Aabb) -> bool {
    spec.and_then(|s| s.cell_range(bounds))
        .is_some_and(|(lo, hi)| volume(lo, hi) <= MAX_VOXELS)
}

/// The voxels of grid `spec` the objects of boxes `boxes` overlap, each
/// counting every voxel of its own box.
pub fn pairs<'a>(spec: &GridSpec, boxes: impl Iterator<Item = &'a Aabb>) -> usize {
    boxes
        .filter_map(|b| spec.cell_range(b))
        .map(|(lo, hi)| volume(lo, hi))
        .sum()
}

/// An object of a group in the grids: the grid it belongs to, and its
/// voxel box there (`None` outside it).
pub type Placed = (usize, Option<([u32; 3], [u32; 3])>);

/// Places each object of `boxes` in the grids (`spec` gives each by
/// number) that `partition` shares objects among.
pub fn place<'a>(
    boxes: &[BoxRef],
    partition: &Partition,
    spec: impl Fn(usize) -> Option<&'a GridSpec>,
    out: &mut [Placed; SIZE],
) {
    for (b, p) in boxes.iter().zip(out.iter_mut()) {
        let g = partition.group(&b.bbox);
        *p = (g, spec(g).and_then(|s| s.cell_range(&b.bbox)));
    }
}

/// The group of a block's objects `boxes` (of box `bounds`, placed in the
/// grids as `placed` says; `spec` gives each grid by number) as an
/// aggregate: its grid and its voxel box there, or `None` if it is not
/// one (not a whole group, not all of one grid, an instance among them,
/// or not crowding its voxels).
pub fn of_grids<'a>(
    boxes: &[BoxRef],
    placed: &[Placed],
    bounds: &Aabb,
    spec: impl Fn(usize) -> Option<&'a GridSpec>,
) -> Option<(usize, [u32; 3], [u32; 3])> {
    let g = placed.first()?.0;
    if boxes.iter().any(|b| b.kind == ShapeKind::Instance) || placed.iter().any(|p| p.0 != g) {
        return None;
    }
    let pairs = placed
        .iter()
        .filter_map(|p| p.1)
        .map(|(lo, hi)| volume(lo, hi))
        .sum();
    let (lo, hi) = crowded(spec(g)?, bounds, boxes.len(), pairs)?;
    Some((g, lo, hi))
}

/// Whether the object of index `index` begins a group: a group is the
/// objects whose index divided by [`SIZE`] is the same (so that the
/// groups of a database are the same however its blocks fall).
#[inline(always)]
pub fn starts_group(index: u32) -> bool {
    (index as usize).is_multiple_of(SIZE)
}

/// Calls `f` with each group of the objects of `block`, in order, and its
/// box (see [`starts_group`]: the first and last group of a block not
/// aligned to [`SIZE`] are short).
pub fn each_group(block: &Block<'_>, f: impl FnMut(&[BoxRef], &Aabb)) {
    groups_of(block.boxes(), f);
}

/// [`each_group`] of the objects `boxes`, consecutive in index order.
fn groups_of(boxes: impl Iterator<Item = BoxRef>, mut f: impl FnMut(&[BoxRef], &Aabb)) {
    let mut group = [BoxRef::EMPTY; SIZE];
    let mut n = 0;
    let mut bounds = Aabb::EMPTY;
    for b in boxes {
        if starts_group(b.index) && n > 0 {
            f(&group[..n], &bounds);
            n = 0;
            bounds = Aabb::EMPTY;
        }
        bounds.union(&b.bbox);
        group[n] = b;
        n += 1;
    }
    if n > 0 {
        f(&group[..n], &bounds);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube(c: [f32; 3], r: f32) -> Aabb {
        Aabb {
            min: c.map(|x| x - r),
            max: c.map(|x| x + r),
        }
    }

    fn union(boxes: &[Aabb]) -> Aabb {
        let mut u = Aabb::EMPTY;
        for b in boxes {
            u.union(b);
        }
        u
    }

    /// A run of objects that does not start at a multiple of [`SIZE`]
    /// splits where the index does: a short first group, whole ones, and
    /// a short last one, each with the union of its boxes.
    #[test]
    fn groups_follow_the_index_not_the_block() {
        let objects = |first: u32, n: u32| {
            (first..first + n).map(|i| BoxRef {
                index: i,
                bbox: cube([i as f32, 0.0, 0.0], 0.5),
                ..BoxRef::EMPTY
            })
        };
        let s = SIZE as u32;
        let mut seen = vec![];
        groups_of(objects(s + 7, 3 * s), |g, bounds| {
            assert!(g.windows(2).all(|w| w[1].index == w[0].index + 1));
            assert!(starts_group(g[0].index) || seen.is_empty());
            let want = union(&g.iter().map(|b| b.bbox).collect::<Vec<_>>());
            assert_eq!((bounds.min, bounds.max), (want.min, want.max));
            seen.push((g[0].index, g.len()));
        });
        let sz = SIZE;
        assert_eq!(
            seen,
            vec![(s + 7, sz - 7), (2 * s, sz), (3 * s, sz), (4 * s, 7)]
        );
        seen.clear();
        groups_of(objects(0, 5), |g, _| seen.push((g[0].index, g.len())));
        assert_eq!(seen, vec![(0, 5)]);
        groups_of(objects(0, 0), |_, _| panic!("no objects, no group"));
    }

    /// Sixty-four small objects in one voxel crowd it; the same objects
    /// spread one to a voxel do not; a group short of [`SIZE`] is none.
    #[test]
    fn only_whole_groups_crowding_their_voxels_are_aggregates() {
        let spec = GridSpec::new(&cube([0.0; 3], 8.0), [16, 16, 16]);
        let close: Vec<Aabb> = (0..SIZE)
            .map(|i| cube([0.1 + 0.01 * i as f32, 0.5, 0.5], 0.05))
            .collect();
        let (lo, hi) =
            crowded(&spec, &union(&close), SIZE, pairs(&spec, close.iter())).expect("crowded");
        assert!(volume(lo, hi) <= 2, "{lo:?} {hi:?}");
        let apart: Vec<Aabb> = (0..SIZE)
            .map(|i| cube([(i % 16) as f32 - 7.5, (i / 16) as f32 - 7.5, 0.5], 0.05))
            .collect();
        let apart_pairs = pairs(&spec, apart.iter());
        assert_eq!(crowded(&spec, &union(&apart), SIZE, apart_pairs), None);
        let few = &close[..SIZE - 1];
        assert_eq!(
            crowded(&spec, &union(few), few.len(), pairs(&spec, few.iter())),
            None
        );
    }
}

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

use super::GridSpec;
use crate::scene::Aabb;

/// Objects in a group.
pub const SIZE: usize = 64;

/// Object-voxel pairs per voxel of a group's box at which the group is an
/// aggregate: a ray stored in one of those voxels would test that many
/// objects one by one, where the hierarchy leads it to the few it may
/// hit (a walk costs about as much as a dozen tests).
pub const CROWD: usize = 16;

/// Voxels of the box from `lo` to `hi`.
#[inline]
pub fn volume(lo: [u32; 3], hi: [u32; 3]) -> usize {
    (0..3).map(|i| (hi[i] - lo[i] + 1) as usize).product()
}

/// The voxel box of a group of objects (of boxes `boxes`, whose union is
/// `bounds`) in grid `spec` if the group is an aggregate there: a whole
/// group, crowding its voxels.
pub fn crowded<'a>(
    spec: &GridSpec,
    bounds: &Aabb,
    boxes: impl ExactSizeIterator<Item = &'a Aabb>,
) -> Option<([u32; 3], [u32; 3])> {
    if boxes.len() != SIZE {
        return None;
    }
    let (lo, hi) = spec.cell_range(bounds)?;
    let pairs: usize = boxes
        .filter_map(|b| spec.cell_range(b))
        .map(|(lo, hi)| volume(lo, hi))
        .sum();
    (pairs >= CROWD * volume(lo, hi)).then_some((lo, hi))
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

    /// Sixty-four small objects in one voxel crowd it; the same objects
    /// spread one to a voxel do not; a group short of [`SIZE`] is none.
    #[test]
    fn only_whole_groups_crowding_their_voxels_are_aggregates() {
        let spec = GridSpec::new(&cube([0.0; 3], 8.0), [16, 16, 16]);
        let close: Vec<Aabb> = (0..SIZE)
            .map(|i| cube([0.1 + 0.01 * i as f32, 0.5, 0.5], 0.05))
            .collect();
        let (lo, hi) = crowded(&spec, &union(&close), close.iter()).expect("crowded");
        assert!(volume(lo, hi) <= 2, "{lo:?} {hi:?}");
        let apart: Vec<Aabb> = (0..SIZE)
            .map(|i| cube([(i % 16) as f32 - 7.5, (i / 16) as f32 - 7.5, 0.5], 0.05))
            .collect();
        assert_eq!(crowded(&spec, &union(&apart), apart.iter()), None);
        let few = &close[..SIZE - 1];
        assert_eq!(crowded(&spec, &union(few), few.iter()), None);
    }
}

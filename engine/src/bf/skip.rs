//! Which blocks a pass may leave unread. The grids' build (the first,
//! complete scan) records each block's voxel box in every grid: the union
//! of its objects' voxel ranges. A pass marks the coarse cells (4 x 4 x 4
//! voxels) that hold registered rays; a block whose boxes meet no marked
//! cell has no object that a registered ray could be tested against, so
//! the scan seeks past it: no read, no decompression, no decoding. The
//! database is still read front to back, and the tests made, their order
//! and every result are exactly those of a full scan.

use super::voxels::VoxelGrids;
use crate::grid::GridSpec;

/// A box of voxels, inclusive; empty when `lo` exceeds `hi`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CellBox {
    pub lo: [u32; 3],
    pub hi: [u32; 3],
}

impl CellBox {
    pub const EMPTY: CellBox = CellBox {
        lo: [u32::MAX; 3],
        hi: [0; 3],
    };

    pub fn is_empty(&self) -> bool {
        (0..3).any(|i| self.lo[i] > self.hi[i])
    }

    pub fn add(&mut self, lo: [u32; 3], hi: [u32; 3]) {
        for i in 0..3 {
            self.lo[i] = self.lo[i].min(lo[i]);
            self.hi[i] = self.hi[i].max(hi[i]);
        }
    }
}

/// log2 of a coarse cell's edge, in voxels: a coarse cell costs four
/// bytes per pass, a sixteenth of a byte per voxel.
const COARSE_SHIFT: u32 = 2;

/// One grid's coarse cells holding registered rays, as a summed-volume
/// table: entry (x + 1, y + 1, z + 1) counts the marked cells in
/// [0, x] x [0, y] x [0, z], so any box is answered with eight lookups,
/// however many cells it spans.
#[derive(Default)]
struct Coarse {
    /// Coarse cells per axis.
    dims: [u32; 3],
    sums: Vec<u32>,
}

impl Coarse {
    /// Index of entry `c` of the table, whose sides are `dims + 1`.
    #[inline]
    fn at(&self, c: [u32; 3]) -> usize {
        let (w, h) = (self.dims[0] as usize + 1, self.dims[1] as usize + 1);
        c[0] as usize + w * (c[1] as usize + h * c[2] as usize)
    }

    /// Turns the marks into running sums along each axis in turn.
    fn sum(&mut self) {
        let d = self.dims.map(|x| x as usize + 1);
        let stride = [1, d[0], d[0] * d[1]];
        for (axis, &step) in stride.iter().enumerate() {
            for i in 0..self.sums.len() {
                let along = (i / step) % d[axis];
                if along > 0 {
                    self.sums[i] += self.sums[i - step];
                }
            }
        }
    }

    /// Marked cells in the inclusive box `lo..=hi` of coarse cells.
    fn count(&self, lo: [u32; 3], hi: [u32; 3]) -> u32 {
        let mut n = 0i64;
        for corner in 0..8 {
            let pick = |axis: usize| {
                if corner >> axis & 1 == 1 {
                    hi[axis] + 1
                } else {
                    lo[axis]
                }
            };
            let c = [pick(0), pick(1), pick(2)];
            let sign = if (corner as u32).count_ones() % 2 == 1 {
                1
            } else {
                -1
            };
            // The high corner has all three bits: an odd count, positive.
            n += sign * self.sums[self.at(c)] as i64;
        }
        n as u32
    }
}

/// The coarse cells one pass has rays in, per grid.
#[derive(Default)]
pub struct Touched {
    grids: Vec<Coarse>,
}

impl Touched {
    /// Forgets the last pass's cells, sized for `grids`.
    pub fn clear(&mut self, grids: &VoxelGrids) {
        self.grids.resize_with(grids.grids.len(), Coarse::default);
        for (c, g) in self.grids.iter_mut().zip(&grids.grids) {
            c.dims = g.spec.res.map(|r| r.div_ceil(1 << COARSE_SHIFT));
            let len = c.dims.iter().map(|&d| d as usize + 1).product();
            c.sums.clear();
            c.sums.resize(len, 0);
        }
    }

    /// Marks the coarse cell of voxel `index` of grid `g`.
    #[inline]
    pub fn mark(&mut self, g: usize, spec: &GridSpec, index: u32) {
        let (r0, r1) = (spec.res[0], spec.res[1]);
        let v = [index % r0, (index / r0) % r1, index / (r0 * r1)];
        let c = &mut self.grids[g];
        let i = c.at(v.map(|x| (x >> COARSE_SHIFT) + 1));
        c.sums[i] = 1;
    }

    /// Ends the marking: call once, before the first [`Touched::meets`].
    pub fn finish(&mut self) {
        for c in &mut self.grids {
            c.sum();
        }
    }

    /// Whether any of the boxes `boxes` (one per grid) meets a marked
    /// cell.
    pub fn meets(&self, boxes: &[CellBox]) -> bool {
        boxes.iter().zip(&self.grids).any(|(b, c)| {
            !b.is_empty()
                && c.count(
                    b.lo.map(|x| x >> COARSE_SHIFT),
                    b.hi.map(|x| x >> COARSE_SHIFT),
                ) > 0
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Aabb;

    #[test]
    fn a_box_meets_only_the_cells_of_registered_voxels() {
        let spec = GridSpec::new(
            &Aabb {
                min: [0.0; 3],
                max: [16.0; 3],
            },
            [16, 16, 16],
        );
        let grids = VoxelGrids {
            grids: vec![super::super::voxels::VoxelGrid {
                flags: vec![0; spec.cells()],
                busy: Default::default(),
                registered: vec![0; spec.cells().div_ceil(64)],
                spec: spec.clone(),
                objects: 0,
                aggregates: 0,
            }],
            partition: crate::grid::Partition::one(),
            blocks: Vec::new(),
            aggregate_groups: Vec::new(),
        };
        let mut t = Touched::default();
        t.clear(&grids);
        t.mark(0, &spec, spec.index([9, 2, 13]) as u32);
        t.finish();
        let b = |lo: [u32; 3], hi: [u32; 3]| [CellBox { lo, hi }];
        // The same coarse cell (8..=11, 0..=3, 12..=15), other voxels.
        assert!(t.meets(&b([8, 0, 12], [8, 0, 12])));
        assert!(t.meets(&b([0, 0, 0], [15, 15, 15])));
        // Next to it.
        assert!(!t.meets(&b([12, 0, 12], [15, 3, 15])));
        assert!(!t.meets(&b([0, 0, 0], [7, 15, 15])));
        assert!(!t.meets(&[CellBox::EMPTY]));
        // Cleared for the next pass.
        t.clear(&grids);
        t.finish();
        assert!(!t.meets(&b([0, 0, 0], [15, 15, 15])));
    }

    #[test]
    fn box_counts_equal_a_brute_force_count() {
        let mut c = Coarse {
            dims: [5, 3, 4],
            sums: vec![0; 6 * 4 * 5],
        };
        let mut marked = Vec::new();
        let mut x = 12345u32;
        for _ in 0..9 {
            x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
            let m = [(x >> 8) % 5, (x >> 12) % 3, (x >> 16) % 4];
            let i = c.at(m.map(|v| v + 1));
            c.sums[i] = 1;
            marked.push(m);
        }
        marked.sort();
        marked.dedup();
        c.sum();
        for lo0 in 0..5 {
            for hi0 in lo0..5 {
                for (lo1, hi1) in [(0, 0), (0, 2), (1, 2), (2, 2)] {
                    for (lo2, hi2) in [(0, 3), (1, 1), (2, 3), (3, 3)] {
                        let (lo, hi) = ([lo0, lo1, lo2], [hi0, hi1, hi2]);
                        let want = marked
                            .iter()
                            .filter(|m| (0..3).all(|a| lo[a] <= m[a] && m[a] <= hi[a]))
                            .count() as u32;
                        assert_eq!(c.count(lo, hi), want, "{lo:?} {hi:?}");
                    }
                }
            }
        }
    }
}

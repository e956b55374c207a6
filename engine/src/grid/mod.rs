//! Uniform spatial subdivision: the grid geometry, conservative voxel
//! ranges of bounding boxes, the 3D-DDA walk of a ray, the choice of
//! resolution, and the split of a scene into groups (one grid each) when a
//! few huge objects would ruin one grid (the paper's Section 2.4).
//!
//! Both tracers use this module, so they agree on which voxels a ray
//! crosses and which voxels an object occupies.

pub mod aggregate;
mod dda;
pub(crate) mod nested;
mod partition;

pub use dda::Dda;
pub use partition::{GridStat, GroupPlan, MAX_GROUPS, Partition, choose_resolution, plan_groups};

use crate::math::Vec3;
use crate::scene::Aabb;
use serde::Serialize;

/// Voxels per object of the automatic grid resolution (measured with
/// callgrind over the seven SPD scenes; see CHANGELOG.md, 2026-11-24).
pub const DEFAULT_DENSITY: f64 = 4.0;

/// Most voxels any grid may have, in either tracer: voxel indices are
/// `u32` throughout, and the breadth-first tracer keeps a flag byte per
/// voxel and the depth-first one a four-byte list start. The automatic
/// resolution stays below it; a fixed `--grid-res` above it is refused.
pub const MAX_CELLS: u64 = 1 << 27;

/// Margin, in voxels, added around a box before it is voxelized, so that an
/// object touching a voxel face (within rounding) is listed on both sides.
const VOXEL_MARGIN: f64 = 1e-6;

/// A uniform grid over a box.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GridSpec {
    pub lo: [f64; 3],
    pub hi: [f64; 3],
    pub res: [u32; 3],
    #[serde(skip)]
    cell: [f64; 3],
    #[serde(skip)]
    inv_cell: [f64; 3],
}

impl GridSpec {
    /// A grid of `res` voxels over `bounds`. An axis of zero extent gets a
    /// small thickness so every voxel has volume.
    pub fn new(bounds: &Aabb, res: [u32; 3]) -> GridSpec {
        let mut lo = [0.0; 3];
        let mut hi = [1.0; 3];
        if !bounds.is_empty() {
            let e = bounds.extent();
            let big = e[0].max(e[1]).max(e[2]);
            let pad = if big > 0.0 {
                big * 1e-6
            } else {
                1e-6 * bounds.max_abs_coord().max(1.0)
            };
            for i in 0..3 {
                lo[i] = bounds.min[i] as f64;
                hi[i] = bounds.max[i] as f64;
                if hi[i] - lo[i] < pad {
                    lo[i] -= pad;
                    hi[i] += pad;
                }
            }
        }
        let res = res.map(|r| r.max(1));
        let mut cell = [0.0; 3];
        let mut inv_cell = [0.0; 3];
        for i in 0..3 {
            cell[i] = (hi[i] - lo[i]) / res[i] as f64;
            inv_cell[i] = res[i] as f64 / (hi[i] - lo[i]);
        }
        GridSpec {
            lo,
            hi,
            res,
            cell,
            inv_cell,
        }
    }

    pub fn cells(&self) -> usize {
        self.res.iter().map(|&r| r as usize).product()
    }

    #[inline(always)]
    pub fn index(&self, c: [u32; 3]) -> usize {
        c[0] as usize
            + self.res[0] as usize * (c[1] as usize + self.res[1] as usize * c[2] as usize)
    }

    /// Whether box `b` lies within the grid (an empty box does). Every
    /// object lies within its group's grid when the database's summaries
    /// agree with its records.
    #[inline]
    pub fn holds(&self, b: &Aabb) -> bool {
        b.is_empty()
            || (0..3).all(|i| self.lo[i] <= b.min[i] as f64 && b.max[i] as f64 <= self.hi[i])
    }

    /// Inclusive voxel ranges along each axis that a box overlaps, widened
    /// by a tiny margin; `None` if the box is empty.
    #[inline]
    pub fn cell_range(&self, b: &Aabb) -> Option<([u32; 3], [u32; 3])> {
        if b.is_empty() {
            return None;
        }
        let mut lo = [0u32; 3];
        let mut hi = [0u32; 3];
        for i in 0..3 {
            let top = (self.res[i] - 1) as f64;
            let a = (b.min[i] as f64 - self.lo[i]) * self.inv_cell[i] - VOXEL_MARGIN;
            let z = (b.max[i] as f64 - self.lo[i]) * self.inv_cell[i] + VOXEL_MARGIN;
            if z < 0.0 || a >= top + 1.0 {
                return None; // outside the grid
            }
            // Clamped to [0, top], truncation is the floor (and cheaper than
            // the libm call on baseline x86-64).
            lo[i] = a.clamp(0.0, top) as u32;
            hi[i] = z.clamp(0.0, top) as u32;
        }
        Some((lo, hi))
    }

    /// The entry and exit distances of a ray through the grid's box, within
    /// `[t_min, t_max]`; `inv` is 1/d per axis.
    #[inline]
    pub fn clip(&self, o: Vec3, d: Vec3, inv: Vec3, t_min: f64, t_max: f64) -> Option<(f64, f64)> {
        let (mut t0, mut t1) = (t_min, t_max);
        for i in 0..3 {
            if d[i] == 0.0 {
                if o[i] < self.lo[i] || o[i] > self.hi[i] {
                    return None;
                }
                continue;
            }
            let mut a = (self.lo[i] - o[i]) * inv[i];
            let mut b = (self.hi[i] - o[i]) * inv[i];
            if a > b {
                std::mem::swap(&mut a, &mut b);
            }
            t0 = t0.max(a);
            t1 = t1.min(b);
        }
        (t0 <= t1).then_some((t0, t1))
    }

    /// The voxel containing a point, clamped to the grid.
    #[inline]
    pub fn cell_of(&self, p: Vec3) -> [u32; 3] {
        let mut c = [0u32; 3];
        for i in 0..3 {
            let f = (p[i] - self.lo[i]) * self.inv_cell[i];
            c[i] = f.clamp(0.0, (self.res[i] - 1) as f64) as u32;
        }
        c
    }

    pub fn cell_size(&self) -> [f64; 3] {
        self.cell
    }
}

/// How far from its bounding box a hit may be computed, for tests that
/// pass over a box (a hierarchy's, an aggregate's) only when no object
/// inside can give a hit: 1e-5 of the scene's scale, well above the
/// rounding of single precision (about 6e-8 of a position's size) and the
/// grids' margin around an object (1e-6 of a voxel). Eye rays start at the
/// eye, which may lie far outside the grids: their hits are rounded
/// relative to the eye's distance from the origin too.
pub fn box_slack<'a>(eye: &[f64; 3], grids: impl IntoIterator<Item = &'a GridSpec>) -> f64 {
    let mut scale: f64 = eye.iter().fold(0.0, |m, c| m.max(2.0 * c.abs()));
    for g in grids {
        for i in 0..3 {
            scale = scale
                .max(g.hi[i] - g.lo[i])
                .max(g.lo[i].abs())
                .max(g.hi[i].abs());
        }
    }
    1e-5 * scale
}

#[cfg(test)]
mod tests;

/// The error for an object outside the grid its group was given: the
/// database's tables (size or density summary) disagree with its records.
pub fn outside_its_grid(db: &crate::sdb::Database, id: u64) -> crate::error::Error {
    crate::error::Error::Database {
        file: db.path().to_path_buf(),
        location: "tables".into(),
        message: format!(
            "object {id} lies outside the bounds the size and density summaries give its \
             group: the tables disagree with the records; regenerate the database"
        ),
    }
}

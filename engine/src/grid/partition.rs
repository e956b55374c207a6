//! How a scene is split into grids, and how fine each grid is.

use super::GridSpec;
use crate::scene::{Aabb, SIZE_CLASSES, SizeSummary, size_class};
use serde::Serialize;

/// Which objects go in which grid.
#[derive(Clone, Debug, PartialEq)]
pub enum Partition {
    /// Every object in one grid.
    One,
    /// Objects whose size class is `threshold` or more form a second group:
    /// the few huge objects (ground polygons, walls) that would otherwise
    /// stretch the grid over empty space.
    Large { threshold: u8 },
}

impl Partition {
    /// Group of an object: 0 for the main grid, 1 for the large objects.
    #[inline]
    pub fn group(&self, b: &Aabb) -> usize {
        match *self {
            Partition::One => 0,
            Partition::Large { threshold } => (size_class(b) >= threshold) as usize,
        }
    }
}

/// The grids of a scene: bounds and object count per group.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupPlan {
    pub partition: Partition,
    pub bounds: Vec<Aabb>,
    pub counts: Vec<u64>,
}

/// At most this share of the objects may be set apart as large.
const MAX_LARGE_SHARE: f64 = 0.01;
/// ... or this many, for small scenes.
const MAX_LARGE_FEW: u64 = 8;
/// The split is worth it when the rest spans at most this fraction of the
/// whole scene's diagonal.
const SHRINK: f64 = 0.5;

/// Decides whether to set the largest objects apart, from the size summary:
/// the largest size classes form the second group when they hold few
/// objects and leaving them out shrinks the main grid's box by at least
/// half. `allow_split = false` (`--grids 1`) keeps one grid.
pub fn plan_groups(sizes: &SizeSummary, allow_split: bool) -> GroupPlan {
    let (total, all) = sizes.range(0, SIZE_CLASSES);
    let one = GroupPlan {
        partition: Partition::One,
        bounds: vec![all],
        counts: vec![total],
    };
    if !allow_split || total < 2 {
        return one;
    }
    let limit = MAX_LARGE_FEW.max((total as f64 * MAX_LARGE_SHARE) as u64);
    let full = all.diagonal();
    let mut best: Option<(f64, u8)> = None;
    // Try setting apart classes >= k, from the largest class down.
    for k in (1..SIZE_CLASSES).rev() {
        let (large, _) = sizes.range(k, SIZE_CLASSES);
        if large == 0 {
            continue;
        }
        if large > limit {
            break;
        }
        let (rest, rest_bounds) = sizes.range(0, k);
        if rest == 0 {
            break;
        }
        // Take the first split that shrinks the main grid enough; setting
        // more classes apart must shrink it as much again.
        let d = rest_bounds.diagonal();
        let bar = best.map_or(full, |(bd, _)| bd);
        if d <= SHRINK * bar {
            best = Some((d, k as u8));
        }
    }
    match best {
        None => one,
        Some((_, k)) => {
            let (nl, bl) = sizes.range(k as usize, SIZE_CLASSES);
            let (nr, br) = sizes.range(0, k as usize);
            GroupPlan {
                partition: Partition::Large { threshold: k },
                bounds: vec![br, bl],
                counts: vec![nr, nl],
            }
        }
    }
}

/// Grid resolution for `objects` objects in `bounds`: about `density`
/// voxels per object, shared among the axes in proportion to the box's
/// extents (a flat box gets a flat grid), at most `max_cells` in all.
pub fn choose_resolution(bounds: &Aabb, objects: u64, density: f64, max_cells: u64) -> [u32; 3] {
    if bounds.is_empty() || objects == 0 {
        return [1, 1, 1];
    }
    let g = GridSpec::new(bounds, [1, 1, 1]);
    let e: Vec<f64> = (0..3).map(|i| g.hi[i] - g.lo[i]).collect();
    let big = e.iter().cloned().fold(0.0, f64::max);
    // Axes thinner than a thousandth of the longest get one voxel.
    let active: Vec<usize> = (0..3).filter(|&i| e[i] > big * 1e-3).collect();
    let target = (objects as f64 * density).clamp(1.0, max_cells as f64);
    let vol: f64 = active.iter().map(|&i| e[i]).product();
    let s = (target / vol).powf(1.0 / active.len() as f64);
    let mut res = [1u32; 3];
    for &i in &active {
        res[i] = (e[i] * s).round().clamp(1.0, 4096.0) as u32;
    }
    while res.iter().map(|&r| r as u64).product::<u64>() > max_cells {
        let i = (0..3).max_by_key(|&i| res[i]).unwrap_or(0);
        res[i] = (res[i] - res[i] / 8).max(1);
    }
    res
}

/// What a grid group looks like in the statistics.
#[derive(Clone, Debug, Serialize)]
pub struct GridStat {
    pub objects: u64,
    pub resolution: [u32; 3],
    pub lo: [f64; 3],
    pub hi: [f64; 3],
}

//! How a scene is split into grids, and how fine each grid is.
//!
//! One grid suits a uniform scene. A few huge objects (a ground polygon, a
//! wall) beside many small ones would stretch a single grid over empty
//! space, so they get a grid of their own (the paper's Section 2.4: objects
//! grouped into several grids, results merged per ray).
//!
//! Groups are ranges of size classes (see [`crate::scene::SizeSummary`]),
//! decided from the database's size summary alone, so no scan is needed.
//! (Grouping by size more finely, e.g. the sphereflake's big spheres apart
//! from its tiny ones, was measured and cost more in extra grid walks than
//! it saved; see BENCHMARKS.md.)

use super::GridSpec;
use crate::scene::{Aabb, SIZE_CLASSES, SizeSummary, size_class};
use serde::Serialize;

/// Which objects go in which grid: group `g` holds the objects whose size
/// class is at least `bounds[g - 1]` and below `bounds[g]` (open-ended at
/// both ends).
#[derive(Clone, Debug, PartialEq)]
pub struct Partition {
    /// Ascending class boundaries; empty for a single grid.
    pub splits: Vec<u8>,
}

impl Partition {
    pub fn one() -> Partition {
        Partition { splits: Vec::new() }
    }

    /// Group of an object with bounding box `b`.
    #[inline]
    pub fn group(&self, b: &Aabb) -> usize {
        let c = size_class(b);
        self.splits.iter().take_while(|&&s| c >= s).count()
    }

    pub fn groups(&self) -> usize {
        self.splits.len() + 1
    }
}

/// The grids of a scene: bounds and object count per group, smallest
/// objects first.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupPlan {
    pub partition: Partition,
    pub bounds: Vec<Aabb>,
    pub counts: Vec<u64>,
}

/// At most this share of the objects may be set apart as huge...
const MAX_HUGE_SHARE: f64 = 0.01;
/// ... or this many, for small scenes.
const MAX_HUGE_FEW: u64 = 8;
/// Setting the huge objects apart is worth it when the rest spans at most
/// this fraction of the whole scene's diagonal.
const SHRINK: f64 = 0.6;
/// Plans the grids from the size summary. `allow_split = false`
/// (`--grids 1`) keeps one grid.
pub fn plan_groups(sizes: &SizeSummary, allow_split: bool) -> GroupPlan {
    let (total, all) = sizes.range(0, SIZE_CLASSES);
    let mut splits = Vec::new();
    if allow_split
        && total >= 2
        && let Some(k) = huge_split(sizes, total, &all)
    {
        splits.push(k);
    }
    let mut edges = vec![0usize];
    edges.extend(splits.iter().map(|&s| s as usize));
    edges.push(SIZE_CLASSES);
    let mut bounds = Vec::new();
    let mut counts = Vec::new();
    for w in edges.windows(2) {
        let (n, b) = sizes.range(w[0], w[1]);
        counts.push(n);
        bounds.push(b);
    }
    GroupPlan {
        partition: Partition { splits },
        bounds,
        counts,
    }
}

/// The smallest size class of the huge objects, if setting them apart
/// pays: the largest classes, few objects, and leaving them out shrinks
/// the rest's box to at most SHRINK (0.6) of the scene's diagonal.
fn huge_split(sizes: &SizeSummary, total: u64, all: &Aabb) -> Option<u8> {
    let limit = MAX_HUGE_FEW.max((total as f64 * MAX_HUGE_SHARE) as u64);
    let full = all.diagonal();
    let mut best: Option<(f64, u8)> = None;
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
    best.map(|(_, k)| k)
}

/// Grid resolution for `objects` objects in `bounds`: about `density`
/// voxels per object, shared among the axes in proportion to the box's
/// extents (a flat box gets a flat grid), at most `max_cells` in all.
pub fn choose_resolution(bounds: &Aabb, objects: u64, density: f64, max_cells: u64) -> [u32; 3] {
    // A handful of objects gains nothing from subdivision; nor does a
    // budget too small for more than one voxel.
    let max_cells = max_cells.max(1);
    if bounds.is_empty() || objects <= 8 {
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
    /// Depth-first: voxels crowded enough to hold a hierarchy of their
    /// objects instead of a list, and the objects those list (counted
    /// once per voxel).
    #[serde(skip_serializing_if = "is_zero")]
    pub nested_voxels: u64,
    #[serde(skip_serializing_if = "is_zero")]
    pub nested_objects: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

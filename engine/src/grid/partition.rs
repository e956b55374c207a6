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
//! it saved; see CHANGELOG.md, 2026-11-24.)

use super::GridSpec;
use crate::scene::{Aabb, DensitySummary, Lattice, SIZE_CLASSES, SizeSummary, size_class};
use serde::Serialize;

/// Which objects go in which grid. Group 0 holds the objects of the
/// main grid; groups `1..=R` the dense regions' (see [`Regions`]); the
/// groups after them the huge objects, by size class: group `R + j`
/// holds the classes from `splits[j - 1]` up to (not including)
/// `splits[j]`, the last open-ended.
#[derive(Clone, Debug, PartialEq)]
pub struct Partition {
    /// Ascending class boundaries; empty for no huge objects.
    pub splits: Vec<u8>,
    pub regions: Option<Regions>,
}

/// Dense regions: sets of cells of the database's density lattice, each
/// with a size-class bound. An object smaller than its region's bound
/// whose centre lies in one of the region's cells goes to the region's
/// grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Regions {
    lattice: Lattice,
    /// Per lattice cell: 0, or 1 + the index of the region it is part of.
    cell_region: Vec<u8>,
    /// Per region: the classes below this one are its objects (256: all).
    below: Vec<u16>,
}

impl Regions {
    pub fn count(&self) -> usize {
        self.below.len()
    }

    /// The region (1-based) of an object of class `class` and box `b`, or 0.
    #[inline]
    fn of(&self, class: u8, b: &Aabb) -> usize {
        self.lattice
            .cell_of(b)
            .map_or(0, |cell| self.taking(cell, class))
    }

    /// The region (1-based) that takes the objects of class `class`
    /// centred in lattice cell `cell`, or 0.
    #[inline]
    fn taking(&self, cell: u32, class: u8) -> usize {
        match self.cell_region[cell as usize] as usize {
            r if r != 0 && (class as u16) < self.below[r - 1] => r,
            _ => 0,
        }
    }
}

impl Partition {
    pub fn one() -> Partition {
        Partition {
            splits: Vec::new(),
            regions: None,
        }
    }

    /// Group of an object with bounding box `b`.
    #[inline]
    pub fn group(&self, b: &Aabb) -> usize {
        if self.splits.is_empty() && self.regions.is_none() {
            // One grid, every object's: no size class to work out (this
            // is asked for each object of every scan, and the size class
            // took 4 % of tetra12's samples).
            return 0;
        }
        let c = size_class(b);
        let huge = self.splits.iter().take_while(|&&s| c >= s).count();
        let regions = self.regions.as_ref();
        let r = regions.map_or(0, Regions::count);
        if huge > 0 {
            return r + huge;
        }
        regions.map_or(0, |x| x.of(c, b))
    }

    pub fn groups(&self) -> usize {
        self.splits.len() + 1 + self.regions.as_ref().map_or(0, Regions::count)
    }
}

/// The grids of a scene: bounds and object count per group (the main
/// grid's, the dense regions', the huge objects').
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

/// Plans the grids from the size summary and, if the database has one,
/// the density summary. `allow_split = false` keeps one grid (the
/// paper's single-grid setup).
pub fn plan_groups(
    sizes: &SizeSummary,
    density: Option<&DensitySummary>,
    allow_split: bool,
) -> GroupPlan {
    let (total, all) = sizes.range(0, SIZE_CLASSES);
    let mut splits = Vec::new();
    if allow_split
        && total >= 2
        && let Some(k) = huge_split(sizes, total, &all)
    {
        splits.push(k);
    }
    let main_classes = splits.first().map_or(SIZE_CLASSES, |&k| k as usize);
    let (main_count, main_bounds) = sizes.range(0, main_classes);
    let room = MAX_GROUPS.saturating_sub(1 + splits.len());
    let dense = match density {
        Some(d) if allow_split && d.usable() && room > 0 => {
            dense_regions(d, main_classes, main_count, &main_bounds, room)
        }
        _ => None,
    };
    let mut bounds = Vec::new();
    let mut counts = Vec::new();
    let regions = match dense {
        None => {
            counts.push(main_count);
            bounds.push(main_bounds);
            None
        }
        Some(d) => {
            counts.push(main_count.saturating_sub(d.counts.iter().sum::<u64>()));
            bounds.push(d.rest);
            counts.extend(&d.counts);
            bounds.extend(&d.bounds);
            Some(d.regions)
        }
    };
    let mut edges: Vec<usize> = splits.iter().map(|&s| s as usize).collect();
    edges.push(SIZE_CLASSES);
    for w in edges.windows(2) {
        let (n, b) = sizes.range(w[0], w[1]);
        counts.push(n);
        bounds.push(b);
    }
    GroupPlan {
        partition: Partition { splits, regions },
        bounds,
        counts,
    }
}

/// A cell is dense when the objects of one size class there are this many
/// times closer together than the main grid's objects on average...
const DENSE_CELL: f64 = 16.0;
/// ... and a region pays a grid of its own when its objects are this many
/// times denser than the main grid's on average (a uniform grid sized for
/// the whole scene would give its voxels as many times the objects)...
const DENSE_REGION: f64 = 16.0;
/// ... and it holds at least this many objects...
const MIN_REGION_OBJECTS: u64 = 2048;
/// ... and this share of the main grid's.
const MIN_REGION_SHARE: f64 = 0.02;
/// Most grids a plan makes: the breadth-first tracer keeps a walk per grid
/// in every ray slot, so each grid allowed costs every ray memory. The
/// main grid, and a dense region and the huge objects, or two regions.
pub const MAX_GROUPS: usize = 3;

struct Dense {
    regions: Regions,
    counts: Vec<u64>,
    bounds: Vec<Aabb>,
    /// Bounds of the main grid's objects left.
    rest: Aabb,
}

/// Extents of a box with thin axes thickened to a thousandth of `big`, so
/// that flat boxes have a volume to compare.
fn thick_volume(e: [f64; 3], big: f64) -> f64 {
    e.iter().map(|&x| x.max(big * 1e-3)).product()
}

/// Finds the dense regions among the objects of classes below
/// `main_classes` (`n` objects within `bounds`), at most `most` of them
/// (the largest).
fn dense_regions(
    d: &DensitySummary,
    main_classes: usize,
    n: u64,
    bounds: &Aabb,
    most: usize,
) -> Option<Dense> {
    use crate::scene::DENSITY_CELLS as C;
    if n < MIN_REGION_OBJECTS || bounds.is_empty() {
        return None;
    }
    let cells = (C * C * C) as usize;
    let e = bounds.extent();
    let big = e[0].max(e[1]).max(e[2]);
    if big <= 0.0 {
        return None;
    }
    let volume = thick_volume(e, big);
    // Dense cells: some size class's objects there lie far closer
    // together (by the box they fill) than the main grid's on average.
    // Judged by the objects' own box, not the cell's, so that a model
    // much smaller than a cell still stands out.
    let mut dense = vec![false; cells];
    // The box of each dense cell's dense objects.
    let mut dense_box = vec![Aabb::EMPTY; cells];
    let average = n as f64 / volume;
    for (&(cell, class), e) in &d.entries {
        if (class as usize) < main_classes
            && e.count >= 64
            && e.count as f64 >= DENSE_CELL * average * thick_volume(e.bounds.extent(), big)
        {
            dense[cell as usize] = true;
            dense_box[cell as usize].union(&e.bounds);
        }
    }
    // Neighbouring dense cells are one region if their dense objects'
    // boxes touch (a model across a cell boundary), not if they merely
    // share a boundary (two models in neighbouring cells).
    let gap = (big * 1e-3) as f32;
    let touch = |a: &Aabb, b: &Aabb| {
        (0..3).all(|i| a.min[i] <= b.max[i] + gap && b.min[i] <= a.max[i] + gap)
    };
    // Regions: the dense cells' connected parts (26-neighbours).
    let mut part = vec![0u32; cells];
    let mut parts: Vec<Vec<u32>> = Vec::new();
    for start in 0..cells {
        if !dense[start] || part[start] != 0 {
            continue;
        }
        parts.push(Vec::new());
        let id = parts.len() as u32;
        part[start] = id;
        let mut stack = vec![start as u32];
        while let Some(c) = stack.pop() {
            parts[id as usize - 1].push(c);
            let p = DensitySummary::coords(c);
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let q = [p[0] + dx, p[1] + dy, p[2] + dz];
                        if q.iter().any(|&x| !(0..C).contains(&x)) {
                            continue;
                        }
                        let i = (q[0] + C * (q[1] + C * q[2])) as usize;
                        if dense[i] && part[i] == 0 && touch(&dense_box[i], &dense_box[c as usize])
                        {
                            part[i] = id;
                            stack.push(i as u32);
                        }
                    }
                }
            }
        }
    }
    // Each part: the classes that make it dense. Adding classes from the
    // smallest up, keep the most that stay at least half as dense as the
    // densest choice worth a grid (a few larger objects among a model's
    // triangles must not stretch its grid over the whole cell).
    let mut found: Vec<(u64, Aabb, u16, usize)> = Vec::new();
    let mut per_part: Vec<Vec<(u8, u64, Aabb)>> = vec![Vec::new(); parts.len()];
    for (&(cell, class), e) in &d.entries {
        let p = part[cell as usize] as usize;
        if p != 0 && (class as usize) < main_classes {
            per_part[p - 1].push((class, e.count, e.bounds));
        }
    }
    for (pi, mut entries) in per_part.into_iter().enumerate() {
        entries.sort_by_key(|e| e.0);
        let (mut count, mut b) = (0u64, Aabb::EMPTY);
        let mut choices: Vec<(f64, u64, Aabb, u16)> = Vec::new();
        for (i, &(class, k, cb)) in entries.iter().enumerate() {
            count += k;
            b.union(&cb);
            // A choice ends with a class's last entry.
            if entries.get(i + 1).is_some_and(|e| e.0 == class) {
                continue;
            }
            let rho = (count as f64 / n as f64) / (thick_volume(b.extent(), big) / volume);
            choices.push((rho, count, b, class as u16 + 1));
        }
        // Only choices that would be set apart count (a few tiny objects
        // in a tiny box are dense, but not worth a grid).
        choices.retain(|&(rho, count, ..)| {
            rho >= DENSE_REGION
                && count >= MIN_REGION_OBJECTS
                && count as f64 >= MIN_REGION_SHARE * n as f64
        });
        let best = choices.iter().map(|c| c.0).fold(0.0, f64::max);
        if let Some(&(_, count, b, below)) = choices.iter().rev().find(|c| c.0 >= best / 2.0) {
            found.push((count, b, below, pi + 1));
        }
    }
    if found.is_empty() {
        return None;
    }
    found.sort_by_key(|f| std::cmp::Reverse(f.0));
    found.truncate(most);
    let mut cell_region = vec![0u8; cells];
    for (r, f) in found.iter().enumerate() {
        for c in &parts[f.3 - 1] {
            cell_region[*c as usize] = r as u8 + 1;
        }
    }
    let regions = Regions {
        lattice: d.lattice(),
        cell_region,
        below: found.iter().map(|f| f.2).collect(),
    };
    // What the main grid keeps: every entry not taken by a region.
    let mut rest = Aabb::EMPTY;
    for (&(cell, class), e) in &d.entries {
        if (class as usize) >= main_classes {
            continue;
        }
        if regions.taking(cell, class) == 0 {
            rest.union(&e.bounds);
        }
    }
    Some(Dense {
        counts: found.iter().map(|f| f.0).collect(),
        bounds: found.iter().map(|f| f.1).collect(),
        regions,
        rest,
    })
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
    /// Depth-first: groups of objects held as aggregates (see
    /// [`super::aggregate`]).
    #[serde(skip_serializing_if = "is_zero")]
    pub aggregates: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

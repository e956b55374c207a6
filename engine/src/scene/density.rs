//! Where the objects are: a coarse cubic lattice over the scene, counting
//! the objects whose bounding-box centre falls in each cell, per size
//! class, with the union of their boxes. Kept in the database's tables
//! beside the [`super::SizeSummary`], it lets a renderer find a dense
//! model in a sparse world (the full dragon on a wide floor) and give it
//! a grid of its own without scanning the objects.
//!
//! The writer does not know the scene's extent until the last object, so
//! the lattice grows as objects arrive: its cells are cubes of a power of
//! two, and when a centre falls outside, the cell side doubles and eight
//! cells become one. A cell is named by integers (`floor(c / side)` per
//! axis, exact for a power-of-two side), so a cell of the final lattice
//! holds exactly the objects a reader finds in it by
//! [`DensitySummary::cell_of`], however the lattice grew.

use super::{Aabb, SizeClass, size_class};
use std::collections::HashMap;

/// Cells per axis.
pub const CELLS: i64 = 32;
/// A summary with more (cell, size class) pairs than this is dropped
/// (a renderer then plans as if the database had none): the tables stay
/// small whatever the scene.
pub const MAX_ENTRIES: usize = 1 << 18;
/// Coordinates beyond this many cells from zero are not counted exactly
/// in an `f64`; a scene that needs them keeps no summary.
const MAX_CELL_COORD: f64 = (1u64 << 50) as f64;

/// Cells of side `2^level`, [`CELLS`] along each axis from the cell of
/// integer coordinates `origin`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lattice {
    pub level: i32,
    pub origin: [i64; 3],
}

impl Lattice {
    /// The integer cell coordinates of the centre of `b` in cells of side
    /// `2^level`, if they are exact.
    #[inline]
    fn absolute(b: &Aabb, level: i32) -> Option<[i64; 3]> {
        let c = centre(b);
        let s = pow2(-level);
        let mut a = [0i64; 3];
        for i in 0..3 {
            let f = floor(c[i] * s);
            if !(f.abs() < MAX_CELL_COORD) {
                return None;
            }
            a[i] = f as i64;
        }
        Some(a)
    }

    /// Index of the cell holding the centre of `b`, if inside the lattice.
    #[inline]
    pub fn cell_of(&self, b: &Aabb) -> Option<u32> {
        let a = Self::absolute(b, self.level)?;
        let mut index = 0i64;
        for i in (0..3).rev() {
            let r = a[i] - self.origin[i];
            if !(0..CELLS).contains(&r) {
                return None;
            }
            index = index * CELLS + r;
        }
        Some(index as u32)
    }
}

/// Counts and bounds per (cell, size class).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DensitySummary {
    /// The cells' side is `2^level`.
    pub level: i32,
    /// The first cell's integer coordinates, in cells of that side.
    pub origin: [i64; 3],
    /// By cell index (`x + CELLS * (y + CELLS * z)`) and size class.
    pub entries: HashMap<(u32, u8), SizeClass>,
    /// Set once the summary could not be kept (see [`MAX_ENTRIES`]).
    pub dropped: bool,
    started: bool,
}

/// The centre of `b` as the lattice sees it (the same arithmetic in the
/// writer and every reader).
#[inline]
fn centre(b: &Aabb) -> [f64; 3] {
    std::array::from_fn(|i| 0.5 * (b.min[i] as f64 + b.max[i] as f64))
}

/// `2^e` for the exponents a lattice uses: built from its bits where it
/// is a normal number (the breadth-first tracer asks for it for every
/// object in every pass; `powi` is a library call), as `powi` gives it.
#[inline]
fn pow2(e: i32) -> f64 {
    if (-1022..=1023).contains(&e) {
        f64::from_bits(((e + 1023) as u64) << 52)
    } else {
        2f64.powi(e)
    }
}

/// `x.floor()`, without the library call baseline x86-64 makes for it:
/// below 2^52 in magnitude, truncation to an integer is exact.
#[inline]
fn floor(x: f64) -> f64 {
    if x.abs() < 4_503_599_627_370_496.0 {
        let t = x as i64 as f64;
        if t > x { t - 1.0 } else { t }
    } else {
        x.floor()
    }
}

impl DensitySummary {
    /// A summary read back from a database.
    pub fn from_parts(
        level: i32,
        origin: [i64; 3],
        entries: impl IntoIterator<Item = ((u32, u8), SizeClass)>,
    ) -> DensitySummary {
        DensitySummary {
            level,
            origin,
            entries: entries.into_iter().collect(),
            dropped: false,
            started: true,
        }
    }

    /// Whether a renderer can plan with it.
    pub fn usable(&self) -> bool {
        self.started && !self.dropped
    }

    /// Side of a cell.
    pub fn cell_side(&self) -> f64 {
        pow2(self.level)
    }

    /// The lattice alone, to place objects in cells.
    pub fn lattice(&self) -> Lattice {
        Lattice {
            level: self.level,
            origin: self.origin,
        }
    }

    /// Index of the cell holding the centre of `b`, if inside the lattice.
    #[inline]
    pub fn cell_of(&self, b: &Aabb) -> Option<u32> {
        self.lattice().cell_of(b)
    }

    /// The cell's coordinates along each axis.
    pub fn coords(index: u32) -> [i64; 3] {
        let i = index as i64;
        [i % CELLS, i / CELLS % CELLS, i / (CELLS * CELLS)]
    }

    /// The box of cell `index`.
    pub fn cell_box(&self, index: u32) -> [[f64; 3]; 2] {
        let c = Self::coords(index);
        let s = self.cell_side();
        let lo: [f64; 3] = std::array::from_fn(|i| (self.origin[i] + c[i]) as f64 * s);
        [lo, std::array::from_fn(|i| lo[i] + s)]
    }

    /// Counts an object with bounding box `b`.
    pub fn add(&mut self, b: &Aabb) {
        if self.dropped || b.is_empty() {
            return;
        }
        if !self.started {
            self.start(b);
        }
        loop {
            if let Some(index) = self.cell_of(b) {
                let e = self
                    .entries
                    .entry((index, size_class(b)))
                    .or_insert(SizeClass {
                        count: 0,
                        bounds: Aabb::EMPTY,
                    });
                e.count += 1;
                e.bounds.union(b);
                if self.entries.len() > MAX_ENTRIES {
                    self.drop_all();
                }
                return;
            }
            if self.level >= 1000 {
                self.drop_all();
                return;
            }
            let (c, s) = (centre(b), pow2(-self.level));
            self.grow(std::array::from_fn(|i| {
                (c[i] * s).floor() < self.origin[i] as f64
            }));
        }
    }

    fn drop_all(&mut self) {
        self.dropped = true;
        self.entries = HashMap::new();
    }

    /// The first object sets a lattice far finer than any scene needs (a
    /// millionth of its distance from the origin, or 2^-100), which grows
    /// from there as objects fall outside it, so that it ends up spanning
    /// the objects' centres (at most four times their extent along an
    /// axis), whatever the first object's size: a ground polygon read
    /// first must not make the cells as large as itself.
    fn start(&mut self, b: &Aabb) {
        let c = centre(b);
        let size = (1e-6 * c.iter().fold(0.0f64, |m, x| m.max(x.abs()))).max(1e-30);
        self.level = size.log2().ceil().clamp(-1000.0, 1000.0) as i32;
        self.started = true;
        if let Some(a) = Lattice::absolute(b, self.level) {
            self.origin = a.map(|x| x - CELLS / 2);
        }
    }

    /// Doubles the cells' side, keeping every cell inside the new lattice
    /// and extending it toward lower coordinates along the axes `left`.
    fn grow(&mut self, left: [bool; 3]) {
        let old = self.origin;
        let mut origin = [0i64; 3];
        for i in 0..3 {
            // The old lattice spans [lo, hi) in the new cells.
            let lo = old[i].div_euclid(2);
            let hi = (old[i] + CELLS + 1).div_euclid(2);
            origin[i] = if left[i] { hi - CELLS } else { lo };
        }
        let mut merged: HashMap<(u32, u8), SizeClass> = HashMap::with_capacity(self.entries.len());
        for ((index, class), e) in self.entries.drain() {
            let c = Self::coords(index);
            let mut at = 0i64;
            for i in (0..3).rev() {
                at = at * CELLS + ((old[i] + c[i]).div_euclid(2) - origin[i]);
            }
            let m = merged.entry((at as u32, class)).or_insert(SizeClass {
                count: 0,
                bounds: Aabb::EMPTY,
            });
            m.count += e.count;
            m.bounds.union(&e.bounds);
        }
        self.entries = merged;
        self.level += 1;
        self.origin = origin;
    }

    /// The entries in a fixed order (for writing).
    pub fn sorted(&self) -> Vec<((u32, u8), SizeClass)> {
        let mut v: Vec<_> = self.entries.iter().map(|(&k, &e)| (k, e)).collect();
        v.sort_by_key(|&(k, _)| k);
        v
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn pow2_and_floor_are_the_library_s() {
        for e in -1100..1100 {
            assert_eq!(pow2(e).to_bits(), 2f64.powi(e).to_bits(), "2^{e}");
        }
        let mut xs = vec![0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 2.5, -2.5, 1e-300, -1e-300];
        xs.extend([
            4.5e15,
            -4.5e15,
            4.6e15,
            -4.6e15,
            1e300,
            -1e300,
            f64::MAX,
            f64::MIN,
        ]);
        let mut seed = 1u64;
        for _ in 0..100_000 {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            let x = f64::from_bits(seed);
            if x.is_finite() {
                xs.push(x);
                xs.push(x * 1e-300);
            }
            xs.push((seed >> 11) as f64 / 1e6 - 4e12);
        }
        for x in xs {
            // Equal as numbers (a -0.0 may come back as 0.0).
            assert_eq!(floor(x), x.floor(), "{x}");
        }
        assert!(floor(f64::NAN).is_nan());
    }

    use super::*;

    fn cube(c: [f32; 3], r: f32) -> Aabb {
        Aabb {
            min: c.map(|x| x - r),
            max: c.map(|x| x + r),
        }
    }

    /// However the lattice grew, each object is in the cell a reader
    /// finds for it, and the counts add up.
    #[test]
    fn growing_keeps_every_object_in_its_cell() {
        let mut x: u64 = 99;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut boxes = Vec::new();
        for i in 0..5000 {
            // Spreading out as it goes, on both sides, at several scales.
            let spread = 1.0 + i as f64 * 0.05;
            let c = [0, 1, 2].map(|_| ((next() - 0.6) * spread) as f32);
            boxes.push(cube(c, (0.001 + 0.01 * next()) as f32));
        }
        let mut d = DensitySummary::default();
        for b in &boxes {
            d.add(b);
        }
        assert!(d.usable());
        let mut want: HashMap<(u32, u8), u64> = HashMap::new();
        for b in &boxes {
            let cell = d.cell_of(b).expect("every object inside the lattice");
            *want.entry((cell, size_class(b))).or_default() += 1;
        }
        let got: HashMap<(u32, u8), u64> = d.entries.iter().map(|(&k, e)| (k, e.count)).collect();
        assert_eq!(got, want);
        let total: u64 = d.entries.values().map(|e| e.count).sum();
        assert_eq!(total, 5000);
        // The lattice is not much larger than the scene.
        let side = d.cell_side() * CELLS as f64;
        assert!(side < 4.0 * 250.0 * 1.3, "lattice side {side}");
    }

    #[test]
    fn a_scene_of_one_point_and_a_far_object() {
        let mut d = DensitySummary::default();
        d.add(&cube([0.0; 3], 0.0));
        d.add(&cube([1e20, -3.0, 5.0], 1.0));
        assert!(d.usable());
        assert_eq!(d.entries.values().map(|e| e.count).sum::<u64>(), 2);
        assert!(d.cell_of(&cube([1e20, -3.0, 5.0], 1.0)).is_some());
    }
}

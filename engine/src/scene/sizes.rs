//! A summary of object sizes: for each power-of-two class of an object's
//! longest bounding-box edge, how many objects and the union of their
//! boxes. Kept in the database's tables, it lets a renderer decide which
//! objects are "large" (a ground polygon beside thousands of small
//! objects) and where the rest lie, without scanning the objects.

use super::Aabb;

pub const SIZE_CLASSES: usize = 256;

/// The class of a box: the binary exponent of its longest edge, as the
/// biased `f32` exponent (0 for an empty or zero-size box).
pub fn size_class(b: &Aabb) -> u8 {
    let e = b.extent();
    let longest = e[0].max(e[1]).max(e[2]) as f32;
    ((longest.to_bits() >> 23) & 0xff) as u8
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SizeClass {
    pub count: u64,
    pub bounds: Aabb,
}

/// Counts and bounds per size class.
#[derive(Clone, Debug, PartialEq)]
pub struct SizeSummary {
    pub classes: Vec<SizeClass>,
}

impl Default for SizeSummary {
    fn default() -> Self {
        SizeSummary {
            classes: vec![
                SizeClass {
                    count: 0,
                    bounds: Aabb::EMPTY
                };
                SIZE_CLASSES
            ],
        }
    }
}

impl SizeSummary {
    pub fn add(&mut self, b: &Aabb) {
        let c = &mut self.classes[size_class(b) as usize];
        c.count += 1;
        c.bounds.union(b);
    }

    pub fn total(&self) -> u64 {
        self.classes.iter().map(|c| c.count).sum()
    }

    /// Count and bounds of the objects of classes `lo..hi`.
    pub fn range(&self, lo: usize, hi: usize) -> (u64, Aabb) {
        let mut n = 0;
        let mut b = Aabb::EMPTY;
        for c in &self.classes[lo..hi] {
            n += c.count;
            b.union(&c.bounds);
        }
        (n, b)
    }
}

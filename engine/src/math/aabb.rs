use serde::Serialize;

/// An axis-aligned bounding box in the `f32` coordinates of the object
/// database. An empty box has `min > max`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Aabb {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: [f32::INFINITY; 3],
        max: [f32::NEG_INFINITY; 3],
    };

    pub fn is_empty(&self) -> bool {
        (0..3).any(|i| !(self.min[i] <= self.max[i]))
    }

    pub fn from_array(a: [f32; 6]) -> Self {
        Aabb {
            min: [a[0], a[1], a[2]],
            max: [a[3], a[4], a[5]],
        }
    }

    pub fn to_array(self) -> [f32; 6] {
        [
            self.min[0],
            self.min[1],
            self.min[2],
            self.max[0],
            self.max[1],
            self.max[2],
        ]
    }

    /// The box of a triangle's corners by plain comparisons, whose result
    /// is the same on every machine (`f32::min` leaves open which of +0
    /// and -0 it returns). A version 4 database packs a face only if this
    /// is the box its record holds, so the box can be rebuilt rather than
    /// kept, bit for bit.
    #[inline(always)]
    pub fn of_face(v: &[[f32; 3]; 3]) -> Aabb {
        let mut b = Aabb::EMPTY;
        for a in 0..3 {
            let x = [v[0][a], v[1][a], v[2][a]];
            let lo = if x[1] < x[0] { x[1] } else { x[0] };
            b.min[a] = if x[2] < lo { x[2] } else { lo };
            let hi = if x[1] > x[0] { x[1] } else { x[0] };
            b.max[a] = if x[2] > hi { x[2] } else { hi };
        }
        b
    }

    pub fn add_point(&mut self, p: [f32; 3]) {
        for i in 0..3 {
            self.min[i] = self.min[i].min(p[i]);
            self.max[i] = self.max[i].max(p[i]);
        }
    }

    pub fn union(&mut self, o: &Aabb) {
        for i in 0..3 {
            self.min[i] = self.min[i].min(o.min[i]);
            self.max[i] = self.max[i].max(o.max[i]);
        }
    }

    pub fn extent(&self) -> [f64; 3] {
        if self.is_empty() {
            return [0.0; 3];
        }
        [
            self.max[0] as f64 - self.min[0] as f64,
            self.max[1] as f64 - self.min[1] as f64,
            self.max[2] as f64 - self.min[2] as f64,
        ]
    }

    /// Length of the diagonal (0 for an empty box).
    pub fn diagonal(&self) -> f64 {
        let e = self.extent();
        (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt()
    }

    /// Largest absolute coordinate of the box (0 for an empty box).
    pub fn max_abs_coord(&self) -> f64 {
        if self.is_empty() {
            return 0.0;
        }
        (0..3)
            .map(|i| (self.min[i].abs().max(self.max[i].abs())) as f64)
            .fold(0.0, f64::max)
    }
}

/// The largest `f32` not above `x`.
pub(crate) fn f32_down(x: f64) -> f32 {
    let f = x as f32;
    if (f as f64) > x { f.next_down() } else { f }
}

/// The smallest `f32` not below `x`.
pub(crate) fn f32_up(x: f64) -> f32 {
    let f = x as f32;
    if (f as f64) < x { f.next_up() } else { f }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outward_rounding_brackets_the_value() {
        for &x in &[0.1f64, -0.1, 1.0 / 3.0, -7.3e-12, 1e30, 0.0] {
            assert!((f32_down(x) as f64) <= x);
            assert!((f32_up(x) as f64) >= x);
        }
    }

    #[test]
    fn empty_box_behaviour() {
        let mut b = Aabb::EMPTY;
        assert!(b.is_empty());
        assert_eq!(b.diagonal(), 0.0);
        b.add_point([1.0, 2.0, 3.0]);
        assert!(!b.is_empty());
        b.add_point([-1.0, 2.0, 5.0]);
        assert_eq!(b.min, [-1.0, 2.0, 3.0]);
        assert_eq!(b.max, [1.0, 2.0, 5.0]);
    }
}

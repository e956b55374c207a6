use super::Real;
use std::ops::{Add, AddAssign, Index, Mul, Neg, Sub};

/// A 3-vector over [`Real`], for the precision-generic intersection tests.
/// Plain data; every operation is written out so that the order
/// of floating-point operations, and therefore every result bit, is the same
/// in every engine that calls it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct V3<T> {
    pub x: T,
    pub y: T,
    pub z: T,
}

impl<T: Real> V3<T> {
    #[inline(always)]
    pub const fn new(x: T, y: T, z: T) -> Self {
        Self { x, y, z }
    }
    #[inline(always)]
    pub fn splat(v: T) -> Self {
        Self { x: v, y: v, z: v }
    }
    #[inline(always)]
    pub fn zero() -> Self {
        Self::splat(T::ZERO)
    }
    #[inline(always)]
    pub fn from_f32(a: [f32; 3]) -> Self {
        Self::new(T::from_f32(a[0]), T::from_f32(a[1]), T::from_f32(a[2]))
    }
    #[inline(always)]
    pub fn from_f64(a: [f64; 3]) -> Self {
        Self::new(T::from_f64(a[0]), T::from_f64(a[1]), T::from_f64(a[2]))
    }
    #[inline(always)]
    pub fn to_f64(self) -> V3<f64> {
        V3::new(self.x.to_f64(), self.y.to_f64(), self.z.to_f64())
    }
    #[inline(always)]
    pub fn cast<U: Real>(self) -> V3<U> {
        V3::new(
            U::from_f64(self.x.to_f64()),
            U::from_f64(self.y.to_f64()),
            U::from_f64(self.z.to_f64()),
        )
    }
    #[inline(always)]
    pub fn dot(self, o: Self) -> T {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    #[inline(always)]
    pub fn cross(self, o: Self) -> Self {
        Self::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    #[inline(always)]
    pub fn length_squared(self) -> T {
        self.dot(self)
    }
    #[inline(always)]
    pub fn length(self) -> T {
        self.dot(self).sqrt()
    }
    /// The unit vector in this direction, or `None` for a zero (or
    /// non-finite) vector.
    #[inline]
    pub fn try_normalize(self) -> Option<Self> {
        let l = self.length();
        if l > T::ZERO && l.is_finite() {
            let inv = T::ONE / l;
            Some(self * inv)
        } else {
            None
        }
    }
    #[inline(always)]
    pub fn scale(self, s: T) -> Self {
        Self::new(self.x * s, self.y * s, self.z * s)
    }
    #[inline(always)]
    pub fn mul_elem(self, o: Self) -> Self {
        Self::new(self.x * o.x, self.y * o.y, self.z * o.z)
    }
    #[inline(always)]
    pub fn min_elem(self, o: Self) -> Self {
        Self::new(self.x.min(o.x), self.y.min(o.y), self.z.min(o.z))
    }
    #[inline(always)]
    pub fn max_elem(self, o: Self) -> Self {
        Self::new(self.x.max(o.x), self.y.max(o.y), self.z.max(o.z))
    }
    #[inline(always)]
    pub fn abs(self) -> Self {
        Self::new(self.x.abs(), self.y.abs(), self.z.abs())
    }
    /// Index (0, 1, 2) of the component of largest magnitude; ties go to the
    /// lower index.
    #[inline(always)]
    pub fn max_axis(self) -> usize {
        let a = self.abs();
        if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        }
    }
    #[inline(always)]
    pub fn to_array(self) -> [T; 3] {
        [self.x, self.y, self.z]
    }
    #[inline(always)]
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }
}

impl<T: Real> Add for V3<T> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl<T: Real> AddAssign for V3<T> {
    #[inline(always)]
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}
impl<T: Real> Sub for V3<T> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Self::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
impl<T: Real> Neg for V3<T> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Self::new(-self.x, -self.y, -self.z)
    }
}
impl<T: Real> Mul<T> for V3<T> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, s: T) -> Self {
        self.scale(s)
    }
}
impl<T: Real> Index<usize> for V3<T> {
    type Output = T;
    #[inline(always)]
    fn index(&self, i: usize) -> &T {
        match i {
            0 => &self.x,
            1 => &self.y,
            2 => &self.z,
            _ => panic!("V3 index {i} out of range"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cross_follows_right_hand_rule() {
        let x = V3::new(1.0, 0.0, 0.0);
        let y = V3::new(0.0, 1.0, 0.0);
        assert_eq!(x.cross(y), V3::new(0.0, 0.0, 1.0));
    }

    #[test]
    fn normalize_rejects_zero() {
        assert!(V3::<f64>::zero().try_normalize().is_none());
        let n = V3::new(3.0f64, 0.0, 4.0).try_normalize().unwrap();
        assert!((n.length() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn max_axis_prefers_lower_index_on_ties() {
        assert_eq!(V3::new(1.0f64, -1.0, 0.5).max_axis(), 0);
        assert_eq!(V3::new(0.0f64, -2.0, 2.0).max_axis(), 1);
        assert_eq!(V3::new(0.0f64, 0.0, -3.0).max_axis(), 2);
    }
}

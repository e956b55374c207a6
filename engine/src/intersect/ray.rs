use crate::math::{Real, V3};

/// A ray prepared for intersection tests: origin, direction, and the
/// shear constants of the watertight triangle test (Woop, Benthin and Wald,
/// "Watertight Ray/Triangle Intersection", JCGT 2013).
#[derive(Clone, Copy, Debug)]
pub struct RayQ<R> {
    pub o: V3<R>,
    pub d: V3<R>,
    pub(crate) kx: u8,
    pub(crate) ky: u8,
    pub(crate) kz: u8,
    pub(crate) sx: R,
    pub(crate) sy: R,
    /// 1 / d per axis (infinite where d is 0), for box tests.
    pub(crate) inv: V3<R>,
    /// d . d and its reciprocal.
    pub(crate) a: R,
    pub(crate) inv_a: R,
}

impl<R: Real> RayQ<R> {
    /// `d` must be non-zero (it need not be unit length).
    #[inline]
    pub fn new(o: V3<R>, d: V3<R>) -> Self {
        let inv = V3::new(R::ONE / d.x, R::ONE / d.y, R::ONE / d.z);
        Self::with_inverse(o, d, inv)
    }

    /// As [`RayQ::new`], given `inv` = 1/d per axis (which the caller may
    /// already have for its grid walk).
    #[inline]
    pub fn with_inverse(o: V3<R>, d: V3<R>, inv: V3<R>) -> Self {
        let kz = d.max_axis();
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < R::ZERO {
            std::mem::swap(&mut kx, &mut ky);
        }
        let sz = inv[kz];
        let a = d.dot(d);
        RayQ {
            o,
            d,
            kx: kx as u8,
            ky: ky as u8,
            kz: kz as u8,
            sx: d[kx] * sz,
            sy: d[ky] * sz,
            inv,
            a,
            inv_a: R::ONE / a,
        }
    }

    /// The watertight test's third shear constant, `1 / d[kz]`: the
    /// reciprocal along the axis of the largest component, which `inv`
    /// holds already (a ray slot of the breadth-first tracer is 8 bytes
    /// smaller for not keeping it twice).
    #[inline(always)]
    pub(crate) fn sz(&self) -> R {
        self.inv[self.kz as usize]
    }

    /// A ray given in the renderer's `f64` vectors.
    #[inline]
    pub fn from_vec3(o: crate::math::Vec3, d: crate::math::Vec3) -> Self {
        use crate::math::Vec3Ext;
        Self::new(o.cast(), d.cast())
    }

    /// The same ray in another precision.
    pub fn cast<S: Real>(&self) -> RayQ<S> {
        RayQ::new(self.o.cast(), self.d.cast())
    }

    #[inline]
    pub fn at(&self, t: R) -> V3<R> {
        self.o + self.d * t
    }

    /// Whether the ray may meet the box within `(t_min, t_max)`. Never
    /// rejects a box the ray touches: the interval is widened by a few ulps
    /// of the distances involved.
    #[inline(always)]
    pub fn may_hit_box(&self, b: &crate::math::Aabb, t_min: R, t_max: R) -> bool {
        let (mut t0, mut t1) = (t_min, t_max);
        for i in 0..3 {
            let (lo, hi) = (R::from_f32(b.min[i]), R::from_f32(b.max[i]));
            let o = self.o[i];
            if self.d[i] == R::ZERO {
                if o < lo || o > hi {
                    return false;
                }
                continue;
            }
            let inv = self.inv[i];
            let (mut a, mut z) = ((lo - o) * inv, (hi - o) * inv);
            if a > z {
                std::mem::swap(&mut a, &mut z);
            }
            // The kernels' product (`kernels::boxes::may_hit_box`): one
            // rounding, by a constant, so both give the same bits even
            // where the larger distance times `EPSILON` would be
            // subnormal.
            let slack = a.abs().max(z.abs()) * (R::EPSILON * R::from_f32(16.0));
            t0 = t0.max(a - slack);
            t1 = t1.min(z + slack);
            if t0 > t1 {
                return false;
            }
        }
        true
    }
}

/// A ray as a placed model's walk and tests take it: prepared for the
/// tests in their precision (`q`), with its origin and direction as given
/// in `f64` (a model's grid is walked in `f64`, whatever the tests'
/// precision), and the open interval `t_min < t < t_max` of distances
/// that count.
#[derive(Clone, Copy, Debug)]
pub struct Ray<'q, R> {
    pub q: &'q RayQ<R>,
    pub o: crate::math::Vec3,
    pub d: crate::math::Vec3,
    pub t_min: R,
    pub t_max: R,
}

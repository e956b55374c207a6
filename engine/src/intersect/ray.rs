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
    pub(crate) sz: R,
}

impl<R: Real> RayQ<R> {
    /// `d` must be non-zero (it need not be unit length).
    #[inline]
    pub fn new(o: V3<R>, d: V3<R>) -> Self {
        let kz = d.max_axis();
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < R::ZERO {
            std::mem::swap(&mut kx, &mut ky);
        }
        let dz = d[kz];
        RayQ {
            o,
            d,
            kx: kx as u8,
            ky: ky as u8,
            kz: kz as u8,
            sx: d[kx] / dz,
            sy: d[ky] / dz,
            sz: R::ONE / dz,
        }
    }

    /// The same ray in another precision.
    pub fn cast<S: Real>(&self) -> RayQ<S> {
        RayQ::new(self.o.cast(), self.d.cast())
    }

    #[inline]
    pub fn at(&self, t: R) -> V3<R> {
        self.o + self.d * t
    }
}

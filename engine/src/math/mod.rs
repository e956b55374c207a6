//! Scalar and vector arithmetic shared by every part of the renderer.
//!
//! Rays, cameras, shading and grids work in `f64` with glam's [`Vec3`]
//! (`DVec3`, scalar code: the same bits on every target). The intersection
//! tests are written once for both precisions, over [`Real`], so that the
//! same routine runs in single or double precision (one of the
//! speed/accuracy knobs); glam has no vector type generic over `f32` and
//! `f64`, so they use the thin [`V3`] here, whose every operation is
//! written out in the same order as glam's. The object database itself
//! always stores `f32`.

mod aabb;
mod real;
mod vec3;

pub use aabb::Aabb;
pub(crate) use aabb::{f32_down, f32_up};
pub use real::Real;
pub use vec3::V3;

/// A 3-vector of `f64`, the precision rays and shading are carried in.
pub use glam::DVec3 as Vec3;

/// What the renderer needs of [`Vec3`] beyond glam.
pub trait Vec3Ext {
    /// From the `f32` coordinates of the object database.
    fn from_f32(a: [f32; 3]) -> Self;
    /// In the precision of an intersection test.
    fn cast<R: Real>(self) -> V3<R>;
    /// Index (0, 1, 2) of the component of largest magnitude; ties go to
    /// the lower index.
    fn max_axis(self) -> usize;
}

impl Vec3Ext for Vec3 {
    #[inline(always)]
    fn from_f32(a: [f32; 3]) -> Self {
        Vec3::new(a[0] as f64, a[1] as f64, a[2] as f64)
    }
    #[inline(always)]
    fn cast<R: Real>(self) -> V3<R> {
        V3::new(
            R::from_f64(self.x),
            R::from_f64(self.y),
            R::from_f64(self.z),
        )
    }
    #[inline(always)]
    fn max_axis(self) -> usize {
        V3::new(self.x, self.y, self.z).max_axis()
    }
}

impl From<V3<f64>> for Vec3 {
    #[inline(always)]
    fn from(v: V3<f64>) -> Vec3 {
        Vec3::new(v.x, v.y, v.z)
    }
}

impl From<Vec3> for V3<f64> {
    #[inline(always)]
    fn from(v: Vec3) -> V3<f64> {
        V3::new(v.x, v.y, v.z)
    }
}

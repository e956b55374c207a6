//! Scalar and vector arithmetic shared by every part of the renderer.
//!
//! Intersection code is generic over [`Real`] so that the same routine can be
//! run in single or double precision (one of the speed/accuracy knobs); the
//! object database itself always stores `f32`.

mod real;
mod vec3;

pub use real::Real;
pub use vec3::V3;

/// A 3-vector of `f64`, the precision rays and shading are carried in.
pub type Vec3 = V3<f64>;

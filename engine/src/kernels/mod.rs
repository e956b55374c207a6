//! Intersection kernels: one primitive tested against a group of rays at
//! once, a SIMD vector of lanes at a time.
//!
//! Both tracers hold rays in groups ([`RayLanes`], one array per
//! coordinate): a depth-first packet, or (breadth-first) the rays a voxel
//! lists. A kernel takes one primitive, the group and a mask of the lanes
//! to test, and returns the lanes it hits with their distances. Each
//! lane's result is bit for bit the scalar test's of the primitive's kind
//! ([`crate::shapes`]): the same operations in the same order, on any of
//! the instruction sets of [`crate::simd`], which is what lets the
//! kernels replace the scalar tests without changing an image.
//!
//! - [`Triangle`]: the watertight triangle test (triangles, and the
//!   triangles of patches and placed models);
//! - [`SphereLanes`]: spheres;
//! - [`PlaneLanes`] and [`Crossings`]: polygons of four or more vertices;
//! - [`ConeLanes`]: cones and cylinders;
//! - [`BoxLanes`]: the conservative box test of a traversal, and
//!   [`MayHitBox`], the exact box pre-test of polygons and cones.
//!
//! Run a kernel with [`crate::simd::Isa::run`].

mod boxes;
mod cone;
mod polygon;
mod rays;
mod sphere;
mod triangle;

pub use boxes::{BoxLanes, MayHitBox, widen};
pub use cone::ConeLanes;
pub use polygon::{Crossings, PlaneLanes};
pub use rays::{LANES, Lanes, RayLanes, each_lane};
pub use sphere::SphereLanes;
pub use triangle::Triangle;

use crate::simd::Float;

/// The low `N` bits: one vector's lanes.
#[inline(always)]
pub(crate) fn lane_mask<V: Float>() -> u64 {
    (1u64 << V::N) - 1
}

/// The vectors of lanes a kernel visits for the lanes `m`: the first lane
/// of each vector holding one of them, and those lanes' bits (relative
/// to it).
#[inline(always)]
pub(crate) fn chunks<V: Float>(m: Lanes) -> impl Iterator<Item = (usize, u64)> {
    let end = (u64::BITS - m.leading_zeros()) as usize;
    let lm = lane_mask::<V>();
    (0..end)
        .step_by(V::N)
        .map(move |c| (c, (m >> c) & lm))
        .filter(|&(_, b)| b != 0)
}

#[cfg(test)]
mod tests;

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
//! - [`Triangle`], the watertight triangle test (triangles, and the
//!   triangles of patches and placed models);
//! - [`SphereLanes`] for spheres;
//! - [`PlaneLanes`] and [`Crossings`] for polygons of four or more
//!   vertices;
//! - [`ConeLanes`] for cones and cylinders;
//! - [`BoxLanes`], the conservative box test of a traversal, and
//!   [`MayHitBox`], the exact box pre-test of polygons and cones;
//! - [`shape_lanes`], the kernel of an object's kind, for either tracer;
//! - and the other way round, [`RayTriangles`]: one ray against a batch
//!   of triangles, for the few rays of a depth-first packet that reach a
//!   voxel listing many.
//!
//! Run a kernel with [`crate::simd::Isa::run`].

mod batch;
mod boxes;
mod cone;
mod polygon;
mod rays;
mod shape;
mod sphere;
mod triangle;

pub use batch::{BATCH, RayTriangles, TriangleBatch};
pub use boxes::{BoxLanes, MayHitBox, widen};
pub use cone::ConeLanes;
pub use polygon::{Crossings, PlaneLanes};
pub use rays::{CHUNK, LANES, Lanes, Need, RayLanes, each_lane};
pub(crate) use shape::on_plane;
pub use shape::{Found, ShapeLanes, shape_lanes};
pub use sphere::SphereLanes;
pub use triangle::Triangle;

use crate::simd::Float;

/// The low `N` bits: one vector's lanes.
#[inline(always)]
pub(crate) fn lane_mask<V: Float>() -> u64 {
    (1u64 << V::N) - 1
}

/// Runs `$body` for each vector of lanes holding a lane of `$m`, with
/// `$c` the vector's first lane and `$bits` those lanes (relative to
/// `$c`).
///
/// A macro, not an iterator or a closure: the kernels are inlined into a
/// function compiled for their instruction set, and a closure or an
/// iterator adapter that the compiler left out of line would be compiled
/// without it, its vector operations turned into calls. For the same
/// reason the kernels use `#[inline(always)]` helpers and plain loops,
/// never `array::map` or closures, around vector code.
macro_rules! for_chunks {
    ($V:ty, $m:expr, |$c:ident, $bits:ident| $body:block) => {{
        let n = <$V as $crate::simd::Float>::N;
        let lm = $crate::kernels::lane_mask::<$V>();
        let m: u64 = $m;
        // Straight to the next vector holding a lane of `m`.
        let mut rest = m;
        while rest != 0 {
            let $c = rest.trailing_zeros() as usize / n * n;
            let $bits = (m >> $c) & lm;
            rest &= !(lm << $c);
            $body
        }
    }};
}
pub(crate) use for_chunks;

/// The lanes from `c` of a per-lane array.
#[inline(always)]
pub(crate) fn ld<V: Float>(a: &[V::Elem; LANES], c: usize) -> V {
    V::load(&a[c..c + V::N])
}

/// A point's coordinates, each in every lane.
#[inline(always)]
pub(crate) fn splat3<V: Float>(p: [V::Elem; 3]) -> [V; 3] {
    [V::splat(p[0]), V::splat(p[1]), V::splat(p[2])]
}

/// `p . q`, summed in the order of [`crate::math::V3::dot`].
#[inline(always)]
pub(crate) fn dot3<V: Float>(p: &[V; 3], q: &[V; 3]) -> V {
    p[0] * q[0] + p[1] * q[1] + p[2] * q[2]
}

/// `p - q`.
#[inline(always)]
pub(crate) fn sub3<V: Float>(p: &[V; 3], q: &[V; 3]) -> [V; 3] {
    [p[0] - q[0], p[1] - q[1], p[2] - q[2]]
}

/// `p - q s`, as `V3`'s `p - q * s`.
#[inline(always)]
pub(crate) fn sub_scaled3<V: Float>(p: &[V; 3], q: &[V; 3], s: V) -> [V; 3] {
    [p[0] - q[0] * s, p[1] - q[1] * s, p[2] - q[2] * s]
}

/// A group's coordinate arrays from lane `c`.
#[inline(always)]
pub(crate) fn ld3<V: Float>(a: &[[V::Elem; LANES]; 3], c: usize) -> [V; 3] {
    [ld(&a[0], c), ld(&a[1], c), ld(&a[2], c)]
}

/// `f32` data in the precision of the lanes.
#[inline(always)]
pub(crate) fn of_f32<R: crate::math::Real>(p: [f32; 3]) -> [R; 3] {
    [R::from_f32(p[0]), R::from_f32(p[1]), R::from_f32(p[2])]
}

/// `f64` data in the precision of the lanes.
#[inline(always)]
pub(crate) fn of_f64<R: crate::math::Real>(p: [f64; 3]) -> [R; 3] {
    [R::from_f64(p[0]), R::from_f64(p[1]), R::from_f64(p[2])]
}

#[cfg(test)]
mod tests;

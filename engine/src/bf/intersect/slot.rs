//! A ray slot: what the breadth-first tracer holds of each ray in
//! memory while it is traced, split by who reads it (the scan's hot part,
//! registration's and completion's cold part), and the bytes it takes.

use super::Pending;
use crate::hit::{Hit, PrimId};
use crate::intersect::RayQ;
use crate::math::Vec3;
use crate::simd::Elem;

/// Grids a ray can walk (the main grid, and dense regions or the huge
/// objects' grid: see [`crate::grid::MAX_GROUPS`]).
pub const MAX_GRIDS: usize = crate::grid::MAX_GROUPS;
pub(super) const NONE16: u16 = u16::MAX;

pub(super) const FRESH: u8 = 0;
pub(super) const WALKING: u8 = 1;
pub(super) const DONE: u8 = 2;
/// A carried material that asks for the shading join instead (the
/// surface has attributes, which slots do not keep).
pub(super) const JOIN: u32 = u32::MAX;

/// A ray's walk through one grid, in 8 bytes. Its 3D-DDA state is not
/// kept: a walk that will go on stopped in the voxel it last stored the ray
/// in (it stops when the ray's store number is used up), and the walk from
/// the ray's start to that voxel gives the state bit for bit again
/// ([`crate::grid::Dda::start_at`]). Kept, the state took 40 bytes a grid.
#[derive(Clone, Copy, Debug)]
pub(super) struct Walk {
    /// The last voxel stored in (`NONE16` in [0] when none yet); while
    /// `WALKING`, the voxel the walk stopped in.
    pub(super) last: [u16; 3],
    pub(super) state: u8,
    /// Passes in which this walk registered.
    pub(super) k: u8,
}

pub(super) const NEW_WALK: Walk = Walk {
    last: [NONE16; 3],
    state: FRESH,
    k: 0,
};

/// What the scan reads for every registration it visits: small, and kept
/// apart from the rest of the ray so that visits stay in cache.
#[derive(Clone, Copy, Debug)]
pub(super) struct Hot<R> {
    /// The last primitive tested (the paper's mailbox).
    pub(super) mailbox: PrimId,
    pub(super) best: Hit,
    /// Tests must find a hit below this: just above the best distance, so
    /// that an exact tie is seen and goes to the smaller id.
    pub(super) upper: R,
    pub(super) t_min: R,
    /// Per grid, the last voxel stored in during the previous pass
    /// (`NONE16` in [0] when none): the last-voxel rule's voxel.
    pub(super) prev: [[u16; 3]; MAX_GRIDS],
    pub(super) active: bool,
    pub(super) shadow: bool,
    pub(super) blocked: bool,
}

/// The rest of a ray in memory: what registration and completion need.
/// The ray itself is the slot's [`RayQ`], in the tests' precision; in
/// `f64` that is the ray as given, and nothing else is kept of it (`o`,
/// `d` and `t_min` take no room); in `f32` they keep the `f64` values the
/// walks need (see [`ray64`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct Cold<R: Elem> {
    pub(super) id: u64,
    pub(super) t_max: f64,
    pub(super) o: [R::Kept; 3],
    pub(super) d: [R::Kept; 3],
    pub(super) t_min: R::Kept,
    /// The surface at the best hit so far, when surfaces are carried.
    pub(super) ng: Vec3,
    pub(super) ns: Vec3,
    pub(super) material: u32,
    /// The input id of the best hit's object, which decides ties.
    pub(super) rank: u32,
    pub(super) walks: [Walk; MAX_GRIDS],
}

pub(super) fn empty_hot<R: Elem>() -> Hot<R> {
    Hot {
        mailbox: PrimId::NONE,
        best: Hit::NONE,
        upper: R::INFINITY,
        t_min: R::ZERO,
        prev: [[NONE16; 3]; MAX_GRIDS],
        active: false,
        shadow: false,
        blocked: false,
    }
}

pub(super) fn empty_cold<R: Elem>() -> Cold<R> {
    Cold {
        walks: [NEW_WALK; MAX_GRIDS],
        id: 0,
        t_max: f64::INFINITY,
        o: [R::keep(0.0); 3],
        d: [R::keep(1.0), R::keep(0.0), R::keep(0.0)],
        t_min: R::keep(0.0),
        ng: Vec3::ZERO,
        ns: Vec3::ZERO,
        material: 0,
        rank: 0,
    }
}

/// A slot's ray in `f64`, as its walks take it: exactly the values
/// [`super::load`] worked out from the ray given.
#[derive(Clone, Copy, Debug)]
pub(super) struct Ray64 {
    pub(super) o: Vec3,
    pub(super) d: Vec3,
    pub(super) inv: Vec3,
    pub(super) t_min: f64,
    pub(super) t_max: f64,
}

/// The origin and direction of a slot's ray in `f64`.
#[inline(always)]
pub(super) fn od64<R: Elem>(q: &RayQ<R>, c: &Cold<R>) -> (Vec3, Vec3) {
    (
        Vec3::new(
            q.o.x.unround(|| c.o[0]),
            q.o.y.unround(|| c.o[1]),
            q.o.z.unround(|| c.o[2]),
        ),
        Vec3::new(
            q.d.x.unround(|| c.d[0]),
            q.d.y.unround(|| c.d[1]),
            q.d.z.unround(|| c.d[2]),
        ),
    )
}

/// A slot's ray in `f64` (see [`Ray64`]). In `f64`, copies of the slot's
/// [`RayQ`] and [`Hot`] values, which [`super::load`] made from the same
/// values; in `f32`, the kept values, with `1 / d` worked out as `load`
/// did (the same operations give the same bits).
#[inline(always)]
pub(super) fn ray64<R: Elem>(q: &RayQ<R>, h: &Hot<R>, c: &Cold<R>) -> Ray64 {
    let (o, d) = od64(q, c);
    Ray64 {
        o,
        d,
        inv: Vec3::new(
            q.inv.x.unround(|| R::keep(1.0 / d.x)),
            q.inv.y.unround(|| R::keep(1.0 / d.y)),
            q.inv.z.unround(|| R::keep(1.0 / d.z)),
        ),
        t_min: h.t_min.unround(|| c.t_min),
        t_max: c.t_max,
    }
}

/// Bytes one ray slot takes (with its place in the queue of rays loaded
/// in parallel, see [`super::Shard::pending`], and among the pass's
/// finished rays).
pub fn slot_bytes<R: Elem>() -> usize {
    std::mem::size_of::<Hot<R>>()
        + std::mem::size_of::<Cold<R>>()
        + std::mem::size_of::<RayQ<R>>()
        // Its place in the queue, or the id it was admitted by.
        + std::mem::size_of::<Pending>().max(std::mem::size_of::<u64>())
        // Its place among the pass's finished rays.
        + std::mem::size_of::<u32>()
}

/// Bytes of a slot's place in the queue of streamed rays (see
/// [`super::Shard::pending`]) beyond what a ray admitted by id takes instead (its
/// id): what a slot saves when its rays can be had by id and its results
/// have their places.
pub fn streamed_extra_bytes() -> usize {
    std::mem::size_of::<Pending>().saturating_sub(std::mem::size_of::<u64>())
}

pub use crate::bf::regmap::{REGISTRATION_BYTES, VOXEL_BYTES, WORST_REGISTRATION_BYTES};

#[cfg(test)]
mod tests {
    use super::*;

    /// The parts of a slot, printed (`--nocapture`) to see what a slot
    /// spends its bytes on; and the slot of the `f64` tracer kept small.
    #[test]
    fn slot_parts() {
        use std::mem::size_of;
        for (name, hot, q, cold, total) in [
            (
                "f64",
                size_of::<Hot<f64>>(),
                size_of::<RayQ<f64>>(),
                size_of::<Cold<f64>>(),
                slot_bytes::<f64>(),
            ),
            (
                "f32",
                size_of::<Hot<f32>>(),
                size_of::<RayQ<f32>>(),
                size_of::<Cold<f32>>(),
                slot_bytes::<f32>(),
            ),
        ] {
            println!(
                "{name}: Hot {hot}, RayQ {q}, Cold {cold} (Walk {} x {MAX_GRIDS}), Pending {}: slot {total}",
                size_of::<Walk>(),
                size_of::<Pending>(),
            );
        }
        assert!(slot_bytes::<f64>() <= 288, "{}", slot_bytes::<f64>());
    }
}

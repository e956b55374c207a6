//! The records the breadth-first tracer keeps on disk: rays, and the
//! result of intersecting each ray.

use crate::hit::PrimId;
use bytemuck::{Pod, Zeroable};

/// What a ray is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum RayKind {
    Eye = 0,
    Reflect = 1,
    Refract = 2,
    Shadow = 3,
}

impl RayKind {
    pub fn from_u8(v: u8) -> RayKind {
        match v {
            0 => RayKind::Eye,
            1 => RayKind::Reflect,
            2 => RayKind::Refract,
            _ => RayKind::Shadow,
        }
    }
}

/// One ray of a round. In a round's ray file, rays are in id order and a
/// ray's id is its position.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct RayRec {
    pub o: [f64; 3],
    /// Unit direction.
    pub d: [f64; 3],
    /// Hits count only closer than this (a shadow ray's light distance).
    pub t_max: f64,
    /// Order among the rays of the next round: spawning ray's id times
    /// `SPAWN_SLOTS` plus the spawn index (shadow rays in light order, then
    /// reflection, then refraction).
    pub key: u64,
    /// Shadow rays: the colour the light adds if nothing blocks it; other
    /// rays: the ray's weight in [0].
    pub payload: [f32; 3],
    /// Pixel corner the ray's colour goes to.
    pub corner: u32,
    /// Depth in the ray tree (eye ray = 1); for a shadow ray, the depth of
    /// the hit that spawned it.
    pub depth: u8,
    pub kind: u8,
    pub _pad: [u8; 6],
}

/// Spawn indices per ray: one per light, then reflection and refraction.
pub const SPAWN_SLOTS: u64 = (crate::sdb::MAX_LIGHTS as u64) + 2;

impl RayRec {
    pub fn kind(&self) -> RayKind {
        RayKind::from_u8(self.kind)
    }
    pub fn is_shadow(&self) -> bool {
        self.kind == RayKind::Shadow as u8
    }
}

/// The outcome of intersecting ray `ray`: the nearest primitive and its
/// distance, or for a shadow ray the first blocker found; `PrimId::NONE`
/// for a miss or an unblocked shadow ray.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct ResultRec {
    pub ray: u64,
    pub prim: PrimId,
    pub t: f64,
}

/// A ray and its hit, as the shading join sorts them (by object).
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct HitRec {
    pub ray: RayRec,
    pub id: u64,
    pub t: f64,
    pub prim: PrimId,
}

/// Colour added to a pixel corner (fixed point), as cluster workers return
/// it from shading.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
#[repr(C)]
pub struct Contribution {
    pub corner: u32,
    pub _pad: u32,
    pub rgb: [i64; 3],
}

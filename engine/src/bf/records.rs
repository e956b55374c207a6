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

/// A ray's result as the tracer keeps it: the [`ResultRec`] and, when the
/// surface was worked out where the hit was found (see
/// [`super::Shading::Carry`]), the surface's normals and material, so that
/// shading needs no second pass over the objects. Stripped to the
/// `ResultRec` where results travel (the cluster), where shading joins.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct Outcome {
    pub res: ResultRec,
    /// Geometric and shading normals at the hit, as the primitive's
    /// `surface` gives them (unit, not turned toward the ray).
    pub ng: [f64; 3],
    pub ns: [f64; 3],
    pub material: u32,
    /// 1 when `ng`, `ns` and `material` are set.
    pub has_surface: u32,
}

impl Outcome {
    /// A result with no surface carried.
    pub fn bare(res: ResultRec) -> Outcome {
        Outcome {
            res,
            ng: [0.0; 3],
            ns: [0.0; 3],
            material: 0,
            has_surface: 0,
        }
    }
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

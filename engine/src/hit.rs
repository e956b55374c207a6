//! Which primitive a ray hit, and the rule that decides between hits.

use bytemuck::{Pod, Zeroable};
use serde::Serialize;

/// Identifies a primitive for ties, mailboxes and shading: the database
/// object it belongs to (its index there, its position in the scene as
/// read) in the high half, and in the low half 0 for the object itself or
/// `1 + k` for triangle `k` of the model an instance record places. The
/// order of ids is the tie order: by object, then by the model's
/// triangle, which is the order of the copies an instance stands for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Pod, Zeroable, Serialize)]
#[repr(transparent)]
pub struct PrimId(pub u64);

impl PrimId {
    /// No primitive: a miss, or an unblocked shadow ray.
    pub const NONE: PrimId = PrimId(u64::MAX);

    /// Object `index` of the database.
    #[inline(always)]
    pub const fn object(index: u32) -> PrimId {
        PrimId((index as u64) << 32)
    }

    /// Triangle `prim` of the model placed by instance `index` (the
    /// database's object `index`, an instance record).
    #[inline(always)]
    pub const fn instance(index: u32, prim: u32) -> PrimId {
        PrimId(((index as u64) << 32) | (prim as u64 + 1))
    }

    #[inline(always)]
    pub fn is_none(self) -> bool {
        self == PrimId::NONE
    }

    /// The database object the primitive belongs to: the object itself,
    /// or the instance record that places it.
    #[inline(always)]
    pub fn world_index(self) -> u32 {
        (self.0 >> 32) as u32
    }

    /// The database object this primitive is, if it is one.
    #[inline(always)]
    pub fn object_index(self) -> Option<u32> {
        (self.0 as u32 == 0).then_some(self.world_index())
    }

    /// `(instance, primitive)` if this is a triangle of a placed model.
    #[inline(always)]
    pub fn instance_parts(self) -> Option<(u32, u32)> {
        let lo = self.0 as u32;
        (lo != 0 && !self.is_none()).then(|| (self.world_index(), lo - 1))
    }
}

/// A primitive's place in the tie order, its object having input id
/// `rank`: by that id, then by the model's triangle.
#[inline(always)]
pub fn tie_key(rank: u32, prim: PrimId) -> u64 {
    (rank as u64) << 32 | (prim.0 & 0xffff_ffff)
}

/// The nearest hit found so far along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f64,
    pub prim: PrimId,
}

impl Hit {
    pub const NONE: Hit = Hit {
        t: f64::INFINITY,
        prim: PrimId::NONE,
    };

    /// Whether a hit at `t` on `prim` wins over this one: nearer, or as near
    /// and of a smaller id (the rendering contract's tie rule). The one
    /// place the rule is written.
    #[inline(always)]
    pub fn loses_to(&self, t: f64, prim: PrimId) -> bool {
        t < self.t || (t == self.t && prim < self.prim)
    }

    /// As [`Hit::loses_to`], for a database whose objects are not in
    /// input order (version 6): ties go by the objects' input ids, `rank`
    /// for the new hit and `own_rank` for this one, then by the model's
    /// triangle.
    #[inline(always)]
    pub fn loses_to_ranked(&self, own_rank: u32, t: f64, prim: PrimId, rank: u32) -> bool {
        t < self.t || (t == self.t && tie_key(rank, prim) < tie_key(own_rank, self.prim))
    }

    #[inline(always)]
    pub fn is_some(&self) -> bool {
        !self.prim.is_none()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearer_wins_and_ties_go_to_the_smaller_id() {
        let h = Hit {
            t: 2.0,
            prim: PrimId::object(5),
        };
        assert!(h.loses_to(1.0, PrimId::object(9)));
        assert!(h.loses_to(2.0, PrimId::object(4)));
        assert!(!h.loses_to(2.0, PrimId::object(5)));
        assert!(!h.loses_to(2.0, PrimId::object(6)));
        assert!(!h.loses_to(3.0, PrimId::object(0)));
        assert!(Hit::NONE.loses_to(1e300, PrimId::object(u32::MAX)));
        let p = PrimId::instance(7, 3);
        assert_eq!(p.instance_parts(), Some((7, 3)));
        assert_eq!(p.world_index(), 7);
        assert_eq!(p.object_index(), None);
        assert_eq!(PrimId::object(7).instance_parts(), None);
        assert_eq!(PrimId::object(7).object_index(), Some(7));
        assert_eq!(PrimId::NONE.instance_parts(), None);
        assert_eq!(PrimId::NONE.object_index(), None);
        // By object, then by the model's triangle: the copies' order.
        assert!(PrimId::instance(1, 3) < PrimId::instance(9, 2));
        assert!(PrimId::instance(1, 2) < PrimId::instance(1, 3));
        assert!(PrimId::instance(1, u32::MAX - 1) < PrimId::object(2));
        assert!(PrimId::object(0) < PrimId::instance(1, 0));
        assert!(PrimId::instance(u32::MAX - 1, u32::MAX - 1) < PrimId::NONE);
    }
}

//! A block's objects as a scan hands them out: decoded in place from the
//! block's words (no allocation per object), with their bounding boxes
//! readable without decoding their geometry.

use super::format::*;
use crate::hit::PrimId;
use crate::scene::Aabb;
use crate::shapes::{Shape, ShapeKind};

/// One decoded, validated block.
pub struct Block<'a> {
    pub index: u64,
    /// The position in the file of its first object.
    pub first_object: u64,
    pub object_count: u32,
    words: &'a [u32],
    /// Each object's input id (version 6), or empty: the position is the
    /// input id.
    ids: &'a [u32],
}

/// One object of a block, borrowing its geometry from the block buffer.
#[derive(Clone, Copy, Debug)]
pub struct ObjectRef<'a> {
    /// Its position in the database: how tracers, hits and the shading
    /// join name it.
    pub index: u32,
    /// Its id in the input, which decides ties (the same as `index`
    /// unless the database is in spatial order).
    pub rank: u32,
    pub material: u32,
    pub bbox: Aabb,
    pub shape: Shape<'a>,
}

impl<'a> Block<'a> {
    /// The objects of the block, in id order.
    pub fn objects(&self) -> ObjectIter<'a> {
        ObjectIter {
            words: self.words,
            ids: self.ids,
            pos: 0,
            first: self.first_object as u32,
            id: self.first_object as u32,
            left: self.object_count,
        }
    }

    /// Each object's place in the block and its bounding box, without
    /// decoding its geometry: what a scan needs to decide whether to look
    /// closer. [`Block::object_at`] decodes one.
    pub fn boxes(&self) -> BoxIter<'a> {
        BoxIter {
            words: self.words,
            ids: self.ids,
            pos: 0,
            first: self.first_object as u32,
            index: self.first_object as u32,
            left: self.object_count,
        }
    }

    /// The object whose record starts at word `at` (as [`Block::boxes`]
    /// gives it), at position `index`, of input id `rank`.
    #[inline(always)]
    pub fn object_at(&self, at: u32, index: u32, rank: u32) -> Option<ObjectRef<'a>> {
        decode_record(self.words.get(at as usize..)?, index).map(|(mut o, _)| {
            o.rank = rank;
            o
        })
    }

    /// Each object's input id, or empty when it is its position.
    pub fn ids(&self) -> &'a [u32] {
        self.ids
    }

    /// The block's records, as words (see the module documentation).
    pub fn words(&self) -> &'a [u32] {
        self.words
    }

    /// A block from words a [`super::Scan`] has read and checked.
    pub(super) fn from_words(
        index: u64,
        first_object: u64,
        object_count: u32,
        words: &'a [u32],
        ids: &'a [u32],
    ) -> Block<'a> {
        Block {
            index,
            first_object,
            object_count,
            words,
            ids,
        }
    }

    /// Bytes of this block's records (runs expanded).
    pub fn raw_bytes(&self) -> usize {
        self.words.len() * 4
    }
}

/// An object's record position in its block, index and bounding box.
#[derive(Clone, Copy, Debug)]
pub struct BoxRef {
    pub at: u32,
    pub index: u32,
    /// The input id (see [`ObjectRef::rank`]).
    pub rank: u32,
    pub kind: ShapeKind,
    pub bbox: Aabb,
}

impl BoxRef {
    /// A placeholder: no object, an empty box.
    pub const EMPTY: BoxRef = BoxRef {
        at: 0,
        index: 0,
        rank: 0,
        kind: ShapeKind::Sphere,
        bbox: Aabb::EMPTY,
    };
}

pub struct BoxIter<'a> {
    words: &'a [u32],
    ids: &'a [u32],
    pos: usize,
    first: u32,
    index: u32,
    left: u32,
}

/// The input id of the object at position `index` of a block whose first
/// is `first`: from the block's ids, or the position itself.
#[inline(always)]
fn rank(ids: &[u32], first: u32, index: u32) -> u32 {
    match ids.get(index.wrapping_sub(first) as usize) {
        Some(&r) => r,
        None => index,
    }
}

impl Iterator for BoxIter<'_> {
    type Item = BoxRef;

    #[inline]
    fn next(&mut self) -> Option<BoxRef> {
        if self.left == 0 {
            return None;
        }
        // Records were validated when the block was read.
        let w = self.words.get(self.pos..self.pos + RECORD_HEADER_WORDS)?;
        let kind = ShapeKind::from_u8((w[0] & 0xff) as u8)?;
        let len = RECORD_HEADER_WORDS + kind.payload_words(w[0] >> 8)?;
        let f = |i: usize| f32::from_bits(w[i]);
        let r = BoxRef {
            at: self.pos as u32,
            index: self.index,
            rank: rank(self.ids, self.first, self.index),
            kind,
            bbox: Aabb {
                min: [f(2), f(3), f(4)],
                max: [f(5), f(6), f(7)],
            },
        };
        self.pos += len;
        self.index = self.index.wrapping_add(1);
        self.left -= 1;
        Some(r)
    }
}

pub struct ObjectIter<'a> {
    words: &'a [u32],
    ids: &'a [u32],
    pos: usize,
    first: u32,
    id: u32,
    left: u32,
}

impl<'a> Iterator for ObjectIter<'a> {
    type Item = ObjectRef<'a>;

    #[inline]
    fn next(&mut self) -> Option<ObjectRef<'a>> {
        if self.left == 0 {
            return None;
        }
        // Records were validated when the block was read.
        let (mut obj, len) = decode_record(&self.words[self.pos..], self.id)?;
        obj.rank = rank(self.ids, self.first, self.id);
        self.pos += len;
        self.id = self.id.wrapping_add(1);
        self.left -= 1;
        Some(obj)
    }
}

/// Decodes the record at the start of `w` (already validated) as object
/// `id`; returns it and its length in words.
#[inline(always)]
pub(crate) fn decode_record(w: &[u32], index: u32) -> Option<(ObjectRef<'_>, usize)> {
    let head = *w.first()?;
    let kind = ShapeKind::from_u8((head & 0xff) as u8)?;
    let count = head >> 8;
    let len = RECORD_HEADER_WORDS + kind.payload_words(count)?;
    let f: &[f32] = bytemuck::cast_slice(w.get(2..len)?);
    let bbox = Aabb {
        min: [f[0], f[1], f[2]],
        max: [f[3], f[4], f[5]],
    };
    Some((
        ObjectRef {
            index,
            rank: index,
            material: w[1],
            bbox,
            shape: kind.decode(&f[6..], count),
        },
        len,
    ))
}

impl ObjectRef<'_> {
    /// The object's primitive id.
    #[inline(always)]
    pub fn prim(&self) -> PrimId {
        PrimId::object(self.index)
    }

    /// The object's place in the tie order (its input id).
    #[inline(always)]
    pub fn tie(&self) -> PrimId {
        PrimId::object(self.rank)
    }
}

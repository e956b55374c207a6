//! A primitive that owns its geometry: the kind, the record's count field
//! and its geometry words, exactly as the object database stores them.

use super::{GeometryMap, Shape, ShapeKind};

#[derive(Clone, Debug, PartialEq)]
pub struct OwnedShape {
    pub kind: ShapeKind,
    pub count: u32,
    /// The geometry, as `f32` bit patterns.
    pub words: Vec<u32>,
}

impl OwnedShape {
    pub fn from_shape(s: &Shape<'_>) -> OwnedShape {
        let mut words = Vec::new();
        s.encode(&mut words);
        OwnedShape {
            kind: s.kind(),
            count: s.count(),
            words,
        }
    }

    /// The primitive, borrowing this geometry.
    pub fn shape(&self) -> Shape<'_> {
        self.kind
            .decode(bytemuck::cast_slice(&self.words), self.count)
    }

    /// Every number of the geometry, in record order.
    pub fn numbers(&self) -> &[f32] {
        bytemuck::cast_slice(&self.words)
    }

    /// The primitive with its geometry mapped (see [`GeometryMap`]).
    pub fn mapped(&self, m: &GeometryMap<'_>) -> OwnedShape {
        let mut words = Vec::with_capacity(self.words.len());
        self.shape().map(m, &mut words);
        OwnedShape {
            kind: self.kind,
            count: self.count,
            words,
        }
    }
}

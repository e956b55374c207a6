//! Instances: a model of the database placed by an affine transform.
//!
//! A model (a set of triangles stored once, in its own section of the
//! database) may be placed many times; each placement is one record of
//! this kind. The record holds the model's index, the model's own box and
//! the transform, so that its bounds need nothing else. The tracers find
//! an instance's hits through its model ([`crate::models`]): the kind's
//! own test finds nothing.

use super::{GeometryMap, Kind};
use crate::intersect::{RayQ, Surface};
use crate::math::Real;
use crate::math::Aabb;
use crate::math::{f32_down, f32_up};
use glam::{DAffine3, DVec3};

/// Record words: the model's index, its box (6), the transform's twelve
/// `f64` (columns of the linear part, then the translation), two words
/// each, low first.
const WORDS: usize = 1 + 6 + 24;

/// An instance record, borrowing its words.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance<'a> {
    pub words: &'a [f32],
}

impl Instance<'_> {
    /// The model it places.
    #[inline]
    pub fn model(&self) -> u32 {
        self.words[0].to_bits()
    }

    /// The model's own box, in its coordinates.
    pub fn model_box(&self) -> Aabb {
        Aabb {
            min: [self.words[1], self.words[2], self.words[3]],
            max: [self.words[4], self.words[5], self.words[6]],
        }
    }

    /// The transform from the model's coordinates to the database's.
    pub fn transform(&self) -> DAffine3 {
        let m: [f64; 12] = std::array::from_fn(|i| {
            let lo = self.words[7 + 2 * i].to_bits() as u64;
            let hi = self.words[8 + 2 * i].to_bits() as u64;
            f64::from_bits(lo | hi << 32)
        });
        DAffine3::from_cols_array(&m)
    }
}

/// The words of an instance of `model` (whose box is `model_box`) placed
/// by `m`.
pub fn instance_words(model: u32, model_box: &Aabb, m: &DAffine3) -> Vec<f32> {
    let mut w = Vec::with_capacity(WORDS);
    w.push(f32::from_bits(model));
    w.extend(model_box.min);
    w.extend(model_box.max);
    for x in m.to_cols_array() {
        let b = x.to_bits();
        w.push(f32::from_bits(b as u32));
        w.push(f32::from_bits((b >> 32) as u32));
    }
    w
}

/// The box of `model_box` placed by `m`, rounded outward to `f32` with a
/// margin for the rounding of the placement itself (every placed vertex,
/// `f32` of the `f64` product, lies inside).
pub fn placed_box(model_box: &Aabb, m: &DAffine3) -> Aabb {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for k in 0..8 {
        let c = DVec3::new(
            if k & 1 == 0 { model_box.min[0] } else { model_box.max[0] } as f64,
            if k & 2 == 0 { model_box.min[1] } else { model_box.max[1] } as f64,
            if k & 4 == 0 { model_box.min[2] } else { model_box.max[2] } as f64,
        );
        let p = m.transform_point3(c);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let mut b = Aabb::EMPTY;
    for i in 0..3 {
        let pad = 1e-12 * lo[i].abs().max(hi[i].abs());
        b.min[i] = f32_down(lo[i] - pad);
        b.max[i] = f32_up(hi[i] + pad);
    }
    b
}

pub struct InstanceKind;

impl Kind for InstanceKind {
    type Shape<'a> = Instance<'a>;
    type Prep = ();
    const NAME: &'static str = "instance";

    fn payload_words(count: u32) -> Option<usize> {
        (count == 0).then_some(WORDS)
    }

    fn count(_: &Instance<'_>) -> u32 {
        0
    }

    #[inline(always)]
    fn decode(g: &[f32], _: u32) -> Instance<'_> {
        Instance {
            words: &g[..WORDS],
        }
    }

    fn encode(s: &Instance<'_>, out: &mut Vec<u32>) {
        out.extend(s.words.iter().map(|f| f.to_bits()));
    }

    fn validate(s: &Instance<'_>) -> Result<(), String> {
        let b = s.model_box();
        if !b.min.iter().chain(&b.max).all(|c| c.is_finite()) || (0..3).any(|i| b.min[i] > b.max[i])
        {
            return Err("instance has a malformed model box".into());
        }
        let m = s.transform();
        if !m.to_cols_array().iter().all(|c| c.is_finite()) {
            return Err("instance transform has a non-finite number".into());
        }
        let det = m.matrix3.determinant();
        if !(det.is_finite() && det != 0.0 && m.inverse().is_finite()) {
            return Err("instance transform cannot be inverted".into());
        }
        let placed = placed_box(&b, &m);
        if !placed.min.iter().chain(&placed.max).all(|c| c.is_finite()) {
            return Err("instance lies beyond single precision once placed".into());
        }
        Ok(())
    }

    fn bounds(s: &Instance<'_>) -> Aabb {
        placed_box(&s.model_box(), &s.transform())
    }

    fn prepare(_: &Instance<'_>) -> Option<()> {
        None
    }

    /// Instances are tested through their models ([`crate::models`]),
    /// which this record does not hold: alone it is never hit.
    fn intersect<R: Real>(
        _: &Instance<'_>,
        _: Option<&()>,
        _: &Aabb,
        _: &RayQ<R>,
        _: R,
        _: R,
    ) -> Option<R> {
        None
    }

    /// Never called for a hit (an instance's hits are its model's
    /// primitives); the direction back to the ray's origin.
    fn surface(_: &Instance<'_>, ray: &RayQ<f64>, t: f64) -> Surface {
        let ng = Surface::unit_or_facing(crate::math::Vec3::ZERO, ray);
        Surface {
            p: ray.at(t).into(),
            ng,
            ns: ng,
            attrs: crate::intersect::Attrs::NONE,
        }
    }

    /// An affine map of the scene (a scale and a shift, as the mappings
    /// of [`GeometryMap`] are): the translation is mapped as a point and
    /// the linear part scaled as lengths are.
    fn map(s: &Instance<'_>, m: &GeometryMap<'_>, out: &mut Vec<u32>) {
        let t = s.transform();
        let k = (m.length)(1.0) as f64;
        let at = (m.point)(t.translation.to_array().map(|c| c as f32));
        let mapped = DAffine3 {
            matrix3: t.matrix3 * k,
            translation: DVec3::from(at.map(f64::from)),
        };
        let w = instance_words(s.model(), &s.model_box(), &mapped);
        out.extend(w.iter().map(|f| f.to_bits()));
    }

    fn triangles(_: &Instance<'_>) -> u64 {
        0
    }
}

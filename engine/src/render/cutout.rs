//! Alpha-mask cut-outs (glTF's `alphaMode: MASK`): a textured triangle of
//! a masked material is not there where its alpha, the base colour
//! factor's times the texture's times the vertex colour's, is below the
//! material's cut-off. Leaves and fences are quads with such textures: a
//! ray (eye, reflected or shadow) passes through the holes.
//!
//! The test is part of the intersection test, so both tracers make it at
//! every hit they find on such a triangle, from the same numbers: the
//! barycentric weights of the ray in the test's precision (the same ray
//! in both tracers), the corners' texture coordinates and colours, and
//! the texture sampled as shading samples it. A hit it rejects is no hit:
//! the walk goes on to what lies behind.

use crate::intersect::{RayQ, triangle};
use crate::math::Real;
use crate::scene::{Material, TextureBinding};
use crate::shapes::{Shape, unpack_color};
use crate::texture::Texture;
use std::sync::Arc;

/// The masked materials of a render's material table, with the images.
#[derive(Debug)]
pub struct Cutouts {
    /// By material index: the binding of a masked material.
    masks: Vec<Option<TextureBinding>>,
    textures: Arc<[Texture]>,
}

impl Cutouts {
    /// The cut-outs of `materials` (the render's table: the world's, then
    /// the models'), or `None` when no material is masked (every test is
    /// then the plain one).
    pub fn new(materials: &[Material], textures: Arc<[Texture]>) -> Option<Arc<Cutouts>> {
        let masks: Vec<Option<TextureBinding>> = materials
            .iter()
            .map(|m| m.texture.filter(|t| t.cutoff > 0.0))
            .collect();
        masks
            .iter()
            .any(Option::is_some)
            .then(|| Arc::new(Cutouts { masks, textures }))
    }

    /// Whether `shape` (of material `material`) is there where `ray`
    /// meets it: anything but a masked textured triangle always is.
    #[inline]
    pub fn keeps<R: Real>(&self, shape: &Shape<'_>, material: u32, ray: &RayQ<R>) -> bool {
        let Shape::Textured(t) = shape else {
            return true;
        };
        let Some(Some(b)) = self.masks.get(material as usize) else {
            return true;
        };
        let v = t.vertices;
        let w = triangle::weights(v[0], v[1], v[2], ray).map(|x| x.to_f64());
        let mix =
            |a: f32, b: f32, c: f32| (a as f64 * w[0] + b as f64 * w[1] + c as f64 * w[2]) as f32;
        let mut alpha = b.alpha;
        if let [a, bb, c] = t.uvs {
            let uv = [mix(a[0], bb[0], c[0]), mix(a[1], bb[1], c[1])];
            if let Some(tex) = self.textures.get(b.image as usize) {
                alpha *= tex.sample(&b.sampler, b.transform.apply(uv))[3];
            }
        }
        if let [a, bb, c] = t.colors {
            alpha *= mix(
                unpack_color(*a)[3],
                unpack_color(*bb)[3],
                unpack_color(*c)[3],
            );
        }
        alpha >= b.cutoff
    }
}

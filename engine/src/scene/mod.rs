//! The scene model: what a scene holds besides its objects (view, lights,
//! materials, background), and the [`SceneSink`] that scene sources (the
//! scene readers, the SPD generators) stream into. The objects themselves
//! are [`crate::shapes`].

pub(crate) mod density;
pub mod recorder;
pub mod setup;
mod sink;
mod sizes;

/// Bounding boxes live with the arithmetic ([`crate::math::Aabb`]);
/// re-exported here, where scenes are described.
pub use crate::math::Aabb;
pub use density::{CELLS as DENSITY_CELLS, DensitySummary, Lattice};
pub use sink::{ModelRef, SceneSink};
pub use sizes::{SIZE_CLASSES, SizeClass, SizeSummary, size_class};

use crate::texture::{Sampler, UvTransform};
use serde::Serialize;

/// The pinhole camera of an NFF `v` block.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct View {
    pub from: [f64; 3],
    pub at: [f64; 3],
    pub up: [f64; 3],
    /// Full field of view in degrees, spanning the first to the last row or
    /// column of pixel corners.
    pub angle: f64,
    pub hither: f64,
    pub resolution: [u32; 2],
}

/// An NFF `f` statement: colour, diffuse, specular (reflection and
/// highlight), Phong exponent, transmission and index of refraction.
///
/// A glTF material also carries its metallic-roughness parameters
/// ([`Pbr`]): direct light then follows glTF's BRDF instead of NFF's
/// Phong terms, while reflection and refraction rays keep the NFF fields.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Material {
    pub color: [f32; 3],
    pub kd: f32,
    pub ks: f32,
    pub shine: f32,
    pub t: f32,
    pub ior: f32,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pbr: Option<Pbr>,
    /// A glTF base colour texture (or OBJ's `map_Kd`): multiplies `color`
    /// where the surface has texture coordinates.
    #[serde(skip)]
    pub texture: Option<TextureBinding>,
    /// glTF's other textures: metallic-roughness, emissive and normal.
    #[serde(skip)]
    pub maps: Maps,
}

/// The textures of a glTF material besides its base colour's: each
/// multiplies its factor where the surface has texture coordinates (read
/// at the same coordinates as the base colour texture).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Maps {
    /// `metallicRoughnessTexture` (linear): blue scales the metallic
    /// factor, green the roughness.
    pub metallic_roughness: Option<TextureBinding>,
    /// `emissiveTexture` (sRGB): scales the emissive colour.
    pub emissive: Option<TextureBinding>,
    /// `normalTexture` (linear), in the tangent space the texture
    /// coordinates give; glTF's `scale` is kept in the binding's `alpha`.
    pub normal: Option<TextureBinding>,
}

impl Maps {
    pub const NONE: Maps = Maps {
        metallic_roughness: None,
        emissive: None,
        normal: None,
    };

    /// The maps with their slot numbers, as the tables store them.
    pub fn slots(&self) -> [(u32, Option<TextureBinding>); 3] {
        [
            (0, self.metallic_roughness),
            (1, self.emissive),
            (2, self.normal),
        ]
    }

    /// The map of slot `slot`.
    pub fn slot_mut(&mut self, slot: u32) -> Option<&mut Option<TextureBinding>> {
        match slot {
            0 => Some(&mut self.metallic_roughness),
            1 => Some(&mut self.emissive),
            2 => Some(&mut self.normal),
            _ => None,
        }
    }
}

/// A texture a material binds: one of the scene's images
/// ([`SceneHeader::textures`]), sampled by `sampler` at the surface's
/// texture coordinates mapped by `transform`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureBinding {
    pub image: u32,
    pub sampler: Sampler,
    pub transform: UvTransform,
    /// glTF's `alphaMode: MASK`: the surface is cut out where its alpha
    /// (`alpha` times the texture's, times the vertex colour's) is below
    /// this ([`crate::render::Cutouts`]); 0: opaque.
    pub cutoff: f32,
    /// The base colour factor's alpha.
    pub alpha: f32,
}

impl TextureBinding {
    /// The binding's bits, to deduplicate materials exactly.
    fn key(&self) -> [u32; 10] {
        let s = &self.sampler;
        let t = &self.transform;
        [
            self.image,
            s.wrap_s as u32 | (s.wrap_t as u32) << 4 | (s.filter as u32) << 8,
            t.offset[0].to_bits(),
            t.offset[1].to_bits(),
            t.rotation.to_bits(),
            t.scale[0].to_bits(),
            t.scale[1].to_bits(),
            self.cutoff.to_bits(),
            self.alpha.to_bits(),
            1,
        ]
    }
}

/// An image a scene's materials sample: as the file gave it (PNG or JPEG
/// bytes: a scene being read, or a version 8 database), decoded when a
/// render starts ([`crate::texture::Texture::decode`]); or, in a database
/// of version 9, its mip chain's tiles, read as shading needs them.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureImage {
    /// Where it came from (a file name, or the glTF image's index), for
    /// messages.
    pub name: String,
    pub data: ImageData,
}

/// What a [`TextureImage`] holds.
#[derive(Clone, Debug, PartialEq)]
pub enum ImageData {
    /// The file's bytes, PNG or JPEG.
    Encoded(Vec<u8>),
    /// Where its tiles lie in the database.
    Tiled(TiledImage),
}

/// An image stored as tiles ([`crate::texture::mip`]): its size, how its
/// colour values are encoded, and where each tile of its chain lies.
#[derive(Clone, Debug, PartialEq)]
pub struct TiledImage {
    pub width: u32,
    pub height: u32,
    pub encoding: crate::texture::Encoding,
    pub tiles: Vec<crate::texture::TileRef>,
}

impl TextureImage {
    /// An image as a file gives it.
    pub fn encoded(name: String, bytes: Vec<u8>) -> TextureImage {
        TextureImage {
            name,
            data: ImageData::Encoded(bytes),
        }
    }

    /// Bytes it holds in memory with the tables.
    pub fn held_bytes(&self) -> u64 {
        match &self.data {
            ImageData::Encoded(b) => b.len() as u64,
            ImageData::Tiled(t) => 16 * t.tiles.len() as u64,
        }
    }
}

/// glTF 2.0's metallic-roughness material (Appendix B of the
/// specification): `color` of the [`Material`] is the base colour.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Pbr {
    pub metallic: f32,
    pub roughness: f32,
    /// Emissive colour times `KHR_materials_emissive_strength`.
    pub emissive: [f32; 3],
}

impl Pbr {
    fn key(&self) -> [u32; 5] {
        [
            self.metallic.to_bits(),
            self.roughness.to_bits(),
            self.emissive[0].to_bits(),
            self.emissive[1].to_bits(),
            self.emissive[2].to_bits(),
        ]
    }
}

/// A material's bits, to deduplicate materials exactly.
pub type MaterialKey = [u32; 54];

impl Material {
    /// The material of objects that precede any `f` statement: white,
    /// purely diffuse.
    pub const DEFAULT: Material = Material {
        color: [1.0, 1.0, 1.0],
        kd: 1.0,
        ks: 0.0,
        shine: 0.0,
        t: 0.0,
        ior: 1.0,
        pbr: None,
        texture: None,
        maps: Maps::NONE,
    };

    /// Bit pattern used to deduplicate materials exactly.
    pub fn key(&self) -> MaterialKey {
        let pbr = self.pbr.map_or([0; 5], |p| p.key());
        let tex = self.texture.map_or([0; 10], |t| t.key());
        let mr = self.maps.metallic_roughness.map_or([0; 10], |t| t.key());
        let em = self.maps.emissive.map_or([0; 10], |t| t.key());
        let nm = self.maps.normal.map_or([0; 10], |t| t.key());
        [
            self.color[0].to_bits(),
            self.color[1].to_bits(),
            self.color[2].to_bits(),
            self.kd.to_bits(),
            self.ks.to_bits(),
            self.shine.to_bits(),
            self.t.to_bits(),
            self.ior.to_bits(),
            self.pbr.is_some() as u32,
            pbr[0],
            pbr[1],
            pbr[2],
            pbr[3],
            pbr[4],
            tex[0],
            tex[1],
            tex[2],
            tex[3],
            tex[4],
            tex[5],
            tex[6],
            tex[7],
            tex[8],
            tex[9],
            mr[0],
            mr[1],
            mr[2],
            mr[3],
            mr[4],
            mr[5],
            mr[6],
            mr[7],
            mr[8],
            mr[9],
            em[0],
            em[1],
            em[2],
            em[3],
            em[4],
            em[5],
            em[6],
            em[7],
            em[8],
            em[9],
            nm[0],
            nm[1],
            nm[2],
            nm[3],
            nm[4],
            nm[5],
            nm[6],
            nm[7],
            nm[8],
            nm[9],
        ]
    }
}

/// A positional point light. `color` is `None` when the scene did not give
/// one; see [`Light::resolved_color`].
///
/// A glTF light (`KHR_lights_punctual`) also carries its photometry
/// ([`Photometric`]): its intensity, inverse-square falloff, range and,
/// for a spot light, its cone. NFF lights have none.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Light {
    pub position: [f64; 3],
    pub color: Option<[f32; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub photometric: Option<Photometric>,
}

/// The kinds of `KHR_lights_punctual` light.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LightKind {
    Point = 0,
    Spot = 1,
    Directional = 2,
}

/// A `KHR_lights_punctual` light's photometry, in world coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Photometric {
    pub kind: LightKind,
    /// Candela (point, spot) or lux (directional).
    pub intensity: f32,
    /// Distance where the light reaches zero; `None`: infinite.
    pub range: Option<f32>,
    /// Spot cone angles in radians (`0 <= inner < outer <= pi/2`).
    pub inner_cone: f32,
    pub outer_cone: f32,
    /// Unit direction the light points along (spot, directional).
    pub direction: [f64; 3],
}

impl Light {
    /// The light's colour: as given, or white scaled by 1/sqrt(number of
    /// lights), the convention of the SPD's own converters.
    pub fn resolved_color(&self, light_count: usize) -> [f32; 3] {
        self.color.unwrap_or_else(|| {
            let s = (1.0 / (light_count.max(1) as f64).sqrt()) as f32;
            [s, s, s]
        })
    }
}

/// What a mesh file (PLY, OBJ, OFF) says about its geometry, before its
/// objects.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MeshFacts {
    /// Vertices in the file's vertex table, used by faces or not.
    pub vertices: u64,
    /// Bounds, in world coordinates, of the vertices its faces use; `None`
    /// when it has no faces (a point cloud).
    pub bounds: Option<([f64; 3], [f64; 3])>,
    /// The up direction the file declares in a comment, if any.
    pub up: Option<[f64; 3]>,
}

/// Everything about a scene except its objects: small, held in memory by
/// every part of the renderer.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneHeader {
    pub view: View,
    pub background: [f32; 3],
    pub lights: Vec<Light>,
    pub materials: Vec<Material>,
    /// The images materials bind ([`TextureBinding::image`]).
    pub textures: Vec<TextureImage>,
}

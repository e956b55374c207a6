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
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Material {
    pub color: [f32; 3],
    pub kd: f32,
    pub ks: f32,
    pub shine: f32,
    pub t: f32,
    pub ior: f32,
}

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
    };

    /// Bit pattern used to deduplicate materials exactly.
    pub fn key(&self) -> [u32; 8] {
        [
            self.color[0].to_bits(),
            self.color[1].to_bits(),
            self.color[2].to_bits(),
            self.kd.to_bits(),
            self.ks.to_bits(),
            self.shine.to_bits(),
            self.t.to_bits(),
            self.ior.to_bits(),
        ]
    }
}

/// A positional point light. `color` is `None` when the scene did not give
/// one; see [`Light::resolved_color`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Light {
    pub position: [f64; 3],
    pub color: Option<[f32; 3]>,
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
}

use super::{Light, Material, Shape, ShapeKind, View};
use crate::Error;
use serde::Serialize;

/// Receives a scene as a stream, in file order: the NFF reader and the SPD
/// generators produce into it; the object-database writer, the NFF writer
/// and `sray info` consume from it. Objects are numbered by their position
/// in the stream.
pub trait SceneSink {
    fn background(&mut self, rgb: [f32; 3]) -> Result<(), Error>;
    fn view(&mut self, view: &View) -> Result<(), Error>;
    fn light(&mut self, light: &Light) -> Result<(), Error>;
    /// Applies to every following object until the next material.
    fn material(&mut self, material: &Material) -> Result<(), Error>;
    fn object(&mut self, shape: &Shape<'_>) -> Result<(), Error>;
}

/// Objects of each kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ShapeCounts {
    pub sphere: u64,
    pub polygon: u64,
    pub patch: u64,
    pub cone: u64,
}

impl ShapeCounts {
    pub fn add(&mut self, kind: ShapeKind, n: u64) {
        *self.get_mut(kind) += n;
    }
    pub fn get(&self, kind: ShapeKind) -> u64 {
        match kind {
            ShapeKind::Sphere => self.sphere,
            ShapeKind::Polygon => self.polygon,
            ShapeKind::Patch => self.patch,
            ShapeKind::Cone => self.cone,
        }
    }
    fn get_mut(&mut self, kind: ShapeKind) -> &mut u64 {
        match kind {
            ShapeKind::Sphere => &mut self.sphere,
            ShapeKind::Polygon => &mut self.polygon,
            ShapeKind::Patch => &mut self.patch,
            ShapeKind::Cone => &mut self.cone,
        }
    }
    pub fn total(&self) -> u64 {
        self.sphere + self.polygon + self.patch + self.cone
    }
}

use super::{Light, Material, View};
use crate::Error;
use crate::shapes::Shape;

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

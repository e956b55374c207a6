use super::{Light, Material, MeshFacts, View};
use crate::Error;
use crate::shapes::Shape;

/// Receives a scene as a stream, in file order: the scene readers and the
/// SPD generators produce into it; the object-database writer, the NFF
/// writer and `sray info` consume from it. Objects are numbered by their
/// position in the stream.
///
/// View and lights are in world coordinates. Object geometry is relative
/// to the stream's origin ([`SceneSink::origin`], the world's origin unless
/// a source says otherwise), so that a model far from the world's origin
/// keeps the precision of its `f32` coordinates.
pub trait SceneSink {
    fn background(&mut self, rgb: [f32; 3]) -> Result<(), Error>;
    fn view(&mut self, view: &View) -> Result<(), Error>;
    fn light(&mut self, light: &Light) -> Result<(), Error>;
    /// Applies to every following object until the next material.
    fn material(&mut self, material: &Material) -> Result<(), Error>;
    fn object(&mut self, shape: &Shape<'_>) -> Result<(), Error>;

    /// The point, in world coordinates, that every object's geometry is
    /// relative to. Sent at most once, before any object. A sink that
    /// cannot keep an origin refuses any but the world's own (the default).
    fn origin(&mut self, origin: [f64; 3]) -> Result<(), Error> {
        if origin == [0.0; 3] {
            Ok(())
        } else {
            Err(Error::Scene(
                "this output cannot place geometry relative to an origin".into(),
            ))
        }
    }

    /// What a mesh file says about itself, before its objects (after its
    /// origin). A mesh has no view and no lights of its own: a sink that
    /// needs them makes defaults from these facts (see
    /// [`crate::scene::setup`]).
    fn mesh(&mut self, _facts: &MeshFacts) -> Result<(), Error> {
        Ok(())
    }
}

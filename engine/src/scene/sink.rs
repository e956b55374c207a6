use super::{Light, Material, MeshFacts, TextureImage, View};
use crate::Error;
use crate::shapes::Shape;
use glam::DAffine3;

/// A model of the scene, once written: what its instances refer to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelRef {
    pub index: u32,
    pub bbox: crate::math::Aabb,
    pub triangles: u64,
}

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

    /// Object `rank` of the scene's input, sent by a source whose order is
    /// not its input's (a database in spatial order) instead of
    /// [`SceneSink::object`], so that a sink keeping input ids for ties
    /// keeps these. The default numbers it by its place in the stream.
    fn ranked_object(&mut self, shape: &Shape<'_>, _rank: u32) -> Result<(), Error> {
        self.object(shape)
    }

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

    /// Starts a model: the materials and objects until
    /// [`SceneSink::end_model`] form it (triangles only, relative to the
    /// model's own origin), stored once and placed by
    /// [`SceneSink::instance`]. A sink that cannot keep models refuses
    /// (the default); a source then places copies instead.
    fn begin_model(&mut self) -> Result<(), Error> {
        Err(Error::Scene("this output cannot hold models".into()))
    }

    /// Ends the model begun last; what its instances refer to.
    fn end_model(&mut self) -> Result<ModelRef, Error> {
        Err(Error::Scene("this output cannot hold models".into()))
    }

    /// Places model `model` (an [`SceneSink::end_model`] index) by `m`,
    /// from the model's coordinates to the stream's. The instance is one
    /// object of the stream.
    fn instance(&mut self, _model: u32, _m: &DAffine3) -> Result<(), Error> {
        Err(Error::Scene("this output cannot hold models".into()))
    }

    /// Whether [`SceneSink::begin_model`] is accepted.
    fn takes_models(&self) -> bool {
        false
    }

    /// An image the following materials may bind
    /// ([`crate::scene::TextureBinding::image`] is the number returned: 0,
    /// 1, 2, ... in the order sent). A sink that keeps no images (the
    /// default) numbers them all the same and drops them: its materials
    /// render untextured.
    fn texture(&mut self, _image: &TextureImage) -> Result<u32, Error> {
        Ok(0)
    }
}

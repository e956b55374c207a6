//! A scene stream captured in memory, for tests and tools that compare
//! scenes. Not for large scenes.

use super::{Light, Material, MeshFacts, SceneSink, TextureImage, View};
use crate::Error;
use crate::shapes::{OwnedShape, Shape};

/// One element of a scene stream.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    Background([f32; 3]),
    View(View),
    Light(Light),
    Material(Material),
    Object(OwnedShape),
    Origin([f64; 3]),
    Mesh(MeshFacts),
    Texture(TextureImage),
}

/// Records a scene stream.
#[derive(Clone, Debug, Default)]
pub struct Recorder {
    pub events: Vec<Event>,
}

impl Recorder {
    pub fn objects(&self) -> impl Iterator<Item = &OwnedShape> {
        self.events.iter().filter_map(|e| match e {
            Event::Object(o) => Some(o),
            _ => None,
        })
    }

    /// Replays the recording into another sink.
    pub fn replay(&self, sink: &mut dyn SceneSink) -> Result<(), Error> {
        for e in &self.events {
            match e {
                Event::Background(c) => sink.background(*c)?,
                Event::View(v) => sink.view(v)?,
                Event::Light(l) => sink.light(l)?,
                Event::Material(m) => sink.material(m)?,
                Event::Object(o) => sink.object(&o.shape())?,
                Event::Origin(o) => sink.origin(*o)?,
                Event::Mesh(m) => sink.mesh(m)?,
                Event::Texture(t) => {
                    sink.texture(t)?;
                }
            }
        }
        Ok(())
    }
}

impl SceneSink for Recorder {
    fn background(&mut self, rgb: [f32; 3]) -> Result<(), Error> {
        self.events.push(Event::Background(rgb));
        Ok(())
    }
    fn view(&mut self, view: &View) -> Result<(), Error> {
        self.events.push(Event::View(*view));
        Ok(())
    }
    fn light(&mut self, light: &Light) -> Result<(), Error> {
        self.events.push(Event::Light(*light));
        Ok(())
    }
    fn material(&mut self, m: &Material) -> Result<(), Error> {
        self.events.push(Event::Material(*m));
        Ok(())
    }
    fn object(&mut self, s: &Shape<'_>) -> Result<(), Error> {
        self.events.push(Event::Object(OwnedShape::from_shape(s)));
        Ok(())
    }
    fn origin(&mut self, origin: [f64; 3]) -> Result<(), Error> {
        self.events.push(Event::Origin(origin));
        Ok(())
    }
    fn mesh(&mut self, facts: &MeshFacts) -> Result<(), Error> {
        self.events.push(Event::Mesh(*facts));
        Ok(())
    }
    fn texture(&mut self, t: &TextureImage) -> Result<u32, Error> {
        let n = self
            .events
            .iter()
            .filter(|e| matches!(e, Event::Texture(_)))
            .count();
        self.events.push(Event::Texture(t.clone()));
        Ok(n as u32)
    }
}

//! A scene stream captured in memory, for tests and tools that compare
//! scenes. Not for large scenes.

use super::{Light, Material, SceneSink, Shape, ShapeKind, View};
use crate::Error;

/// An owned copy of a [`Shape`].
#[derive(Clone, Debug, PartialEq)]
pub enum OwnedShape {
    Sphere {
        center: [f32; 3],
        radius: f32,
    },
    Polygon {
        vertices: Vec<[f32; 3]>,
    },
    Patch {
        vertices: Vec<[f32; 3]>,
        normals: Vec<[f32; 3]>,
    },
    Cone {
        base: [f32; 3],
        base_radius: f32,
        apex: [f32; 3],
        apex_radius: f32,
    },
}

impl OwnedShape {
    pub fn from_shape(s: &Shape<'_>) -> OwnedShape {
        match *s {
            Shape::Sphere { center, radius } => OwnedShape::Sphere { center, radius },
            Shape::Polygon { vertices } => OwnedShape::Polygon {
                vertices: vertices.to_vec(),
            },
            Shape::Patch { vertices, normals } => OwnedShape::Patch {
                vertices: vertices.to_vec(),
                normals: normals.to_vec(),
            },
            Shape::Cone {
                base,
                base_radius,
                apex,
                apex_radius,
            } => OwnedShape::Cone {
                base,
                base_radius,
                apex,
                apex_radius,
            },
        }
    }

    pub fn as_shape(&self) -> Shape<'_> {
        match self {
            OwnedShape::Sphere { center, radius } => Shape::Sphere {
                center: *center,
                radius: *radius,
            },
            OwnedShape::Polygon { vertices } => Shape::Polygon { vertices },
            OwnedShape::Patch { vertices, normals } => Shape::Patch { vertices, normals },
            OwnedShape::Cone {
                base,
                base_radius,
                apex,
                apex_radius,
            } => Shape::Cone {
                base: *base,
                base_radius: *base_radius,
                apex: *apex,
                apex_radius: *apex_radius,
            },
        }
    }

    pub fn kind(&self) -> ShapeKind {
        self.as_shape().kind()
    }

    /// Every coordinate (and radius / normal component), in order.
    pub fn numbers(&self) -> Vec<f32> {
        match self {
            OwnedShape::Sphere { center, radius } => vec![center[0], center[1], center[2], *radius],
            OwnedShape::Polygon { vertices } => vertices.iter().flatten().copied().collect(),
            OwnedShape::Patch { vertices, normals } => {
                vertices.iter().chain(normals).flatten().copied().collect()
            }
            OwnedShape::Cone {
                base,
                base_radius,
                apex,
                apex_radius,
            } => vec![
                base[0],
                base[1],
                base[2],
                *base_radius,
                apex[0],
                apex[1],
                apex[2],
                *apex_radius,
            ],
        }
    }
}

/// One element of a scene stream.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    Background([f32; 3]),
    View(View),
    Light(Light),
    Material(Material),
    Object(OwnedShape),
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
                Event::Object(o) => sink.object(&o.as_shape())?,
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
}

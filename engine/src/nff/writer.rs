use super::gfmt::fmt_g;
use crate::error::Error;
use crate::scene::{Light, Material, SceneSink, View};
use crate::shapes::{Cone, Patch, Polygon, Shape, Sphere};
use std::io::Write;
use std::path::PathBuf;

/// Writes a scene stream as NFF text, numbers printed as the SPD programs
/// print them (`%g`), cones on one line as the SPD writes them. NFF has no
/// origin: geometry relative to one (a recentred mesh) is written in world
/// coordinates, every number in full (shortest exact) precision, as `%g`'s
/// six digits would lose what the origin kept.
pub struct NffWriter<W: Write> {
    out: W,
    name: PathBuf,
    line: String,
    origin: [f64; 3],
}

impl<W: Write> NffWriter<W> {
    pub fn new(out: W, name: impl Into<PathBuf>) -> Self {
        NffWriter {
            out,
            name: name.into(),
            line: String::with_capacity(256),
            origin: [0.0; 3],
        }
    }

    /// Points of geometry, in world coordinates.
    fn points(&mut self, p: [f32; 3]) {
        if self.origin == [0.0; 3] {
            self.nums(&f3(p));
        } else {
            for i in 0..3 {
                if !self.line.is_empty() && !self.line.ends_with(' ') && !self.line.ends_with('\n')
                {
                    self.line.push(' ');
                }
                let x = p[i] as f64 + self.origin[i];
                self.line.push_str(&format!("{x}"));
            }
        }
    }

    pub fn into_inner(self) -> W {
        self.out
    }

    fn num(&mut self, x: f64) {
        if !self.line.is_empty() && !self.line.ends_with(' ') && !self.line.ends_with('\n') {
            self.line.push(' ');
        }
        fmt_g(x, &mut self.line);
    }

    fn nums(&mut self, xs: &[f64]) {
        for &x in xs {
            self.num(x);
        }
    }

    fn word(&mut self, w: &str) {
        self.line.push_str(w);
    }

    fn end_line(&mut self) {
        self.line.push('\n');
    }

    fn flush_line(&mut self) -> Result<(), Error> {
        let r = self.out.write_all(self.line.as_bytes());
        self.line.clear();
        r.map_err(|e| Error::io(&self.name, e))
    }
}

fn f3(a: [f32; 3]) -> [f64; 3] {
    [a[0] as f64, a[1] as f64, a[2] as f64]
}

impl<W: Write> SceneSink for NffWriter<W> {
    fn origin(&mut self, origin: [f64; 3]) -> Result<(), Error> {
        self.origin = origin;
        Ok(())
    }

    fn background(&mut self, rgb: [f32; 3]) -> Result<(), Error> {
        self.word("b");
        self.nums(&f3(rgb));
        self.end_line();
        self.flush_line()
    }

    fn view(&mut self, v: &View) -> Result<(), Error> {
        self.word("v\nfrom");
        self.nums(&v.from);
        self.word("\nat");
        self.nums(&v.at);
        self.word("\nup");
        self.nums(&v.up);
        self.word("\nangle");
        self.num(v.angle);
        self.word("\nhither");
        self.num(v.hither);
        self.word(&format!(
            "\nresolution {} {}\n",
            v.resolution[0], v.resolution[1]
        ));
        self.flush_line()
    }

    fn light(&mut self, l: &Light) -> Result<(), Error> {
        self.word("l");
        self.nums(&l.position);
        if let Some(c) = l.color {
            self.nums(&f3(c));
        }
        self.end_line();
        self.flush_line()
    }

    fn material(&mut self, m: &Material) -> Result<(), Error> {
        self.word("f");
        self.nums(&f3(m.color));
        self.nums(&[
            m.kd as f64,
            m.ks as f64,
            m.shine as f64,
            m.t as f64,
            m.ior as f64,
        ]);
        self.end_line();
        self.flush_line()
    }

    fn object(&mut self, shape: &Shape<'_>) -> Result<(), Error> {
        match *shape {
            Shape::Sphere(Sphere { center, radius }) => {
                self.word("s");
                self.points(center);
                self.num(radius as f64);
                self.end_line();
            }
            Shape::Cone(Cone {
                base,
                base_radius,
                apex,
                apex_radius,
            }) => {
                self.word("c");
                self.points(base);
                self.num(base_radius as f64);
                self.points(apex);
                self.num(apex_radius as f64);
                self.end_line();
            }
            Shape::Polygon(Polygon { vertices }) => {
                self.word(&format!("p {}\n", vertices.len()));
                for v in vertices {
                    self.points(*v);
                    self.end_line();
                }
            }
            Shape::Patch(Patch { vertices, normals }) => {
                self.word(&format!("pp {}\n", vertices.len()));
                for (v, n) in vertices.iter().zip(normals) {
                    self.points(*v);
                    self.nums(&f3(*n));
                    self.end_line();
                }
            }
            // NFF has no texture coordinates or vertex colours: a
            // textured triangle is written as its triangle (as glTF's
            // material parameters become NFF's), smooth if it has normals.
            Shape::Textured(t) if t.normals.is_empty() => {
                self.word("p 3\n");
                for v in t.vertices {
                    self.points(*v);
                    self.end_line();
                }
            }
            Shape::Textured(t) => {
                self.word("pp 3\n");
                for (v, n) in t.vertices.iter().zip(t.normals) {
                    self.points(*v);
                    self.nums(&f3(*n));
                    self.end_line();
                }
            }
            // NFF has these four entities; a kind it cannot express is
            // refused rather than approximated.
            #[allow(unreachable_patterns)]
            other => {
                return Err(Error::Scene(format!(
                    "a {} cannot be written as NFF; convert to an object database (.sdb) instead",
                    other.kind().name()
                )));
            }
        }
        self.flush_line()
    }
}

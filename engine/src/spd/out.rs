//! The SPD library's output calls, writing into a [`SceneSink`].
//!
//! The SPD programs print every number with `%g`; each value here is rounded
//! the same way ([`round_g6`]) before it is stored, so a generated scene is
//! exactly the scene the SPD's own NFF file describes, and rendering
//! `spd:NAME:SIZE` or that NFF file gives the same image.

use super::matrix::PI;
use crate::error::Error;
use crate::nff::round_g6;
use crate::progress::Progress;
use crate::scene::{Light, Material, SceneSink, View};
use crate::shapes::{Cone, Patch, Polygon, Shape, Sphere};

pub struct Out<'a> {
    sink: &'a mut dyn SceneSink,
    progress: &'a dyn Progress,
    unreported: u64,
    verts: Vec<[f32; 3]>,
    norms: Vec<[f32; 3]>,
}

fn r32(x: f64) -> f32 {
    round_g6(x) as f32
}

fn r3(p: [f64; 3]) -> [f32; 3] {
    [r32(p[0]), r32(p[1]), r32(p[2])]
}

fn r64(p: [f64; 3]) -> [f64; 3] {
    [round_g6(p[0]), round_g6(p[1]), round_g6(p[2])]
}

impl<'a> Out<'a> {
    pub fn new(sink: &'a mut dyn SceneSink, progress: &'a dyn Progress) -> Self {
        Out {
            sink,
            progress,
            unreported: 0,
            verts: Vec::with_capacity(256),
            norms: Vec::with_capacity(256),
        }
    }

    pub fn finish(self) {
        self.progress.inc(self.unreported);
    }

    fn counted(&mut self) {
        self.unreported += 1;
        if self.unreported == 1 << 14 {
            self.progress.inc(self.unreported);
            self.unreported = 0;
        }
    }

    pub fn background(&mut self, c: [f64; 3]) -> Result<(), Error> {
        self.sink.background(r3(c))
    }

    #[allow(clippy::too_many_arguments)]
    pub fn viewpoint(
        &mut self,
        from: [f64; 3],
        at: [f64; 3],
        up: [f64; 3],
        fov: f64,
        hither: f64,
        res: [u32; 2],
    ) -> Result<(), Error> {
        self.sink.view(&View {
            from: r64(from),
            at: r64(at),
            up: r64(up),
            angle: round_g6(fov),
            hither: round_g6(hither),
            resolution: res,
        })
    }

    /// A light as the SPD writes it to NFF: position only.
    pub fn light(&mut self, p: [f64; 3]) -> Result<(), Error> {
        self.sink.light(&Light {
            photometric: None,
            position: r64(p),
            color: None,
        })
    }

    /// `lib_output_color`: the highlight's half-angle `ang` (degrees) becomes
    /// a Phong exponent; ambient and the separate highlight weight have no
    /// place in NFF.
    #[allow(clippy::too_many_arguments)]
    pub fn color(
        &mut self,
        c: [f64; 3],
        _ka: f64,
        kd: f64,
        ks: f64,
        _ks_spec: f64,
        ang: f64,
        kt: f64,
        ior: f64,
    ) -> Result<(), Error> {
        let rad = PI * ang / 180.0;
        let phong = if rad <= 0.0 {
            100000.0
        } else if rad >= PI / 2.0 {
            1.0
        } else {
            0.5f64.ln() / rad.cos().ln()
        };
        self.sink.material(&Material {
            pbr: None,
            texture: None,
            maps: crate::scene::Maps::NONE,
            color: r3(c),
            kd: r32(kd),
            ks: r32(ks),
            shine: r32(phong),
            t: r32(kt),
            ior: r32(ior),
        })
    }

    pub fn sphere(&mut self, c: [f64; 3], r: f64) -> Result<(), Error> {
        self.counted();
        self.sink.object(&Shape::Sphere(Sphere {
            center: r3(c),
            radius: r32(r),
        }))
    }

    pub fn cylcone(
        &mut self,
        base: [f64; 3],
        br: f64,
        apex: [f64; 3],
        ar: f64,
    ) -> Result<(), Error> {
        self.counted();
        self.sink.object(&Shape::Cone(Cone {
            base: r3(base),
            base_radius: r32(br),
            apex: r3(apex),
            apex_radius: r32(ar),
        }))
    }

    pub fn polygon(&mut self, v: &[[f64; 3]]) -> Result<(), Error> {
        self.counted();
        self.verts.clear();
        self.verts.extend(v.iter().map(|p| r3(*p)));
        self.sink.object(&Shape::Polygon(Polygon {
            vertices: &self.verts,
        }))
    }

    pub fn polypatch(&mut self, v: &[[f64; 3]], n: &[[f64; 3]]) -> Result<(), Error> {
        self.counted();
        self.verts.clear();
        self.verts.extend(v.iter().map(|p| r3(*p)));
        self.norms.clear();
        self.norms.extend(n.iter().map(|p| r3(*p)));
        self.sink.object(&Shape::Patch(Patch {
            vertices: &self.verts,
            normals: &self.norms,
        }))
    }
}

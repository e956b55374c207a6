//! A camera, lights, a material and a background for scenes that have
//! none (meshes), and the command line's overrides for any scene.
//!
//! [`SetupSink`] sits between a scene source and its consumer. It passes
//! the scene through, except that
//!
//! - a mesh (which announces itself with [`SceneSink::mesh`]) gets the
//!   default view, background and lights before its first object;
//! - `--camera` replaces the parts of the view it names (the default view
//!   of a mesh is framed with the overridden angle, up and target);
//! - `--light` (repeatable) replaces all of the scene's lights;
//! - `--material` replaces every material of the scene.
//!
//! **The default view** looks at the centre of the bounding box of the
//! model's faces from the front and a little above: 20 degrees above the
//! horizontal plane and 25 degrees to the right of the front direction,
//! which is +z when up is +y (the convention of OBJ and of scanned models,
//! the Stanford ones among them), -y when up is +z, and in general the
//! axis after the up axis. Up is the axis a comment in the file declares
//! (`up z`, `Z_UP`, ...), else +y. The field of view is 40 degrees; the
//! camera stands back until all eight corners of the bounding box are
//! inside 90 % of the image's width and height (a 5 % margin each side),
//! so the whole model is in view whatever its shape.
//!
//! **The default lights**, in the camera's frame, at four times the box's
//! half-diagonal from its centre: a key light above and to the left of the
//! camera (colour 0.85), a fill light right of the camera and a little
//! below (0.35). There is no ambient term in NFF's shading, so the fill
//! light is what keeps the sides the key light misses from being black.
//! **The background** is a dark blue-grey (0.1, 0.11, 0.14). **The
//! material** of faces the file gives none is a light grey, purely diffuse
//! (`f 0.8 0.8 0.8 1 0 0 0 1`, set by the mesh readers).

use super::{Light, Material, MeshFacts, SceneSink, View};
use crate::error::Error;
use crate::shapes::Shape;

/// Default field of view of a mesh, in degrees.
pub const DEFAULT_FOV: f64 = 40.0;
/// Elevation and azimuth of the default view direction, in degrees.
pub const DEFAULT_ELEVATION: f64 = 20.0;
pub const DEFAULT_AZIMUTH: f64 = 25.0;
/// Share of the image's width and height the model's box may fill.
pub const FILL: f64 = 0.9;
/// Background of a mesh.
pub const DEFAULT_BACKGROUND: [f32; 3] = [0.1, 0.11, 0.14];
pub const KEY_LIGHT: [f32; 3] = [0.85, 0.85, 0.85];
pub const FILL_LIGHT: [f32; 3] = [0.35, 0.35, 0.35];

/// `--camera from=X,Y,Z at=X,Y,Z up=X,Y,Z fov=DEG`: any of the parts.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraOverride {
    pub from: Option<[f64; 3]>,
    pub at: Option<[f64; 3]>,
    pub up: Option<[f64; 3]>,
    pub fov: Option<f64>,
}

impl CameraOverride {
    pub fn is_empty(&self) -> bool {
        *self == CameraOverride::default()
    }

    /// Parses `from=X,Y,Z at=X,Y,Z up=X,Y,Z fov=DEG`, the parts in any
    /// order, separated by spaces (or given as separate arguments and
    /// joined by the caller).
    pub fn parse(s: &str) -> Result<CameraOverride, String> {
        let mut c = CameraOverride::default();
        let mut any = false;
        for part in s.split_whitespace() {
            any = true;
            let (k, v) = part.split_once('=').ok_or_else(|| {
                format!(
                    "--camera part '{part}' is not KEY=VALUE (from=X,Y,Z at=X,Y,Z up=X,Y,Z fov=DEG)"
                )
            })?;
            match k {
                "from" => c.from = Some(triple(v, "from")?),
                "at" => c.at = Some(triple(v, "at")?),
                "up" => c.up = Some(triple(v, "up")?),
                "fov" => {
                    let f: f64 = v
                        .parse()
                        .map_err(|_| format!("--camera fov='{v}' is not a number"))?;
                    if !(f > 0.0 && f < 180.0) {
                        return Err(format!(
                            "--camera fov={v} must be between 0 and 180 degrees"
                        ));
                    }
                    c.fov = Some(f);
                }
                _ => {
                    return Err(format!(
                        "--camera takes from=, at=, up= and fov=, not '{k}='"
                    ));
                }
            }
        }
        if !any {
            return Err("--camera needs at least one of from=, at=, up=, fov=".into());
        }
        if let Some(u) = c.up
            && u == [0.0; 3]
        {
            return Err("--camera up=0,0,0 has no direction".into());
        }
        if let (Some(f), Some(a)) = (c.from, c.at)
            && f == a
        {
            return Err("--camera from= and at= are the same point".into());
        }
        Ok(c)
    }
}

fn numbers(v: &str, what: &str, n: usize) -> Result<Vec<f64>, String> {
    let xs: Vec<f64> = v
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{what} '{v}' is not {n} comma-separated numbers"))?;
    if xs.len() != n || !xs.iter().all(|x| x.is_finite()) {
        return Err(format!(
            "{what} '{v}' is not {n} comma-separated finite numbers"
        ));
    }
    Ok(xs)
}

fn triple(v: &str, what: &str) -> Result<[f64; 3], String> {
    let x = numbers(v, &format!("--camera {what}="), 3)?;
    Ok([x[0], x[1], x[2]])
}

/// `--light X,Y,Z[,R,G,B]`.
pub fn parse_light(s: &str) -> Result<Light, String> {
    let n = s.split(',').count();
    if n != 3 && n != 6 {
        return Err(format!("--light '{s}' is not X,Y,Z or X,Y,Z,R,G,B"));
    }
    let x = numbers(s, "--light", n)?;
    Ok(Light {
        photometric: None,
        position: [x[0], x[1], x[2]],
        color: (n == 6).then(|| [x[3] as f32, x[4] as f32, x[5] as f32]),
    })
}

/// `--material r,g,b,Kd,Ks,shine,T,ior`, NFF's `f` line.
pub fn parse_material(s: &str) -> Result<Material, String> {
    let x = numbers(s, "--material (r,g,b,Kd,Ks,shine,T,ior)", 8)?;
    let f = |i: usize| x[i] as f32;
    if !x.iter().all(|v| (*v as f32).is_finite()) {
        return Err(format!(
            "--material '{s}' has a number beyond single precision"
        ));
    }
    Ok(Material {
        pbr: None,
        texture: None,
        maps: super::Maps::NONE,
        color: [f(0), f(1), f(2)],
        kd: f(3),
        ks: f(4),
        shine: f(5),
        t: f(6),
        ior: f(7),
    })
}

/// What the command line sets, and the image's shape (for framing).
#[derive(Clone, Debug, PartialEq)]
pub struct Setup {
    pub camera: CameraOverride,
    /// Replace the scene's lights when not empty.
    pub lights: Vec<Light>,
    /// Replaces every material.
    pub material: Option<Material>,
    /// Width and height of the image the default view frames.
    pub image: [u32; 2],
    /// Which of a glTF file's cameras to look through (its index among
    /// the file's cameras; the first one a node places if `None`).
    pub camera_index: Option<usize>,
    /// Write each placement of a glTF mesh as a copy of its own, not as
    /// an instance of a model stored once.
    pub flatten_instances: bool,
}

impl Default for Setup {
    fn default() -> Self {
        Setup {
            camera: CameraOverride::default(),
            lights: Vec::new(),
            material: None,
            image: [512, 512],
            camera_index: None,
            flatten_instances: false,
        }
    }
}

impl Setup {
    /// Whether it changes nothing of a scene that has its own view.
    pub fn overrides_nothing(&self) -> bool {
        self.camera.is_empty() && self.lights.is_empty() && self.material.is_none()
    }
}

type V = [f64; 3];
fn add(a: V, b: V) -> V {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn scale(a: V, s: f64) -> V {
    [a[0] * s, a[1] * s, a[2] * s]
}
fn dot(a: V, b: V) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V, b: V) -> V {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn unit(a: V) -> Option<V> {
    let l = dot(a, a).sqrt();
    (l > 0.0 && l.is_finite()).then(|| scale(a, 1.0 / l))
}

/// The front of a model whose up direction is `up`: the axis after the
/// dominant axis of up (+y up: +z; +z up: -y; +x up: +z), signed so that
/// the camera's right is the remaining axis's positive direction where
/// that axis is x.
fn front(up: V) -> V {
    let a = [up[0].abs(), up[1].abs(), up[2].abs()];
    let f = if a[1] >= a[0] && a[1] >= a[2] {
        [0.0, 0.0, up[1].signum()]
    } else if a[2] >= a[0] {
        [0.0, -up[2].signum(), 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    // Orthogonal to up.
    let f = sub(f, scale(up, dot(f, up)));
    unit(f).unwrap_or([0.0, 0.0, 1.0])
}

/// The default view of a box (world coordinates), with the overridden
/// parts of `cam`, framing an image of `image` pixels.
pub fn default_view(
    bounds: (V, V),
    up_hint: Option<V>,
    cam: &CameraOverride,
    image: [u32; 2],
) -> View {
    let (lo, hi) = bounds;
    let centre = scale(add(lo, hi), 0.5);
    let half = scale(sub(hi, lo), 0.5);
    let radius = dot(half, half).sqrt();
    let at = cam.at.unwrap_or(centre);
    let up = cam
        .up
        .and_then(unit)
        .or_else(|| up_hint.and_then(unit))
        .unwrap_or([0.0, 1.0, 0.0]);
    let fov = cam.fov.unwrap_or(DEFAULT_FOV);
    let dir = match cam.from {
        Some(f) => unit(sub(f, at)),
        None => None,
    }
    .unwrap_or_else(|| {
        let fr = front(up);
        let right = unit(cross(scale(fr, -1.0), up)).unwrap_or([1.0, 0.0, 0.0]);
        let (el, az) = (DEFAULT_ELEVATION.to_radians(), DEFAULT_AZIMUTH.to_radians());
        let d = add(
            scale(add(scale(fr, az.cos()), scale(right, az.sin())), el.cos()),
            scale(up, el.sin()),
        );
        unit(d).unwrap_or(fr)
    });
    let from = match cam.from {
        Some(f) => f,
        None => {
            // Camera frame: looking along -dir.
            let fwd = scale(dir, -1.0);
            let right = unit(cross(fwd, up)).unwrap_or([1.0, 0.0, 0.0]);
            let upv = cross(right, fwd);
            let long = image[0].max(image[1]).max(1) as f64;
            let t = (fov.to_radians() / 2.0).tan() * FILL;
            let (tx, ty) = (t * image[0] as f64 / long, t * image[1] as f64 / long);
            let mut d: f64 = 0.0;
            for k in 0..8 {
                let c = [
                    if k & 1 == 0 { lo[0] } else { hi[0] },
                    if k & 2 == 0 { lo[1] } else { hi[1] },
                    if k & 4 == 0 { lo[2] } else { hi[2] },
                ];
                let o = sub(c, at);
                let (x, y, z) = (dot(o, right), dot(o, upv), dot(o, dir));
                d = d.max(z + x.abs() / tx).max(z + y.abs() / ty);
            }
            // A box of no size still needs a camera that is not at it.
            let floor = (radius * 1e-3)
                .max(at.iter().fold(0.0f64, |m, c| m.max(c.abs())) * 1e-9)
                .max(1e-30);
            add(at, scale(dir, d.max(floor)))
        }
    };
    View {
        from,
        at,
        up,
        angle: fov,
        hither: 1e-3 * radius.max(1e-30),
        resolution: image,
    }
}

/// The default key and fill lights of a box seen by `view`.
pub fn default_lights(bounds: (V, V), view: &View) -> [Light; 2] {
    let (lo, hi) = bounds;
    let centre = scale(add(lo, hi), 0.5);
    let r = (dot(sub(hi, lo), sub(hi, lo)).sqrt() / 2.0).max(1e-30);
    let back = unit(sub(view.from, view.at)).unwrap_or([0.0, 0.0, 1.0]);
    let fwd = scale(back, -1.0);
    let right = unit(cross(fwd, view.up)).unwrap_or([1.0, 0.0, 0.0]);
    let upv = cross(right, fwd);
    let place = |d: V| add(centre, scale(unit(d).unwrap_or(back), 4.0 * r));
    [
        Light {
            photometric: None,
            position: place(add(add(back, scale(upv, 1.0)), scale(right, -0.8))),
            color: Some(KEY_LIGHT),
        },
        Light {
            photometric: None,
            position: place(add(add(back, scale(right, 0.9)), scale(upv, -0.15))),
            color: Some(FILL_LIGHT),
        },
    ]
}

/// Applies a [`Setup`] to a scene stream on its way to `inner`.
pub struct SetupSink<'a> {
    inner: &'a mut dyn SceneSink,
    setup: &'a Setup,
    saw_view: bool,
    saw_light: bool,
    saw_background: bool,
    lights_sent: bool,
    material_sent: bool,
    /// `material_sent` of the world while a model is being written.
    world_material_sent: bool,
}

impl<'a> SetupSink<'a> {
    pub fn new(inner: &'a mut dyn SceneSink, setup: &'a Setup) -> Self {
        SetupSink {
            inner,
            setup,
            saw_view: false,
            saw_light: false,
            saw_background: false,
            lights_sent: false,
            material_sent: false,
            world_material_sent: false,
        }
    }

    fn send_override_lights(&mut self) -> Result<(), Error> {
        if !self.lights_sent && !self.setup.lights.is_empty() {
            self.lights_sent = true;
            for l in &self.setup.lights {
                self.inner.light(l)?;
            }
        }
        Ok(())
    }

    /// Ends the stream: sends override lights if nothing gave them a
    /// place yet.
    pub fn finish(&mut self) -> Result<(), Error> {
        self.send_override_lights()
    }
}

impl SceneSink for SetupSink<'_> {
    fn background(&mut self, rgb: [f32; 3]) -> Result<(), Error> {
        self.saw_background = true;
        self.inner.background(rgb)
    }

    fn view(&mut self, view: &View) -> Result<(), Error> {
        self.saw_view = true;
        let c = &self.setup.camera;
        let mut v = *view;
        if let Some(f) = c.from {
            v.from = f;
        }
        if let Some(a) = c.at {
            v.at = a;
        }
        if let Some(u) = c.up {
            v.up = u;
        }
        if let Some(f) = c.fov {
            v.angle = f;
        }
        self.inner.view(&v)?;
        self.send_override_lights()
    }

    fn light(&mut self, light: &Light) -> Result<(), Error> {
        self.saw_light = true;
        if self.setup.lights.is_empty() {
            self.inner.light(light)
        } else {
            self.send_override_lights()
        }
    }

    fn texture(&mut self, image: &super::TextureImage) -> Result<u32, Error> {
        self.inner.texture(image)
    }

    fn material(&mut self, material: &Material) -> Result<(), Error> {
        match self.setup.material {
            None => self.inner.material(material),
            Some(m) if !self.material_sent => {
                self.material_sent = true;
                self.inner.material(&m)
            }
            Some(_) => Ok(()),
        }
    }

    fn object(&mut self, shape: &Shape<'_>) -> Result<(), Error> {
        if let Some(m) = self.setup.material
            && !self.material_sent
        {
            self.material_sent = true;
            self.inner.material(&m)?;
        }
        self.inner.object(shape)
    }

    fn ranked_object(&mut self, shape: &Shape<'_>, rank: u32) -> Result<(), Error> {
        if let Some(m) = self.setup.material
            && !self.material_sent
        {
            self.material_sent = true;
            self.inner.material(&m)?;
        }
        self.inner.ranked_object(shape, rank)
    }

    fn origin(&mut self, origin: [f64; 3]) -> Result<(), Error> {
        self.inner.origin(origin)
    }

    fn begin_model(&mut self) -> Result<(), Error> {
        self.inner.begin_model()?;
        // A model has its own materials: the override goes to it too.
        self.world_material_sent = std::mem::replace(&mut self.material_sent, false);
        Ok(())
    }

    fn end_model(&mut self) -> Result<super::ModelRef, Error> {
        let r = self.inner.end_model()?;
        self.material_sent = self.world_material_sent;
        Ok(r)
    }

    fn instance(&mut self, model: u32, m: &glam::DAffine3) -> Result<(), Error> {
        self.inner.instance(model, m)
    }

    fn takes_models(&self) -> bool {
        !self.setup.flatten_instances && self.inner.takes_models()
    }

    fn mesh(&mut self, facts: &MeshFacts) -> Result<(), Error> {
        self.inner.mesh(facts)?;
        if self.saw_view {
            return Ok(());
        }
        // A mesh of no faces is framed as a unit box (it renders nothing).
        let bounds = facts.bounds.unwrap_or(([-1.0; 3], [1.0; 3]));
        let view = default_view(bounds, facts.up, &self.setup.camera, self.setup.image);
        self.saw_view = true;
        self.inner.view(&view)?;
        if !self.saw_background {
            self.saw_background = true;
            self.inner.background(DEFAULT_BACKGROUND)?;
        }
        // A scene file's own lights (glTF) stand; a bare mesh gets the
        // default ones.
        if self.setup.lights.is_empty() && !self.saw_light {
            self.lights_sent = true;
            for l in default_lights(bounds, &view) {
                self.inner.light(&l)?;
            }
        }
        self.send_override_lights()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::Camera;

    /// Every corner of the box projects inside the image.
    fn frames(b: (V, V), v: &View, w: u32, h: u32) {
        let cam = Camera::new(v, w, h).unwrap();
        let eye = cam.eye;
        // Directions to the image's corners bound what is in view.
        let tl = cam.direction(0, 0);
        let br = cam.direction(w, h);
        let fwd = crate::math::Vec3::from_array(sub(v.at, v.from)).normalize();
        let right = fwd.cross(crate::math::Vec3::from_array(v.up)).normalize();
        let up = right.cross(fwd);
        let (tx, ty) = (
            tl.dot(right).abs() / tl.dot(fwd),
            tl.dot(up).abs() / tl.dot(fwd),
        );
        assert!((br.dot(right) / br.dot(fwd) - tx).abs() < 1e-9);
        for k in 0..8 {
            let c = [
                if k & 1 == 0 { b.0[0] } else { b.1[0] },
                if k & 2 == 0 { b.0[1] } else { b.1[1] },
                if k & 4 == 0 { b.0[2] } else { b.1[2] },
            ];
            let o = crate::math::Vec3::from_array(c) - eye;
            let z = o.dot(fwd);
            assert!(z > 0.0);
            assert!(o.dot(right).abs() / z <= tx * 0.95 + 1e-9, "corner {k} x");
            assert!(o.dot(up).abs() / z <= ty * 0.95 + 1e-9, "corner {k} y");
        }
    }

    #[test]
    fn the_default_view_frames_any_box() {
        let boxes = [
            ([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]),
            ([0.0, 12.6, -2.7], [4.8, 17.9, 0.0]),
            ([1e5, 1e5, 1e5], [1e5 + 0.2, 1e5 + 0.15, 1e5 + 0.1]),
            ([-10.0, 0.0, -0.01], [10.0, 0.1, 0.01]),
        ];
        for b in boxes {
            for img in [[512, 512], [800, 300], [200, 600]] {
                for up in [None, Some([0.0, 0.0, 1.0])] {
                    let v = default_view(b, up, &CameraOverride::default(), img);
                    frames(b, &v, img[0], img[1]);
                }
            }
        }
    }

    #[test]
    fn the_default_view_looks_from_the_front_and_above() {
        let b = ([-1.0; 3], [1.0; 3]);
        let v = default_view(b, None, &CameraOverride::default(), [512, 512]);
        assert!(
            v.from[2] > 0.0 && v.from[1] > 0.0 && v.from[0] > 0.0,
            "{v:?}"
        );
        assert!(v.from[2] > v.from[1] && v.from[2] > v.from[0]);
        let v = default_view(
            b,
            Some([0.0, 0.0, 1.0]),
            &CameraOverride::default(),
            [512, 512],
        );
        assert!(
            v.from[1] < 0.0 && v.from[2] > 0.0 && v.from[0] > 0.0,
            "{v:?}"
        );
        let l = default_lights(b, &v);
        assert!(l[0].position[2] > l[1].position[2]);
    }

    #[test]
    fn overrides_parse() {
        let c = CameraOverride::parse("from=1,2,3 fov=30").unwrap();
        assert_eq!(c.from, Some([1.0, 2.0, 3.0]));
        assert_eq!(c.fov, Some(30.0));
        assert!(CameraOverride::parse("from=1,2").is_err());
        assert!(CameraOverride::parse("fov=200").is_err());
        assert!(CameraOverride::parse("eye=1,2,3").is_err());
        assert!(CameraOverride::parse("up=0,0,0").is_err());
        assert_eq!(
            parse_light("1,2,3,0.5,0.5,0.5").unwrap().color,
            Some([0.5; 3])
        );
        assert_eq!(parse_light("1,2,3").unwrap().color, None);
        assert!(parse_light("1,2").is_err());
        assert!(parse_light("1,2,nan").is_err());
        let m = parse_material("1,0,0,0.7,0.3,20,0,1").unwrap();
        assert_eq!(
            (m.color, m.kd, m.ks, m.shine),
            ([1.0, 0.0, 0.0], 0.7, 0.3, 20.0)
        );
        assert!(parse_material("1,0,0").is_err());
    }
}

use crate::error::Error;
use crate::kernels::{CHUNK, LANES};
use crate::math::Vec3;
use crate::scene::View;
use crate::simd::{Isa, Job, Lanes};

/// The pinhole camera. Eye rays go through pixel corners: a `w` x `h`
/// image has `(w+1) x (h+1)` of them, and the view angle spans from the
/// first to the last corner along the image's longer side (pixels are
/// square).
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    pub eye: Vec3,
    fwd: Vec3,
    right: Vec3,
    up: Vec3,
    half_w: f64,
    half_h: f64,
    pub width: u32,
    pub height: u32,
}

/// [`Camera::directions_at`], compiled for each instruction set.
struct Directions<'a> {
    camera: &'a Camera,
    x: &'a [f64; LANES],
    y: &'a [f64; LANES],
    n: usize,
    d: &'a mut [[f64; LANES]; 3],
}

impl Job for Directions<'_> {
    type Out = ();

    #[inline(always)]
    fn run<L: Lanes>(self) {
        for c in (0..self.n.min(LANES)).step_by(CHUNK) {
            for i in c..c + CHUNK {
                let v = self.camera.direction_lane(self.x[i], self.y[i]);
                for a in 0..3 {
                    self.d[a][i] = v[a];
                }
            }
        }
    }
}

impl Camera {
    pub fn new(view: &View, width: u32, height: u32) -> Result<Camera, Error> {
        let eye = Vec3::from_array(view.from);
        let fwd = (Vec3::from_array(view.at) - eye)
            .try_normalize()
            .ok_or_else(|| Error::Scene("the view's 'from' and 'at' are the same point".into()))?;
        let right = fwd
            .cross(Vec3::from_array(view.up))
            .try_normalize()
            .ok_or_else(|| Error::Scene("the view's 'up' is parallel to its direction".into()))?;
        let up = right.cross(fwd);
        let s = (view.angle.to_radians() / 2.0).tan();
        let long = width.max(height) as f64;
        Ok(Camera {
            eye,
            fwd,
            right,
            up,
            half_w: s * width as f64 / long,
            half_h: s * height as f64 / long,
            width,
            height,
        })
    }

    pub fn corners(&self) -> usize {
        (self.width as usize + 1) * (self.height as usize + 1)
    }

    /// Unit direction of the eye ray through corner (`col`, `row`), rows
    /// from the top.
    #[inline]
    pub fn direction(&self, col: u32, row: u32) -> Vec3 {
        self.direction_at(col as f64, row as f64)
    }

    /// Unit direction of the eye ray through image point (`x`, `y`), in
    /// pixels from the top left corner (`0..=width`, `0..=height`).
    #[inline]
    pub fn direction_at(&self, x: f64, y: f64) -> Vec3 {
        Vec3::from_array(self.direction_lane(x, y))
    }

    /// The directions of the eye rays through the image points (`x[i]`,
    /// `y[i]`) of the first `n` lanes, into `d` (one array per axis),
    /// exactly as [`Camera::direction_at`] computes each: the same
    /// operations lane by lane, in loops of a fixed number of lanes that
    /// the compiler turns into vector instructions (lanes from `n` to the
    /// next multiple of 16 are written too, with what they compute).
    /// The loop is compiled for the instruction set `isa`.
    pub fn directions_at(
        &self,
        isa: Isa,
        x: &[f64; LANES],
        y: &[f64; LANES],
        n: usize,
        d: &mut [[f64; LANES]; 3],
    ) {
        isa.run(Directions {
            camera: self,
            x,
            y,
            n,
            d,
        });
    }

    /// [`Camera::direction_at`], in plain arithmetic without branches, so
    /// that a loop of it vectorises: glam's `fwd + right * x + up * y`
    /// and `try_normalize` (the reciprocal of the square root of `x x + y
    /// y + z z`, `fwd` where that is not finite and positive), spelled
    /// out.
    #[inline(always)]
    fn direction_lane(&self, x: f64, y: f64) -> [f64; 3] {
        let x = self.half_w * (2.0 * x / self.width as f64 - 1.0);
        let y = self.half_h * (1.0 - 2.0 * y / self.height as f64);
        let (f, r, u) = (self.fwd, self.right, self.up);
        let v = [
            f.x + r.x * x + u.x * y,
            f.y + r.y * x + u.y * y,
            f.z + r.z * x + u.z * y,
        ];
        let rcp = 1.0 / (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let ok = rcp.is_finite() && rcp > 0.0;
        [
            if ok { v[0] * rcp } else { f.x },
            if ok { v[1] * rcp } else { f.y },
            if ok { v[2] * rcp } else { f.z },
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corners_span_the_view_angle() {
        let v = View {
            from: [0.0, 0.0, 0.0],
            at: [0.0, 0.0, -1.0],
            up: [0.0, 1.0, 0.0],
            angle: 90.0,
            hither: 1.0,
            resolution: [4, 4],
        };
        let c = Camera::new(&v, 4, 4).unwrap();
        let first = c.direction(0, 0);
        let last = c.direction(4, 4);
        let mid = c.direction(2, 2);
        assert!((mid - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-12);
        // 90 degrees between first and last corner horizontally: x = -1, +1 at z = -1.
        assert!(
            (first.x / -first.z - -1.0).abs() < 1e-12 && (first.y / -first.z - 1.0).abs() < 1e-12
        );
        assert!((last.x / -last.z - 1.0).abs() < 1e-12 && (last.y / -last.z + 1.0).abs() < 1e-12);
        assert_eq!(c.corners(), 25);
    }

    /// The directions of a packet, on every instruction set, are glam's
    /// `(fwd + right x + up y).try_normalize()` of each point, bit for bit.
    #[test]
    fn packets_of_directions_are_the_single_ray_directions() {
        let v = View {
            from: [0.3, -2.0, 7.0],
            at: [1.0, 0.5, -3.0],
            up: [0.1, 1.0, 0.2],
            angle: 61.5,
            hither: 1.0,
            resolution: [7, 5],
        };
        let c = Camera::new(&v, 701, 503).unwrap();
        let (mut x, mut y) = ([0.0; LANES], [0.0; LANES]);
        for i in 0..LANES {
            x[i] = (i * 37 % 702) as f64 + (i % 3) as f64 / 3.0;
            y[i] = (i * 53 % 504) as f64 + (i % 7) as f64 / 7.0;
        }
        let glam = |x: f64, y: f64| {
            let x = c.half_w * (2.0 * x / c.width as f64 - 1.0);
            let y = c.half_h * (1.0 - 2.0 * y / c.height as f64);
            (c.fwd + c.right * x + c.up * y)
                .try_normalize()
                .unwrap_or(c.fwd)
        };
        for n in [LANES, 23, 1] {
            for isa in Isa::available_here() {
                let mut d = [[f64::NAN; LANES]; 3];
                c.directions_at(isa, &x, &y, n, &mut d);
                for i in 0..n {
                    let want = glam(x[i], y[i]);
                    assert_eq!(c.direction_at(x[i], y[i]).to_array(), want.to_array());
                    let got = [d[0][i], d[1][i], d[2][i]];
                    assert_eq!(
                        got.map(f64::to_bits),
                        want.to_array().map(f64::to_bits),
                        "{isa}, lane {i}"
                    );
                }
            }
        }
    }

    #[test]
    fn degenerate_views_are_errors() {
        let mut v = View {
            from: [1.0, 2.0, 3.0],
            at: [1.0, 2.0, 3.0],
            up: [0.0, 0.0, 1.0],
            angle: 45.0,
            hither: 1.0,
            resolution: [8, 8],
        };
        assert!(Camera::new(&v, 8, 8).is_err());
        v.at = [1.0, 2.0, 4.0];
        assert!(Camera::new(&v, 8, 8).is_err());
    }
}

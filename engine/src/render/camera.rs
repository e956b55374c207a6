use crate::error::Error;
use crate::math::Vec3;
use crate::scene::View;

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
        let x = self.half_w * (2.0 * x / self.width as f64 - 1.0);
        let y = self.half_h * (1.0 - 2.0 * y / self.height as f64);
        (self.fwd + self.right * x + self.up * y)
            .try_normalize()
            .unwrap_or(self.fwd)
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

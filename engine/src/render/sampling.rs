//! How eye rays sample the image.
//!
//! The rendering contract traces one eye ray through every pixel corner
//! and averages a pixel's four corners ([`Sampling::Corners`]). For the
//! speed/accuracy trade-off, pixels can instead take `k x k` jittered
//! samples each ([`Sampling::Jittered`]): one per cell of a `k x k` grid
//! over the pixel, at a position within the cell drawn from a hash of the
//! pixel and the sample, so the image is the same on every run, thread and
//! worker.
//!
//! Either way eye ray `i` has a fixed direction and a fixed *slot* of the
//! frame its colour goes to: corner `i`, or pixel `i / (k * k)`.

use super::camera::Camera;
use crate::error::Error;
use crate::math::Vec3;
use serde::Serialize;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Sampling {
    /// One ray per pixel corner; a pixel is the mean of its four corners.
    Corners,
    /// `per_side^2` jittered rays per pixel, stratified.
    Jittered { per_side: u32 },
}

/// Most samples per pixel accepted.
pub const MAX_SAMPLES: u32 = 1024;

impl Sampling {
    /// `1`: corners (the contract); a square `k^2` from 4 up: jittered.
    pub fn new(samples: u32) -> Result<Sampling, Error> {
        let k = (samples as f64).sqrt().round() as u32;
        match samples {
            1 => Ok(Sampling::Corners),
            n if n <= MAX_SAMPLES && k >= 2 && k * k == n => Ok(Sampling::Jittered { per_side: k }),
            n => Err(Error::Invalid(format!(
                "{n} samples per pixel: use 1 (pixel corners) or a square from 4 to {MAX_SAMPLES} (4, 9, 16, ...)"
            ))),
        }
    }

    /// Rays per frame slot.
    pub fn per_slot(self) -> u32 {
        match self {
            Sampling::Corners => 1,
            Sampling::Jittered { per_side } => per_side * per_side,
        }
    }

    /// Frame slots per row and rows of slots.
    pub fn slot_grid(self, width: u32, height: u32) -> (u32, u32) {
        match self {
            Sampling::Corners => (width + 1, height + 1),
            Sampling::Jittered { .. } => (width, height),
        }
    }

    pub fn slots(self, width: u32, height: u32) -> u64 {
        let (w, h) = self.slot_grid(width, height);
        w as u64 * h as u64
    }

    pub fn eye_rays(self, width: u32, height: u32) -> u64 {
        self.slots(width, height) * self.per_slot() as u64
    }
}

/// The eye rays of one image.
#[derive(Clone, Copy, Debug)]
pub struct EyeRays {
    pub camera: Camera,
    pub sampling: Sampling,
}

impl EyeRays {
    pub fn count(&self) -> u64 {
        self.sampling
            .eye_rays(self.camera.width, self.camera.height)
    }

    /// Direction of eye ray `i`, and the frame slot its colour goes to.
    #[inline]
    pub fn ray(&self, i: u64) -> (Vec3, u32) {
        let (w, slot, s) = match self.sampling {
            // One ray a slot: no division by the samples.
            Sampling::Corners => (self.camera.width as u64 + 1, i, 0),
            Sampling::Jittered { per_side } => {
                let spp = (per_side * per_side) as u64;
                (self.camera.width as u64, i / spp, (i % spp) as u32)
            }
        };
        let (col, row) = ((slot % w) as u32, (slot / w) as u32);
        let (x, y) = self.point(col, row, s);
        (self.camera.direction_at(x, y), slot as u32)
    }

    /// The image point (in pixels from the top left corner) that sample
    /// `s` of the frame slot in column `col` and row `row` of the slot
    /// grid ([`Sampling::slot_grid`]) passes through: eye ray `(row * w +
    /// col) * per_slot + s`'s, for slot rows of `w`.
    #[inline]
    pub fn point(&self, col: u32, row: u32, s: u32) -> (f64, f64) {
        match self.sampling {
            Sampling::Corners => (col as f64, row as f64),
            Sampling::Jittered { per_side } => {
                let pixel = row as u64 * self.camera.width as u64 + col as u64;
                let (u, v) = jitter(pixel, s);
                let k = per_side as f64;
                let px = col as f64 + ((s % per_side) as f64 + u) / k;
                let py = row as f64 + ((s / per_side) as f64 + v) / k;
                (px, py)
            }
        }
    }
}

/// Two numbers in [0, 1) from a pixel and a sample index (SplitMix64).
fn jitter(pixel: u64, sample: u32) -> (f64, f64) {
    let mut z = pixel
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(sample as u64 + 1)
        .wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z ^= z >> 31;
    z = z.wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 29;
    let unit = |b: u64| (b >> 11) as f64 * (1.0 / (1u64 << 53) as f64);
    (unit(z), unit(z.rotate_left(32) ^ 0x5851_F42D_4C95_7F2D))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::View;

    fn cam() -> Camera {
        let v = View {
            from: [0.0, 0.0, 0.0],
            at: [0.0, 0.0, -1.0],
            up: [0.0, 1.0, 0.0],
            angle: 90.0,
            hither: 1.0,
            resolution: [4, 4],
        };
        Camera::new(&v, 4, 3).unwrap()
    }

    #[test]
    fn sample_counts() {
        assert_eq!(Sampling::new(1).unwrap(), Sampling::Corners);
        assert_eq!(
            Sampling::new(16).unwrap(),
            Sampling::Jittered { per_side: 4 }
        );
        for bad in [0, 2, 5, 15, 2048] {
            assert!(Sampling::new(bad).is_err(), "{bad}");
        }
        assert_eq!(Sampling::Corners.eye_rays(4, 3), 20);
        assert_eq!(Sampling::new(4).unwrap().eye_rays(4, 3), 48);
    }

    #[test]
    fn jittered_samples_stay_in_their_cells() {
        let e = EyeRays {
            camera: cam(),
            sampling: Sampling::new(4).unwrap(),
        };
        // Pixel 5 is (1, 1); its four samples fall in the four quarters,
        // strictly between the pixel's corner rays.
        let corner = |x: f64, y: f64| e.camera.direction_at(x, y);
        for s in 0..4u64 {
            let (d, slot) = e.ray(5 * 4 + s);
            assert_eq!(slot, 5);
            let (qx, qy) = ((s % 2) as f64, (s / 2) as f64);
            let lo = corner(1.0 + qx * 0.5, 1.0 + qy * 0.5);
            let hi = corner(1.5 + qx * 0.5, 1.5 + qy * 0.5);
            assert!(d.x > lo.x && d.x < hi.x, "sample {s}");
            assert!(d.y < lo.y && d.y > hi.y, "sample {s}");
        }
        // The same every time.
        assert_eq!(e.ray(21).0.x, e.ray(21).0.x);
        assert_ne!(e.ray(21).0.x, e.ray(25).0.x);
    }
}

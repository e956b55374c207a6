use super::sampling::Sampling;
use crate::error::Error;
use crate::fsutil::{persist, temp_beside};
use std::io::BufWriter;
use std::path::Path;

/// One in the frame buffer's fixed point: colours are summed as integers
/// in units of 2^-32, so a pixel is the same whatever order its
/// contributions arrive in (threads, workers, passes).
pub const FIXED_ONE: f64 = 4_294_967_296.0;

/// A colour contribution in fixed point (saturating far outside any real
/// colour).
#[inline]
pub fn to_fixed(c: [f32; 3]) -> [i64; 3] {
    // Round half away from zero; the cast truncates and saturates.
    c.map(|x| {
        let v = x as f64 * FIXED_ONE;
        (v + 0.5f64.copysign(v)) as i64
    })
}

/// Accumulated colour per frame slot: each pixel corner (corner sampling)
/// or each pixel (jittered sampling); see [`Sampling`].
#[derive(Clone, Debug)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub sampling: Sampling,
    /// Row-major: (width + 1) x (height + 1) corners, or width x height
    /// pixels.
    pub slots: Vec<[i64; 3]>,
}

impl Frame {
    /// A frame for corner sampling (the contract's).
    pub fn new(width: u32, height: u32) -> Frame {
        Frame::with_sampling(width, height, Sampling::Corners)
    }

    pub fn with_sampling(width: u32, height: u32, sampling: Sampling) -> Frame {
        Frame {
            width,
            height,
            sampling,
            slots: vec![[0; 3]; sampling.slots(width, height) as usize],
        }
    }

    /// Slots per row.
    pub fn row_len(&self) -> usize {
        self.sampling.slot_grid(self.width, self.height).0 as usize
    }

    #[inline]
    pub fn add(&mut self, slot: u32, c: [i64; 3]) {
        let s = &mut self.slots[slot as usize];
        for k in 0..3 {
            s[k] = s[k].saturating_add(c[k]);
        }
    }

    /// 8-bit RGB: each pixel the average of its four corners (or of its
    /// samples), clamped to [0, 1], scaled to 255 and rounded; no gamma.
    pub fn to_rgb8(&self) -> Vec<u8> {
        let (w, h) = (self.width as usize, self.height as usize);
        let mut out = Vec::with_capacity(w * h * 3);
        // Each slot is clamped to a sane range first, so that a sum of
        // four fits in an i64.
        let v = |j: usize, k: usize| self.slots[j][k].clamp(-(1 << 60), 1 << 60);
        let spp = self.sampling.per_slot() as f64;
        for y in 0..h {
            for x in 0..w {
                for k in 0..3 {
                    let mean = match self.sampling {
                        Sampling::Corners => {
                            let i = y * (w + 1) + x;
                            let sum: i64 = [i, i + 1, i + w + 1, i + w + 2]
                                .iter()
                                .map(|&j| v(j, k))
                                .sum();
                            sum as f64 * (1.0 / 4.0)
                        }
                        Sampling::Jittered { .. } => v(y * w + x, k) as f64 / spp,
                    };
                    let c = (mean * (1.0 / FIXED_ONE)).clamp(0.0, 1.0);
                    out.push((c * 255.0 + 0.5) as u8);
                }
            }
        }
        out
    }

    /// The image in linear floating point (mean per pixel, unclamped),
    /// for error measurements.
    pub fn to_rgb_f64(&self) -> Vec<[f64; 3]> {
        let (w, h) = (self.width as usize, self.height as usize);
        let mut out = Vec::with_capacity(w * h);
        let spp = self.sampling.per_slot() as f64;
        for y in 0..h {
            for x in 0..w {
                out.push(std::array::from_fn(|k| match self.sampling {
                    Sampling::Corners => {
                        let i = y * (w + 1) + x;
                        [i, i + 1, i + w + 1, i + w + 2]
                            .iter()
                            .map(|&j| self.slots[j][k] as f64)
                            .sum::<f64>()
                            / (4.0 * FIXED_ONE)
                    }
                    Sampling::Jittered { .. } => {
                        self.slots[y * w + x][k] as f64 / (spp * FIXED_ONE)
                    }
                }));
            }
        }
        out
    }

    /// The image as PNG bytes.
    pub fn png_bytes(&self) -> Result<Vec<u8>, Error> {
        let mut v = Vec::new();
        encode_png(&mut v, self.width, self.height, &self.to_rgb8())
            .map_err(|e| Error::Invalid(format!("cannot encode the image: {e}")))?;
        Ok(v)
    }

    /// Writes a PNG, atomically.
    pub fn write_png(&self, path: &Path) -> Result<(), Error> {
        write_png(path, self.width, self.height, &self.to_rgb8())
    }
}

/// Writes 8-bit RGB pixels as a PNG, atomically.
pub fn write_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), Error> {
    let tmp = temp_beside(path)?;
    encode_png(BufWriter::new(tmp.as_file()), width, height, rgb)
        .map_err(|e| Error::io(path, std::io::Error::other(e)))?;
    persist(tmp, path)
}

/// Encodes 8-bit RGB pixels as a PNG into `out`.
pub fn encode_png(
    out: impl std::io::Write,
    width: u32,
    height: u32,
    rgb: &[u8],
) -> Result<(), png::EncodingError> {
    let mut enc = png::Encoder::new(out, width, height);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::Fast);
    let mut w = enc.write_header()?;
    w.write_image_data(rgb)?;
    w.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_average_four_corners() {
        let mut f = Frame::new(2, 1);
        // Corners of row 0: 0 1 2; row 1: 3 4 5.
        for c in [0, 1, 3, 4] {
            f.add(c, to_fixed([1.0, 0.5, 0.0]));
        }
        f.add(2, to_fixed([2.0, 0.0, 0.0]));
        let rgb = f.to_rgb8();
        assert_eq!(&rgb[..3], &[255, 128, 0]);
        // Second pixel: corners 1, 2, 4, 5 = (1 + 2 + 1 + 0) / 4 = 1 -> 255.
        assert_eq!(rgb[3], 255);
        assert_eq!(rgb[4], 64);
    }

    #[test]
    fn order_does_not_matter() {
        let cs = [[0.1f32, 0.2, 0.3], [1e-7, 3.3, 0.7], [0.25, 0.125, 1e-3]];
        let mut a = Frame::new(1, 1);
        let mut b = Frame::new(1, 1);
        for c in cs {
            a.add(0, to_fixed(c));
        }
        for c in cs.iter().rev() {
            b.add(0, to_fixed(*c));
        }
        assert_eq!(a.slots, b.slots);
    }
}

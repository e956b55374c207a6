//! The frame buffer: colour summed per frame slot in fixed point, in
//! memory, or, when the image is too large for the memory budget, as
//! contributions spilled to disk and summed at the end, slot by slot in
//! order, while the image is written row by row (the paper's way: colour
//! contributions are written out and sorted).

use super::sampling::Sampling;
use crate::error::Error;
use crate::error::IoContext;
use crate::fsutil::{persist, temp_beside};
use crate::spill::{ExternalSorter, SpillDir};
use bytemuck::{Pod, Zeroable};
use image::codecs::openexr::OpenExrEncoder;
use image::{ExtendedColorType, ImageEncoder};
use std::io::Write;
use std::path::Path;

/// Colour added to a frame slot (fixed point): what a render spills when
/// its frame does not fit in memory, and what cluster workers return from
/// shading.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
#[repr(C)]
pub struct Contribution {
    pub corner: u32,
    /// The same colour goes to the `run` slots after `corner` too: a
    /// worker sends a row of eye rays that all missed (the background) as
    /// one record. 0 in a spilled frame, which adds slot by slot.
    pub run: u32,
    pub rgb: [i64; 3],
}

impl Contribution {
    /// One past the last slot this adds to.
    pub fn end(&self) -> u64 {
        self.corner as u64 + self.run as u64 + 1
    }
}

type ContributionSorter = ExternalSorter<Contribution, u32, fn(&Contribution) -> u32>;

fn contribution_slot(c: &Contribution) -> u32 {
    c.corner
}

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
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub sampling: Sampling,
    /// Row-major: (width + 1) x (height + 1) corners, or width x height
    /// pixels. Empty when the frame is spilled.
    pub slots: Vec<[i64; 3]>,
    /// The contributions, when the frame lives on disk.
    spilled: Option<Box<Spilled>>,
}

struct Spilled {
    sorter: ContributionSorter,
    /// The first failure to spill, reported when the image is written.
    error: Option<Error>,
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
            spilled: None,
        }
    }

    /// A frame kept on disk: contributions go to `spill`, at most
    /// `mem_records` of them in memory at a time, and are summed when the
    /// image is written (see [`Frame::write_image`]).
    pub fn spilled(
        width: u32,
        height: u32,
        sampling: Sampling,
        spill: &SpillDir,
        mem_records: usize,
    ) -> Frame {
        Frame {
            width,
            height,
            sampling,
            slots: Vec::new(),
            spilled: Some(Box::new(Spilled {
                sorter: ExternalSorter::new(
                    spill,
                    "frame",
                    mem_records,
                    contribution_slot as fn(&Contribution) -> u32,
                ),
                error: None,
            })),
        }
    }

    /// Bytes a frame of `slots` slots takes in memory.
    pub fn memory_bytes(slots: u64) -> u64 {
        slots * std::mem::size_of::<[i64; 3]>() as u64
    }

    /// Whether the frame lives on disk.
    pub fn is_spilled(&self) -> bool {
        self.spilled.is_some()
    }

    /// Slots per row.
    pub fn row_len(&self) -> usize {
        self.sampling.slot_grid(self.width, self.height).0 as usize
    }

    #[inline]
    pub fn add(&mut self, slot: u32, c: [i64; 3]) {
        if let Some(sp) = &mut self.spilled {
            // Adding nothing changes nothing: black misses cost no I/O.
            if c != [0; 3]
                && sp.error.is_none()
                && let Err(e) = sp.sorter.push(Contribution {
                    corner: slot,
                    run: 0,
                    rgb: c,
                })
            {
                sp.error = Some(e);
            }
            return;
        }
        let s = &mut self.slots[slot as usize];
        for k in 0..3 {
            s[k] = s[k].saturating_add(c[k]);
        }
    }

    /// Adds a contribution to each of its slots.
    pub fn add_contribution(&mut self, c: &Contribution) {
        for slot in c.corner as u64..c.end() {
            self.add(slot as u32, c.rgb);
        }
    }

    /// Each pixel's linear colour: the mean of its four corners (or of its
    /// samples), unclamped, in f64. Every encoding derives from this one
    /// computation ([`Frame::pixel_row`]), so the 8-bit and the float
    /// images of a frame agree.
    pub fn to_rgb_f64(&self) -> Vec<[f64; 3]> {
        let w = self.width as usize;
        let mut out = vec![[0.0; 3]; w * self.height as usize];
        if w > 0 {
            for (y, row) in out.chunks_exact_mut(w).enumerate() {
                self.pixel_row(y, row);
            }
        }
        out
    }

    /// Row `y` of [`Frame::to_rgb_f64`], into `out` (a row's pixels): what
    /// the PNG writer takes a row at a time, with no image-sized buffer.
    pub fn pixel_row(&self, y: usize, out: &mut [[f64; 3]]) {
        let w = self.width as usize;
        let (upper, lower) = match self.sampling {
            Sampling::Corners => (
                &self.slots[y * (w + 1)..(y + 1) * (w + 1)],
                &self.slots[(y + 1) * (w + 1)..(y + 2) * (w + 1)],
            ),
            Sampling::Jittered { .. } => (&self.slots[y * w..(y + 1) * w], &[][..]),
        };
        pixel_means(self.sampling, upper, lower, out);
    }

    /// 8-bit RGB: each pixel the average of its four corners (or of its
    /// samples), clamped to [0, 1], scaled to 255 and rounded; no gamma.
    pub fn to_rgb8(&self) -> Vec<u8> {
        self.to_rgb_f64()
            .iter()
            .flatten()
            .map(|&c| to_u8(c))
            .collect()
    }

    /// Linear 32-bit float RGB, unclamped: each pixel's mean as in
    /// [`Frame::to_rgb8`] before clamping, rounded to f32. Where rounding
    /// to f32 would carry a value across an 8-bit rounding boundary (a
    /// value within an f32 rounding step of (k + 0.5) / 255), it is moved
    /// one step back to the side the f64 mean is on, so that every value
    /// here, clamped, scaled and rounded, is exactly the 8-bit image's.
    pub fn to_rgb_f32(&self) -> Vec<[f32; 3]> {
        self.to_rgb_f64()
            .iter()
            .map(|p| p.map(to_f32_matching_u8))
            .collect()
    }

    /// Writes the image as `format` to `out`, row by row where it can: a
    /// spilled frame is summed slot by slot in order as rows are written,
    /// so no more than two rows of slots are ever in memory. OpenEXR needs
    /// the whole image in memory, so a spilled frame refuses it.
    pub fn write_image(self, format: ImageFormat, out: &mut dyn Write) -> Result<(), Error> {
        let (w, h) = (self.width, self.height);
        match (format, self.spilled.is_some()) {
            (ImageFormat::Exr, true) => Err(Error::Invalid(format!(
                "a {w}x{h} OpenEXR image must be held whole in memory ({}), more than this render's budget allows; write .png, or give a larger --memory",
                crate::units::fmt_bytes(w as u64 * h as u64 * 12)
            ))),
            (ImageFormat::Exr, false) => out
                .write_all(&self.encode(format)?)
                .map_err(|e| Error::Invalid(format!("cannot write the image: {e}"))),
            (ImageFormat::Png, false) => self.write_png(out),
            (ImageFormat::Png, true) => {
                let mut rows = PixelRows::new(self)?;
                let mut row = vec![[0.0f64; 3]; w as usize];
                write_png(w, h, out, |bytes| {
                    rows.next_row(&mut row)?;
                    for (b, c) in bytes.iter_mut().zip(row.iter().flatten()) {
                        *b = to_u8(*c);
                    }
                    Ok(())
                })
            }
        }
    }

    /// Writes a frame held in memory as PNG, with the same encoder as a
    /// spilled frame's, so that an image does not depend on the budget
    /// down to its bytes.
    fn write_png(&self, out: &mut dyn Write) -> Result<(), Error> {
        // A row at a time: no image of floats and of bytes held whole (a
        // 4096x4096 frame would take 400 MB and 50 MB more).
        let mut row = vec![[0.0f64; 3]; self.width as usize];
        let mut y = 0;
        write_png(self.width, self.height, out, |bytes| {
            self.pixel_row(y, &mut row);
            y += 1;
            for (b, c) in bytes.iter_mut().zip(row.iter().flatten()) {
                *b = to_u8(*c);
            }
            Ok(())
        })
    }

    /// The image encoded as `format` (a frame in memory).
    pub fn encode(&self, format: ImageFormat) -> Result<Vec<u8>, Error> {
        let mut out = std::io::Cursor::new(Vec::new());
        let (w, h) = (self.width, self.height);
        match format {
            ImageFormat::Png => self.write_png(&mut out)?,
            ImageFormat::Exr => OpenExrEncoder::new(&mut out)
                .write_image(
                    bytemuck::cast_slice(&self.to_rgb_f32()),
                    w,
                    h,
                    ExtendedColorType::Rgb32F,
                )
                .map_err(|e| Error::Invalid(format!("cannot encode the image as {format}: {e}")))?,
        }
        Ok(out.into_inner())
    }

    /// Writes the image to `path`, atomically, in the format its extension
    /// names.
    pub fn write(&self, path: &Path) -> Result<(), Error> {
        let bytes = self.encode(ImageFormat::from_path(path)?)?;
        let mut tmp = temp_beside(path)?;
        tmp.write_all(&bytes).at(path)?;
        persist(tmp, path)
    }
}

/// Writes an 8-bit RGB PNG of `w` x `h` pixels, row by row: `row` fills
/// each row's bytes in turn, top to bottom.
fn write_png(
    w: u32,
    h: u32,
    out: &mut dyn Write,
    mut row: impl FnMut(&mut [u8]) -> Result<(), Error>,
) -> Result<(), Error> {
    let err =
        |e: png::EncodingError| Error::Invalid(format!("cannot encode the image as PNG: {e}"));
    let mut enc = png::Encoder::new(out, w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::Fast);
    let mut writer = enc.write_header().map_err(err)?;
    let mut stream = writer.stream_writer().map_err(err)?;
    let mut bytes = vec![0u8; 3 * w as usize];
    for _ in 0..h {
        row(&mut bytes)?;
        stream
            .write_all(&bytes)
            .map_err(|e| Error::Invalid(format!("cannot write the image: {e}")))?;
    }
    stream.finish().map_err(err)
}

/// A spilled frame's pixels, a row at a time: contributions in slot order
/// summed into at most two rows of slots (a pixel row needs two rows of
/// corners).
struct PixelRows {
    width: usize,
    height: usize,
    sampling: Sampling,
    contributions: crate::spill::Sorted<Contribution, u32, fn(&Contribution) -> u32>,
    /// The next contribution not yet summed.
    pending: Option<Contribution>,
    /// Slot rows `y` and `y + 1` (corners), or row `y` (pixels).
    upper: Vec<[i64; 3]>,
    lower: Vec<[i64; 3]>,
    y: usize,
}

impl PixelRows {
    fn new(frame: Frame) -> Result<PixelRows, Error> {
        let sp = frame.spilled.expect("a spilled frame");
        if let Some(e) = sp.error {
            return Err(e);
        }
        let (slots_per_row, _) = frame.sampling.slot_grid(frame.width, frame.height);
        let mut rows = PixelRows {
            width: frame.width as usize,
            height: frame.height as usize,
            sampling: frame.sampling,
            contributions: sp.sorter.finish()?,
            pending: None,
            upper: vec![[0; 3]; slots_per_row as usize],
            lower: vec![[0; 3]; slots_per_row as usize],
            y: 0,
        };
        rows.pending = rows.contributions.next()?;
        rows.fill(0, true)?;
        if rows.sampling == Sampling::Corners {
            rows.fill(1, false)?;
        }
        Ok(rows)
    }

    /// Sums slot row `row` into the upper (or lower) buffer.
    fn fill(&mut self, row: usize, upper: bool) -> Result<(), Error> {
        let n = self.upper.len();
        let buf = if upper {
            &mut self.upper
        } else {
            &mut self.lower
        };
        buf.fill([0; 3]);
        let (lo, hi) = ((row * n) as u64, ((row + 1) * n) as u64);
        while let Some(c) = self.pending {
            let slot = c.corner as u64;
            if slot >= hi {
                break;
            }
            if slot >= lo {
                let s = &mut buf[(slot - lo) as usize];
                for k in 0..3 {
                    s[k] = s[k].saturating_add(c.rgb[k]);
                }
            }
            self.pending = self.contributions.next()?;
        }
        Ok(())
    }

    /// The next row of pixel means (as [`Frame::to_rgb_f64`] computes
    /// them), or false after the last.
    fn next_row(&mut self, out: &mut [[f64; 3]]) -> Result<bool, Error> {
        if self.y == self.height {
            return Ok(false);
        }
        let n = self.width.min(out.len());
        pixel_means(self.sampling, &self.upper, &self.lower, &mut out[..n]);
        self.y += 1;
        if self.y < self.height {
            match self.sampling {
                Sampling::Corners => {
                    std::mem::swap(&mut self.upper, &mut self.lower);
                    self.fill(self.y + 1, false)?;
                }
                Sampling::Jittered { .. } => self.fill(self.y, true)?,
            }
        }
        Ok(true)
    }
}

/// A row of pixel means into `out`: of the corners in `upper` and
/// `lower` (the rows of slots above and below the pixels), or of the
/// samples in `upper` (jittered sampling; `lower` unused). The one place
/// a frame's pixels are computed, in memory or spilled.
fn pixel_means(sampling: Sampling, upper: &[[i64; 3]], lower: &[[i64; 3]], out: &mut [[f64; 3]]) {
    // Each slot is clamped to a sane range first, so that a sum of four
    // fits in an i64.
    let v = |s: &[i64; 3], k: usize| s[k].clamp(-(1 << 60), 1 << 60);
    // The sampling is matched once a row, not per channel, and the
    // channels are spelled out (`array::from_fn` was left a call per
    // channel, 80 % of the time): this runs for every pixel of every
    // image (a coordinator's whole frame at a job's end).
    match sampling {
        Sampling::Corners => {
            let corners = upper.windows(2).zip(lower.windows(2));
            for ((t, b), px) in corners.zip(out.iter_mut()) {
                let mean = |k| {
                    let sum = v(&t[0], k) + v(&t[1], k) + v(&b[0], k) + v(&b[1], k);
                    sum as f64 * (1.0 / 4.0) * (1.0 / FIXED_ONE)
                };
                *px = [mean(0), mean(1), mean(2)];
            }
        }
        Sampling::Jittered { .. } => {
            let spp = sampling.per_slot() as f64;
            for (s, px) in upper.iter().zip(out.iter_mut()) {
                let mean = |k| v(s, k) as f64 / spp * (1.0 / FIXED_ONE);
                *px = [mean(0), mean(1), mean(2)];
            }
        }
    }
}

/// A pixel value in [0, 1] as 8 bits: clamped, scaled, rounded.
#[inline]
fn to_u8(c: f64) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// `c` as the nearest f32, unless that lands on the other side of an 8-bit
/// rounding boundary than `c` (see [`Frame::to_rgb_f32`]): then the next
/// f32 towards `c`, which is on `c`'s side (the boundary lies between `c`
/// and its nearest f32, so within half a step of `c`).
fn to_f32_matching_u8(c: f64) -> f32 {
    let v = c as f32;
    if to_u8(v as f64) == to_u8(c) {
        return v;
    }
    let toward = if (v as f64) < c {
        f32::from_bits(if v >= 0.0 {
            v.to_bits() + 1
        } else {
            v.to_bits() - 1
        })
    } else {
        f32::from_bits(if v > 0.0 {
            v.to_bits() - 1
        } else {
            v.to_bits() + 1
        })
    };
    debug_assert_eq!(to_u8(toward as f64), to_u8(c));
    toward
}

/// Image file formats, chosen by the output file's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// 8-bit RGB, clamped to [0, 1]; no gamma.
    Png,
    /// OpenEXR, linear 32-bit float RGB, unclamped: for compositing.
    Exr,
}

impl ImageFormat {
    /// The extensions this writes, for messages.
    pub const SUPPORTED: &'static str = ".png (8-bit) or .exr (OpenEXR, 32-bit float)";

    /// The format an output path's extension names (case-insensitive).
    pub fn from_path(path: &Path) -> Result<ImageFormat, Error> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        match ext.as_deref() {
            Some("png") => Ok(ImageFormat::Png),
            Some("exr") => Ok(ImageFormat::Exr),
            _ => Err(Error::Invalid(format!(
                "{}: cannot tell the image format from the extension: the output must end in {}",
                path.display(),
                ImageFormat::SUPPORTED
            ))),
        }
    }
}

impl std::fmt::Display for ImageFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ImageFormat::Png => "PNG",
            ImageFormat::Exr => "OpenEXR",
        })
    }
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
    fn a_run_adds_its_colour_to_each_of_its_slots() {
        let mut a = Frame::new(3, 1);
        let mut b = Frame::new(3, 1);
        let c = to_fixed([0.25, 0.5, 1.0]);
        a.add_contribution(&Contribution {
            corner: 1,
            run: 2,
            rgb: c,
        });
        for slot in 1..=3 {
            b.add(slot, c);
        }
        assert_eq!(a.slots, b.slots);
        assert_eq!(a.slots[0], [0; 3]);
        assert_eq!(a.slots[4], [0; 3]);
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

    #[test]
    fn float_image_is_the_mean_unclamped() {
        let mut f = Frame::new(2, 1);
        for c in [0, 1, 3, 4] {
            f.add(c, to_fixed([1.0, 0.5, 0.0]));
        }
        f.add(2, to_fixed([6.0, 0.0, 0.0]));
        let px = f.to_rgb_f32();
        assert_eq!(px[0], [1.0, 0.5, 0.0]);
        // (1 + 6 + 1 + 0) / 4 = 2: above 1, kept.
        assert_eq!(px[1], [2.0, 0.25, 0.0]);
        assert_eq!(f.to_rgb8(), [255, 128, 0, 255, 64, 0]);
    }

    #[test]
    fn float_values_round_to_the_8_bit_values() {
        // Values on both sides of, and very near, every 8-bit rounding
        // boundary: a plain cast to f32 crosses some of them.
        let mut crossed = 0;
        for k in 0..255 {
            let b = (k as f64 + 0.5) / 255.0;
            for i in -64i64..=64 {
                let c = b + i as f64 * 1e-10;
                let v = to_f32_matching_u8(c);
                assert_eq!(to_u8(v as f64), to_u8(c), "{c}");
                assert!((v as f64 - c).abs() <= c * 2e-7, "{c} -> {v}");
                crossed += (to_u8(c as f32 as f64) != to_u8(c)) as u32;
            }
        }
        assert!(crossed > 0, "no boundary case was exercised");
        assert_eq!(to_f32_matching_u8(-0.25), -0.25);
        assert_eq!(to_f32_matching_u8(3.5), 3.5);
    }

    #[test]
    fn format_follows_the_extension() {
        for (p, f) in [
            ("a.png", ImageFormat::Png),
            ("dir/b.PNG", ImageFormat::Png),
            ("c.exr", ImageFormat::Exr),
            ("d.Exr", ImageFormat::Exr),
        ] {
            assert_eq!(ImageFormat::from_path(Path::new(p)).unwrap(), f, "{p}");
        }
        for p in ["a.jpg", "b", "c.png.tmp", ".exr"] {
            let e = ImageFormat::from_path(Path::new(p))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(".png") && e.contains(".exr") && e.contains(p),
                "{e}"
            );
        }
    }

    #[test]
    fn encodings_decode_to_the_frame() {
        let mut f = Frame::new(3, 2);
        for (i, s) in f.slots.iter_mut().enumerate() {
            *s = to_fixed([i as f32 * 0.3, 0.1, 1.0 - i as f32 * 0.1]);
        }
        let png = image::load_from_memory(&f.encode(ImageFormat::Png).unwrap()).unwrap();
        assert_eq!(png.color(), image::ColorType::Rgb8);
        assert_eq!(png.into_rgb8().into_raw(), f.to_rgb8());
        let exr = image::load_from_memory(&f.encode(ImageFormat::Exr).unwrap()).unwrap();
        assert_eq!(exr.color(), image::ColorType::Rgb32F);
        let want: Vec<f32> = f.to_rgb_f32().concat();
        assert_eq!(exr.into_rgb32f().into_raw(), want);
    }
}

//! Textures: images decoded with the `image` crate (PNG, JPEG) and sampled
//! as a glTF sampler says (wrap modes, nearest or bilinear filtering),
//! through `KHR_texture_transform`'s offset, rotation and scale.
//!
//! Texture coordinates follow glTF: (0, 0) is the image's upper-left
//! corner, (1, 1) its lower-right one, and texel `(i, j)` covers
//! `[i/w, (i+1)/w] x [j/h, (j+1)/h]`, its centre at `((i+0.5)/w,
//! (j+0.5)/h)`. Colour textures (base colour, emissive) are sRGB-encoded
//! and decoded to linear values; data textures (metallic-roughness,
//! normals) are taken as they are. KTX2 and Basis Universal images
//! (`KHR_texture_basisu`) are refused with a message naming the
//! extension. Sampling is a pure function of the texture and the
//! coordinates, so every tracer and thread gets the same colour.

use crate::error::Error;
use std::sync::Arc;

pub mod mip;
pub mod store;

pub use mip::{Level, TILE, TileTexels};
pub use store::{TileReads, TileRef, TileStore};

/// How coordinates outside [0, 1] map into the image (glTF's
/// `wrapS`/`wrapT`: 10497, 33071, 33648).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wrap {
    Repeat,
    ClampToEdge,
    MirroredRepeat,
}

impl Wrap {
    /// The wrap mode of a glTF sampler's code (repeat if unknown, glTF's
    /// default).
    pub fn from_gltf(code: u32) -> Wrap {
        match code {
            33071 => Wrap::ClampToEdge,
            33648 => Wrap::MirroredRepeat,
            _ => Wrap::Repeat,
        }
    }

    /// Texel index `i` of a row or column of `n` texels, wrapped.
    #[inline]
    fn index(self, i: i64, n: u32) -> u32 {
        let n = n as i64;
        (match self {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::ClampToEdge => i.clamp(0, n - 1),
            Wrap::MirroredRepeat => {
                let m = i.rem_euclid(2 * n);
                if m >= n { 2 * n - 1 - m } else { m }
            }
        }) as u32
    }
}

/// Magnification filter: nearest texel or bilinear between four.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Filter {
    Nearest,
    Linear,
}

impl Filter {
    /// The filter of a glTF sampler's `magFilter` (9728 nearest, 9729
    /// linear; linear if absent, as viewers do).
    pub fn from_gltf(code: Option<u32>) -> Filter {
        match code {
            Some(9728) => Filter::Nearest,
            _ => Filter::Linear,
        }
    }
}

/// A glTF sampler.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sampler {
    pub wrap_s: Wrap,
    pub wrap_t: Wrap,
    pub filter: Filter,
}

impl Default for Sampler {
    fn default() -> Self {
        Sampler {
            wrap_s: Wrap::Repeat,
            wrap_t: Wrap::Repeat,
            filter: Filter::Linear,
        }
    }
}

/// `KHR_texture_transform`: texture coordinates scaled, rotated (radians,
/// counter-clockwise in the image as displayed) and offset, in that order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvTransform {
    pub offset: [f32; 2],
    pub rotation: f32,
    pub scale: [f32; 2],
}

impl Default for UvTransform {
    fn default() -> Self {
        UvTransform {
            offset: [0.0; 2],
            rotation: 0.0,
            scale: [1.0; 2],
        }
    }
}

impl UvTransform {
    /// The coordinates mapped: `T * R * S * uv` with the extension's
    /// matrices.
    pub fn apply(&self, uv: [f32; 2]) -> [f32; 2] {
        let (s, c) = (self.rotation as f64).sin_cos();
        let (x, y) = (
            uv[0] as f64 * self.scale[0] as f64,
            uv[1] as f64 * self.scale[1] as f64,
        );
        [
            (c * x + s * y + self.offset[0] as f64) as f32,
            (-s * x + c * y + self.offset[1] as f64) as f32,
        ]
    }
}

/// Whether a texture holds colours (sRGB-encoded) or data (linear).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    Srgb,
    Linear,
}

/// A texture: its mip chain ([`mip`]) as tiles of 8-bit RGBA (4 bytes a
/// texel), held in memory or read from a database through a
/// [`TileStore`], turned into linear values as they are read.
#[derive(Debug)]
pub struct Texture {
    pub width: u32,
    pub height: u32,
    levels: Vec<Level>,
    tiles: Tiles,
    /// Each 8-bit colour value's linear value (alpha is always linear).
    linear: Box<[f32; 256]>,
}

/// Where a texture's tiles are.
#[derive(Debug)]
enum Tiles {
    /// In memory (an image decoded when the render starts, or a test's).
    Held(Vec<Box<TileTexels>>),
    /// In a database, read through the store's cache: texture `index` of
    /// the store, its tiles at `refs`.
    Stored {
        store: Arc<TileStore>,
        index: u32,
        refs: Vec<TileRef>,
    },
}

/// The KTX2 file identifier.
const KTX2_MAGIC: [u8; 12] = [
    0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A,
];

/// sRGB-encoded `c` in [0, 1] to linear.
fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The linear value of each 8-bit value of `encoding`.
fn lut(encoding: Encoding) -> Box<[f32; 256]> {
    Box::new(std::array::from_fn(|v| {
        let c = v as f32 / 255.0;
        match encoding {
            Encoding::Srgb => srgb_to_linear(c),
            Encoding::Linear => c,
        }
    }))
}

/// Decodes a PNG or JPEG image to its width, height and 8-bit RGBA
/// texels, row by row from the top; `what` names it in errors (a file
/// and the image's index).
pub fn decode_rgba8(bytes: &[u8], what: &str) -> Result<(u32, u32, Vec<[u8; 4]>), Error> {
    if bytes.starts_with(&KTX2_MAGIC) || bytes.starts_with(b"sB") {
        return Err(Error::Scene(format!(
            "{what}: a KTX2/Basis Universal texture (KHR_texture_basisu) is not supported; \
             convert it to PNG or JPEG"
        )));
    }
    let format = image::guess_format(bytes)
        .map_err(|e| Error::Scene(format!("{what}: not an image sray reads ({e})")))?;
    if !matches!(format, image::ImageFormat::Png | image::ImageFormat::Jpeg) {
        return Err(Error::Scene(format!(
            "{what}: {format:?} textures are not supported (PNG and JPEG are)"
        )));
    }
    let img = image::load_from_memory_with_format(bytes, format)
        .map_err(|e| Error::Scene(format!("{what}: {e}")))?
        .into_rgba8();
    let (width, height) = img.dimensions();
    if width == 0 || height == 0 {
        return Err(Error::Scene(format!("{what}: the image is empty")));
    }
    Ok((width, height, img.pixels().map(|p| p.0).collect()))
}

impl Texture {
    /// A texture of `width` x `height` linear RGBA texels in [0, 1], row by
    /// row from the top, kept as 8-bit values (rounded).
    pub fn from_texels(width: u32, height: u32, texels: Vec<[f32; 4]>) -> Texture {
        assert_eq!(texels.len(), width as usize * height as usize);
        assert!(width > 0 && height > 0);
        let q = |c: f32| (c.clamp(0.0, 1.0) * 255.0).round() as u8;
        let texels = texels.iter().map(|t| t.map(q)).collect();
        Self::held(width, height, texels, Encoding::Linear)
    }

    /// Decodes a PNG or JPEG image ([`decode_rgba8`]) and makes its mip
    /// chain, held in memory.
    pub fn decode(bytes: &[u8], what: &str, encoding: Encoding) -> Result<Texture, Error> {
        let (width, height, texels) = decode_rgba8(bytes, what)?;
        Ok(Self::held(width, height, texels, encoding))
    }

    /// The mip chain of `texels` (`width` x `height`, row by row), held.
    pub fn held(width: u32, height: u32, texels: Vec<[u8; 4]>, encoding: Encoding) -> Texture {
        let (levels, n) = mip::levels(width, height).expect("a texture has texels");
        let mut tiles = Vec::with_capacity(n as usize);
        mip::for_each_tile(texels, width, height, encoding, |t, _, _| {
            tiles.push(Box::new(*t));
            Ok::<_, ()>(())
        })
        .expect("held tiles");
        Texture {
            width,
            height,
            levels,
            tiles: Tiles::Held(tiles),
            linear: lut(encoding),
        }
    }

    /// Texture `index` of `store`, `width` x `height` texels whose chain's
    /// tiles lie at `refs`; an error when `refs` are not as many as the
    /// chain has tiles.
    pub fn stored(
        width: u32,
        height: u32,
        encoding: Encoding,
        store: Arc<TileStore>,
        index: u32,
        refs: Vec<TileRef>,
    ) -> Result<Texture, String> {
        let (levels, n) = mip::levels(width, height)
            .ok_or_else(|| format!("texture {index} is {width} x {height} texels"))?;
        if refs.len() != n as usize {
            return Err(format!(
                "texture {index} lists {} tiles, its {width} x {height} mip chain has {n}",
                refs.len()
            ));
        }
        Ok(Texture {
            width,
            height,
            levels,
            tiles: Tiles::Stored { store, index, refs },
            linear: lut(encoding),
        })
    }

    /// The error of the store its tiles are read from, if a read failed.
    pub fn store_error(&self) -> Option<Error> {
        match &self.tiles {
            Tiles::Stored { store, .. } => store.error(),
            Tiles::Held(_) => None,
        }
    }

    /// What the store its tiles are read from has read (`None` when they
    /// are held).
    pub fn store_reads(&self) -> Option<TileReads> {
        match &self.tiles {
            Tiles::Stored { store, .. } => Some(store.reads()),
            Tiles::Held(_) => None,
        }
    }

    /// Levels of its mip chain.
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// The level whose texels best match a footprint `texels` texels of
    /// the finest level wide: the finest level whose texel is no wider
    /// than the footprint (level `k` has texels `2^k` wide). Made with
    /// comparisons only, so every machine picks the same level.
    pub fn level_for(&self, texels: f64) -> usize {
        let mut level = 0;
        let mut width = 2.0;
        while level + 1 < self.levels.len() && width <= texels {
            level += 1;
            width *= 2.0;
        }
        level
    }

    #[inline]
    fn with_tile<R>(&self, tile: u32, f: impl FnOnce(&TileTexels) -> R) -> R {
        match &self.tiles {
            Tiles::Held(t) => f(&t[tile as usize]),
            Tiles::Stored { store, index, refs } => {
                f(&store.tile(*index, tile, &refs[tile as usize], || self.extent(tile)))
            }
        }
    }

    /// Columns and rows of tile `tile` of the chain inside its level.
    fn extent(&self, tile: u32) -> (u32, u32) {
        let l = self
            .levels
            .iter()
            .rev()
            .find(|l| l.first_tile <= tile)
            .expect("the first level starts at tile 0");
        let k = tile - l.first_tile;
        l.extent(k % l.tiles_x(), k / l.tiles_x())
    }

    #[inline]
    fn linear(&self, p: [u8; 4]) -> [f32; 4] {
        [
            self.linear[p[0] as usize],
            self.linear[p[1] as usize],
            self.linear[p[2] as usize],
            p[3] as f32 / 255.0,
        ]
    }

    /// Texel `(i, j)` of the finest level: column `i`, row `j` from the
    /// top.
    #[inline]
    pub fn texel(&self, i: u32, j: u32) -> [f32; 4] {
        self.texel_at(0, i, j)
    }

    /// Texel `(i, j)` of level `level`.
    pub fn texel_at(&self, level: usize, i: u32, j: u32) -> [f32; 4] {
        let (tile, at) = self.levels[level].locate(i, j);
        let p = self.with_tile(tile, |t| t[at]);
        self.linear(p)
    }

    /// Bytes its tiles take in memory (none when they are read from a
    /// database).
    pub fn bytes(&self) -> usize {
        match &self.tiles {
            Tiles::Held(t) => t.len() * mip::TILE_BYTES,
            Tiles::Stored { .. } => 0,
        }
    }

    /// The tile a sample at `uv` of level `level` starts in (the tile of
    /// its upper-left texel), for sorting lookups by the tiles they read.
    pub fn tile_of(&self, s: &Sampler, uv: [f32; 2], level: usize) -> u32 {
        let l = &self.levels[level.min(self.levels.len() - 1)];
        let (i, j) = match self.place(s, uv, l) {
            Place::Nearest(i, j) => (i, j),
            Place::Linear { i, j, .. } => (i[0], j[0]),
        };
        l.locate(i, j).0
    }

    /// The finest level at coordinates `uv` as `s` samples it.
    pub fn sample(&self, s: &Sampler, uv: [f32; 2]) -> [f32; 4] {
        self.sample_level(s, uv, 0)
    }

    /// Level `level` (clamped to the chain) at coordinates `uv` as `s`
    /// samples it.
    pub fn sample_level(&self, s: &Sampler, uv: [f32; 2], level: usize) -> [f32; 4] {
        let l = &self.levels[level.min(self.levels.len() - 1)];
        match self.place(s, uv, l) {
            Place::Nearest(i, j) => {
                let (tile, at) = l.locate(i, j);
                self.linear(self.with_tile(tile, |t| t[at]))
            }
            Place::Linear { i, j, fx, fy } => {
                let corners = [(i[0], j[0]), (i[1], j[0]), (i[0], j[1]), (i[1], j[1])];
                let at = corners.map(|(i, j)| l.locate(i, j));
                // Mostly all four in one tile: fetch it once.
                let p = if at.iter().all(|a| a.0 == at[0].0) {
                    self.with_tile(at[0].0, |t| at.map(|a| t[a.1]))
                } else {
                    at.map(|a| self.with_tile(a.0, |t| t[a.1]))
                };
                let [a, b, c, d] = p.map(|p| self.linear(p));
                std::array::from_fn(|k| {
                    let top = a[k] + (b[k] - a[k]) * fx;
                    let bottom = c[k] + (d[k] - c[k]) * fx;
                    top + (bottom - top) * fy
                })
            }
        }
    }

    /// The texels a sample at `uv` of level `l` reads.
    #[inline]
    fn place(&self, s: &Sampler, uv: [f32; 2], l: &Level) -> Place {
        let x = uv[0] as f64 * l.width as f64;
        let y = uv[1] as f64 * l.height as f64;
        if !(x.is_finite() && y.is_finite()) {
            return Place::Nearest(0, 0);
        }
        // Far outside, every wrap mode repeats or clamps: keep the
        // indices in range of i64.
        let (x, y) = (x.clamp(-1e15, 1e15), y.clamp(-1e15, 1e15));
        match s.filter {
            Filter::Nearest => Place::Nearest(
                s.wrap_s.index(x.floor() as i64, l.width),
                s.wrap_t.index(y.floor() as i64, l.height),
            ),
            Filter::Linear => {
                let (x, y) = (x - 0.5, y - 0.5);
                let (x0, y0) = (x.floor(), y.floor());
                let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
                let (x0, y0) = (x0 as i64, y0 as i64);
                Place::Linear {
                    i: [s.wrap_s.index(x0, l.width), s.wrap_s.index(x0 + 1, l.width)],
                    j: [
                        s.wrap_t.index(y0, l.height),
                        s.wrap_t.index(y0 + 1, l.height),
                    ],
                    fx,
                    fy,
                }
            }
        }
    }
}

/// The texels of one sample: one, or four with their weights.
enum Place {
    Nearest(u32, u32),
    Linear {
        i: [u32; 2],
        j: [u32; 2],
        fx: f32,
        fy: f32,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4 x 2 pattern whose texel (i, j) has red i/4 and green j/2.
    fn pattern() -> Texture {
        let texels = (0..2)
            .flat_map(|j| (0..4).map(move |i| [i as f32 / 4.0, j as f32 / 2.0, 0.5, 1.0]))
            .collect();
        Texture::from_texels(4, 2, texels)
    }

    fn sampler(wrap: Wrap, filter: Filter) -> Sampler {
        Sampler {
            wrap_s: wrap,
            wrap_t: wrap,
            filter,
        }
    }

    #[test]
    fn nearest_finds_each_texel_over_its_square_and_wraps() {
        let t = pattern();
        let s = sampler(Wrap::Repeat, Filter::Nearest);
        for j in 0..2 {
            for i in 0..4 {
                for (fu, fv) in [(0.01, 0.01), (0.5, 0.5), (0.99, 0.99)] {
                    let uv = [(i as f32 + fu) / 4.0, (j as f32 + fv) / 2.0];
                    assert_eq!(t.sample(&s, uv), t.texel(i, j), "{uv:?}");
                    // One period further, the same texel.
                    assert_eq!(t.sample(&s, [uv[0] + 1.0, uv[1] - 3.0]), t.texel(i, j));
                }
            }
        }
        let c = sampler(Wrap::ClampToEdge, Filter::Nearest);
        assert_eq!(t.sample(&c, [1.7, -0.3]), t.texel(3, 0));
        let m = sampler(Wrap::MirroredRepeat, Filter::Nearest);
        // Just past the right edge, the mirror shows the last column.
        assert_eq!(t.sample(&m, [1.1, 0.25]), t.texel(3, 0));
        assert_eq!(t.sample(&m, [-0.1, 0.25]), t.texel(0, 0));
        assert_eq!(t.sample(&m, [1.9, 0.25]), t.texel(0, 0));
    }

    #[test]
    fn bilinear_is_each_texel_at_its_centre_and_the_mean_between() {
        let t = pattern();
        let s = sampler(Wrap::ClampToEdge, Filter::Linear);
        for j in 0..2 {
            for i in 0..4 {
                let uv = [(i as f32 + 0.5) / 4.0, (j as f32 + 0.5) / 2.0];
                assert_eq!(t.sample(&s, uv), t.texel(i, j), "{uv:?}");
            }
        }
        // Halfway between the centres of texels (1, 0) and (2, 1).
        let got = t.sample(&s, [0.5, 0.5]);
        let want: [f32; 4] = std::array::from_fn(|k| {
            (t.texel(1, 0)[k] + t.texel(2, 0)[k] + t.texel(1, 1)[k] + t.texel(2, 1)[k]) / 4.0
        });
        for k in 0..4 {
            assert!((got[k] - want[k]).abs() < 1e-6, "{got:?} {want:?}");
        }
        // Repeat blends the last column with the first across the edge.
        let r = sampler(Wrap::Repeat, Filter::Linear);
        let edge = t.sample(&r, [0.0, 0.25]);
        assert!((edge[0] - (t.texel(3, 0)[0] + t.texel(0, 0)[0]) / 2.0).abs() < 1e-6);
    }

    /// A reference: level `texels` (`w` x `h`) sampled bilinearly with
    /// wrap `r`, straight from the array (no tiles).
    fn reference(texels: &[[u8; 4]], w: u32, h: u32, uv: [f32; 2], r: Wrap) -> [f32; 4] {
        let lut = lut(Encoding::Srgb);
        let at = |i: i64, j: i64| {
            let p = texels[(r.index(j, h) * w + r.index(i, w)) as usize];
            [
                lut[p[0] as usize],
                lut[p[1] as usize],
                lut[p[2] as usize],
                p[3] as f32 / 255.0,
            ]
        };
        let (x, y) = (uv[0] as f64 * w as f64 - 0.5, uv[1] as f64 * h as f64 - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let (i, j) = (x0 as i64, y0 as i64);
        let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
        std::array::from_fn(|k| {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bottom = c[k] + (d[k] - c[k]) * fx;
            top + (bottom - top) * fy
        })
    }

    #[test]
    fn tiles_sample_as_the_whole_level_across_tile_edges_at_every_level() {
        let (w, h) = (300u32, 130u32);
        let texels: Vec<[u8; 4]> = (0..w * h)
            .map(|v| {
                let (i, j) = (v % w, v / w);
                [
                    (i * 7 + j) as u8,
                    (j * 3) as u8,
                    (i ^ j) as u8,
                    (255 - i % 200) as u8,
                ]
            })
            .collect();
        let t = Texture::held(w, h, texels.clone(), Encoding::Srgb);
        assert_eq!(t.levels(), 9);
        let mut level = texels;
        let (mut lw, mut lh) = (w, h);
        for l in 0..t.levels() {
            for r in [Wrap::Repeat, Wrap::ClampToEdge, Wrap::MirroredRepeat] {
                let s = sampler(r, Filter::Linear);
                for k in 0..400 {
                    // Points across the whole texture and past its edges,
                    // on tile edges too (64 texels apart at level 0).
                    let uv = [
                        -0.2 + 1.4 * ((k * 37) % 400) as f32 / 400.0,
                        -0.2 + 1.4 * ((k * 91) % 400) as f32 / 400.0,
                    ];
                    assert_eq!(
                        t.sample_level(&s, uv, l),
                        reference(&level, lw, lh, uv, r),
                        "level {l} {r:?} at {uv:?}"
                    );
                }
                let edge = [64.0 / lw as f32, 64.0 / lh as f32];
                assert_eq!(
                    t.sample_level(&s, edge, l),
                    reference(&level, lw, lh, edge, r)
                );
            }
            level = mip::downsample(&level, lw, lh, Encoding::Srgb);
            (lw, lh) = ((lw / 2).max(1), (lh / 2).max(1));
        }
    }

    #[test]
    fn the_level_is_the_finest_whose_texels_are_no_wider_than_the_footprint() {
        let t = Texture::held(256, 64, vec![[0; 4]; 256 * 64], Encoding::Linear);
        assert_eq!(t.levels(), 9);
        let got: Vec<usize> = [0.0, 0.5, 1.0, 1.99, 2.0, 3.9, 4.0, 100.0, 1e9, f64::NAN]
            .iter()
            .map(|&x| t.level_for(x))
            .collect();
        assert_eq!(got, [0, 0, 0, 0, 1, 1, 2, 6, 8, 0]);
    }

    #[test]
    fn the_texture_transform_scales_rotates_and_offsets() {
        let tr = UvTransform {
            offset: [0.5, 0.25],
            rotation: std::f32::consts::FRAC_PI_2,
            scale: [2.0, 3.0],
        };
        // Scaled to (2, 0), rotated a quarter turn to (0, -2), offset.
        let got = tr.apply([1.0, 0.0]);
        assert!(
            (got[0] - 0.5).abs() < 1e-6 && (got[1] + 1.75).abs() < 1e-6,
            "{got:?}"
        );
        assert_eq!(UvTransform::default().apply([0.3, 0.7]), [0.3, 0.7]);
    }

    #[test]
    fn png_decodes_to_linear_texels_and_ktx2_is_refused_by_name() {
        let mut img = image::RgbaImage::new(2, 1);
        img.put_pixel(0, 0, image::Rgba([255, 0, 188, 255]));
        img.put_pixel(1, 0, image::Rgba([0, 255, 0, 128]));
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let t = Texture::decode(&png, "t.png", Encoding::Srgb).unwrap();
        assert_eq!((t.width, t.height), (2, 1));
        let a = t.texel(0, 0);
        assert_eq!((a[0], a[1], a[3]), (1.0, 0.0, 1.0));
        // sRGB 188 is about half the light of 255.
        assert!((a[2] - 0.5029).abs() < 1e-3, "{a:?}");
        assert!((t.texel(1, 0)[3] - 128.0 / 255.0).abs() < 1e-6);
        let lin = Texture::decode(&png, "t.png", Encoding::Linear).unwrap();
        assert!((lin.texel(0, 0)[2] - 188.0 / 255.0).abs() < 1e-6);
        // A flat grey JPEG decodes to about that grey.
        let grey = image::RgbImage::from_pixel(8, 8, image::Rgb([128, 128, 128]));
        let mut jpg = Vec::new();
        grey.write_to(
            &mut std::io::Cursor::new(&mut jpg),
            image::ImageFormat::Jpeg,
        )
        .unwrap();
        let j = Texture::decode(&jpg, "t.jpg", Encoding::Linear).unwrap();
        assert!(
            (j.texel(3, 5)[1] - 128.0 / 255.0).abs() < 0.02,
            "{:?}",
            j.texel(3, 5)
        );
        let mut ktx = KTX2_MAGIC.to_vec();
        ktx.extend([0; 64]);
        let e = Texture::decode(&ktx, "box.gltf image 0", Encoding::Srgb)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("KHR_texture_basisu") && e.contains("box.gltf image 0"),
            "{e}"
        );
        let e = Texture::decode(b"GIF89a....", "g", Encoding::Srgb)
            .unwrap_err()
            .to_string();
        assert!(e.contains("PNG and JPEG"), "{e}");
    }
}

//! A texture's mip chain and its tiles: each level half the size of the
//! one before (rounded down, at least one texel) down to 1 x 1, each level
//! cut into square tiles of [`TILE`] texels a side, numbered level by
//! level, row by row. Tiles are what a database stores and what shading
//! reads, so that a texture far larger than memory is read a few tiles at
//! a time (pbrt-v4's and OpenImageIO's tiled, mip-mapped textures).
//!
//! A coarser level's texel is the mean of the (up to) four finer texels it
//! covers, taken in linear light for colour textures (averaging sRGB codes
//! would darken edges), and turned back into the nearest 8-bit code
//! through the same table shading reads them with, so the chain is the
//! same on every machine.

use super::Encoding;

/// Texels on a tile's side.
pub const TILE: u32 = 64;
/// Texels in a tile.
pub const TILE_TEXELS: usize = (TILE * TILE) as usize;
/// Bytes of a tile's texels (8-bit RGBA).
pub const TILE_BYTES: usize = 4 * TILE_TEXELS;

/// A tile's texels, row by row; texels past the level's edge are zero.
pub type TileTexels = [[u8; 4]; TILE_TEXELS];

/// One level of a mip chain.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Level {
    pub width: u32,
    pub height: u32,
    /// The number of the level's first tile in the chain.
    pub first_tile: u32,
}

impl Level {
    pub fn tiles_x(&self) -> u32 {
        self.width.div_ceil(TILE)
    }

    pub fn tiles_y(&self) -> u32 {
        self.height.div_ceil(TILE)
    }

    /// The tile holding texel `(i, j)` of this level, and the texel's
    /// place in it.
    #[inline]
    pub fn locate(&self, i: u32, j: u32) -> (u32, usize) {
        let tile = self.first_tile + (j / TILE) * self.tiles_x() + i / TILE;
        (tile, ((j % TILE) * TILE + i % TILE) as usize)
    }
}

/// The levels of the chain of a `width` x `height` texture, with the
/// number of tiles they take in all; `None` when the dimensions are zero
/// or the tiles would not be numbered by a `u32`.
pub fn levels(width: u32, height: u32) -> Option<(Vec<Level>, u32)> {
    if width == 0 || height == 0 {
        return None;
    }
    let (mut w, mut h) = (width, height);
    let mut out = Vec::new();
    let mut tiles: u64 = 0;
    loop {
        let l = Level {
            width: w,
            height: h,
            first_tile: u32::try_from(tiles).ok()?,
        };
        tiles += l.tiles_x() as u64 * l.tiles_y() as u64;
        out.push(l);
        if w == 1 && h == 1 {
            break;
        }
        (w, h) = ((w / 2).max(1), (h / 2).max(1));
    }
    Some((out, u32::try_from(tiles).ok()?))
}

/// The level after `fine` (of `fw` x `fh` texels, row by row), `cw` x
/// `ch` texels: each the mean of the texels it covers.
pub fn downsample(fine: &[[u8; 4]], fw: u32, fh: u32, encoding: Encoding) -> Vec<[u8; 4]> {
    let (cw, ch) = ((fw / 2).max(1), (fh / 2).max(1));
    let lut = super::lut(encoding);
    let mut out = Vec::with_capacity(cw as usize * ch as usize);
    for j in 0..ch {
        for i in 0..cw {
            let xs = [(2 * i).min(fw - 1), (2 * i + 1).min(fw - 1)];
            let ys = [(2 * j).min(fh - 1), (2 * j + 1).min(fh - 1)];
            let mut sum = [0f32; 4];
            for y in ys {
                for x in xs {
                    let t = fine[(y * fw + x) as usize];
                    for k in 0..3 {
                        sum[k] += lut[t[k] as usize];
                    }
                    sum[3] += t[3] as f32;
                }
            }
            out.push([
                encode(&lut, sum[0] / 4.0),
                encode(&lut, sum[1] / 4.0),
                encode(&lut, sum[2] / 4.0),
                (sum[3] / 4.0).round() as u8,
            ]);
        }
    }
    out
}

/// The 8-bit code whose value in `lut` (increasing) is nearest `v`.
fn encode(lut: &[f32; 256], v: f32) -> u8 {
    let hi = lut.partition_point(|&x| x < v);
    if hi == 0 {
        return 0;
    }
    if hi == 256 {
        return 255;
    }
    if v - lut[hi - 1] <= lut[hi] - v {
        (hi - 1) as u8
    } else {
        hi as u8
    }
}

impl Level {
    /// Columns and rows of tile `(tx, ty)` inside the level (tiles on its
    /// right and bottom edges are cut short).
    pub fn extent(&self, tx: u32, ty: u32) -> (u32, u32) {
        (
            (self.width - tx * TILE).min(TILE),
            (self.height - ty * TILE).min(TILE),
        )
    }
}

/// The texels of a tile `cols` x `rows` inside its level, row by row: what
/// a database stores of it (before compression), so that a small level's
/// tile does not take a whole tile's bytes.
pub fn pack(tile: &TileTexels, cols: u32, rows: u32) -> Vec<u8> {
    let mut out = Vec::with_capacity((4 * cols * rows) as usize);
    for r in 0..rows as usize {
        let row = &tile[r * TILE as usize..r * TILE as usize + cols as usize];
        out.extend_from_slice(bytemuck::cast_slice(row));
    }
    out
}

/// A tile from what [`pack`] made of it; `None` when `bytes` are not
/// `cols` x `rows` texels.
pub fn unpack(bytes: &[u8], cols: u32, rows: u32) -> Option<TileTexels> {
    if bytes.len() != (4 * cols * rows) as usize {
        return None;
    }
    let mut tile = [[0u8; 4]; TILE_TEXELS];
    for (r, row) in bytes.chunks_exact((4 * cols) as usize).enumerate() {
        let dst = &mut tile[r * TILE as usize..r * TILE as usize + cols as usize];
        bytemuck::cast_slice_mut::<[u8; 4], u8>(dst).copy_from_slice(row);
    }
    Some(tile)
}

/// Tile `(tx, ty)` of a level of `w` x `h` texels (row by row).
pub fn cut_tile(texels: &[[u8; 4]], w: u32, h: u32, tx: u32, ty: u32) -> Box<TileTexels> {
    let mut tile = Box::new([[0u8; 4]; TILE_TEXELS]);
    let (x0, y0) = (tx * TILE, ty * TILE);
    let cols = (w - x0).min(TILE) as usize;
    for r in 0..(h - y0).min(TILE) {
        let src = ((y0 + r) * w + x0) as usize;
        let dst = (r * TILE) as usize;
        tile[dst..dst + cols].copy_from_slice(&texels[src..src + cols]);
    }
    tile
}

/// Every tile of the chain of a `w` x `h` image (row by row), in the
/// chain's order, handed to `emit` one at a time with its columns and
/// rows inside its level: a level is held while it is cut and the next
/// is made from it.
pub fn for_each_tile<E>(
    texels: Vec<[u8; 4]>,
    w: u32,
    h: u32,
    encoding: Encoding,
    mut emit: impl FnMut(&TileTexels, u32, u32) -> Result<(), E>,
) -> Result<(), E> {
    let (mut level, mut lw, mut lh) = (texels, w, h);
    loop {
        for ty in 0..lh.div_ceil(TILE) {
            for tx in 0..lw.div_ceil(TILE) {
                let (cols, rows) = ((lw - tx * TILE).min(TILE), (lh - ty * TILE).min(TILE));
                emit(&cut_tile(&level, lw, lh, tx, ty), cols, rows)?;
            }
        }
        if lw == 1 && lh == 1 {
            return Ok(());
        }
        level = downsample(&level, lw, lh, encoding);
        (lw, lh) = ((lw / 2).max(1), (lh / 2).max(1));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_halve_down_to_one_texel_and_number_their_tiles() {
        let (ls, n) = levels(200, 70).unwrap();
        let dims: Vec<(u32, u32)> = ls.iter().map(|l| (l.width, l.height)).collect();
        assert_eq!(
            dims,
            [
                (200, 70),
                (100, 35),
                (50, 17),
                (25, 8),
                (12, 4),
                (6, 2),
                (3, 1),
                (1, 1)
            ]
        );
        // 4 x 2 tiles, then 2 x 1, then one a level.
        assert_eq!(ls[0].first_tile, 0);
        assert_eq!(ls[1].first_tile, 8);
        assert_eq!(ls[2].first_tile, 10);
        assert_eq!(n, 10 + 6);
        assert_eq!(ls[0].locate(130, 65), (6, (TILE + 2) as usize));
        assert!(levels(0, 5).is_none());
        assert_eq!(levels(1, 1).unwrap().0.len(), 1);
    }

    #[test]
    fn a_coarser_texel_is_the_mean_in_linear_light() {
        // Black and white sRGB average to sRGB 188 (half the light), not 128.
        let fine = vec![[0, 0, 0, 0], [255, 255, 255, 255]];
        let c = downsample(&fine, 2, 1, Encoding::Srgb);
        assert_eq!(c, [[188, 188, 188, 128]]);
        let fine2 = vec![[0, 0, 0, 0], [254, 254, 254, 255]];
        let c = downsample(&fine2, 2, 1, Encoding::Linear);
        assert_eq!(c, [[127, 127, 127, 128]]);
        // An odd edge repeats the last row and column.
        let fine: Vec<[u8; 4]> = (0..9).map(|v| [v * 10, 0, 0, 255]).collect();
        let c = downsample(&fine, 3, 3, Encoding::Linear);
        assert_eq!(c, [[20, 0, 0, 255]]);
    }

    #[test]
    fn tiles_cover_the_level_and_pad_with_zeros() {
        let (w, h) = (70u32, 3u32);
        let texels: Vec<[u8; 4]> = (0..w * h)
            .map(|v| [v as u8, (v >> 8) as u8, 1, 2])
            .collect();
        let t1 = cut_tile(&texels, w, h, 1, 0);
        assert_eq!(t1[0], texels[64]);
        assert_eq!(t1[(2 * TILE + 5) as usize], texels[(2 * w + 69) as usize]);
        assert_eq!(t1[6], [0; 4]);
        let mut n = 0;
        for_each_tile(texels, w, h, Encoding::Linear, |t, cols, rows| {
            n += 1;
            assert_eq!(unpack(&pack(t, cols, rows), cols, rows).as_ref(), Some(t));
            assert_eq!(pack(t, cols, rows).len(), (4 * cols * rows) as usize);
            Ok::<_, ()>(())
        })
        .unwrap();
        assert_eq!(n, levels(w, h).unwrap().1);
    }
}

//! On-disk structures of the object database.

use crate::shapes::KINDS;
use bytemuck::{Pod, Zeroable};

#[cfg(not(target_endian = "little"))]
compile_error!("the object database format is little-endian; big-endian targets are not supported");

pub const MAGIC: [u8; 8] = *b"SRAYSDB\0";
/// The oldest version read: geometry relative to the world's origin.
/// Version 2 (also read) has it relative to the header's origin (a mesh,
/// recentred), so that an older sray refused it rather than misplacing
/// the geometry.
pub const VERSION: u32 = 1;
/// Version 3 (also read): the tables end with a density summary
/// ([`crate::scene::DensitySummary`]), and the geometry is relative to the
/// header's origin (zero: the world's). An older sray refuses it rather
/// than reading the tables as malformed.
pub const VERSION_DENSITY: u32 = 3;
/// The version written today: as version 3, with blocks that store
/// consecutive triangles as runs ([`super::packed`]); the header records
/// the records' size once expanded (`decoded_bytes`).
pub const VERSION_PACKED: u32 = 4;
/// Version 5: as version 4, with models stored once and placed by
/// instance records. Each model is a version 4 database of its own,
/// appended after the tables (which list where); `models_bytes` in the
/// header is their total size. Written only when a scene has models, so
/// that every other scene stays readable by an sray of version 4.
pub const VERSION_MODELS: u32 = 5;
/// Version 6: as version 5 (models only if `models_bytes` is not zero),
/// with objects in spatial order ([`super::spatial`]): each block's
/// payload starts with its objects' input ids
/// ([`super::packed::pack_ids`]), then its records and runs. Written only
/// in the spatial order, so that a file in input order stays readable by
/// an sray of version 4 or 5.
pub const VERSION_IDS: u32 = 6;
/// Version 7: a version 4, 5 or 6 layout (the header's `layout` word says
/// whether blocks store input ids, [`LAYOUT_IDS`]; models as in version
/// 6) whose tables carry, between the density summary and the models'
/// table, the scene's appearance: glTF materials and lights
/// ([`super::tables`]). Written only when a scene has them, so that every
/// NFF, SPD or untextured mesh database stays as it was, byte for byte.
pub const VERSION_APPEARANCE: u32 = 7;
/// Version 8: as version 7, whose appearance table goes on with the
/// materials' textures and the images they sample, and whose records may
/// be textured triangles ([`crate::shapes::Textured`]). Written only when
/// a scene has either, so every other database stays as it was.
pub const VERSION_TEXTURES: u32 = 8;
/// Version 9: as version 8, with the images stored as tiles of their mip
/// chains ([`crate::texture::mip`]) in a section between the last block
/// and the tables, which list where each tile lies instead of holding the
/// images' bytes: a render reads the tiles it needs, through a cache, so
/// textures may be larger than memory. Written for every scene with
/// textures or corner attributes (version 8 is still read).
pub const VERSION_TILED: u32 = 9;
/// The newest version read.
pub const VERSION_NEWEST: u32 = VERSION_TILED;
/// Limits on a database's images: how many, and how many bytes in all
/// (they are held in memory with the tables).
pub const MAX_IMAGES: usize = 1 << 16;
pub const MAX_IMAGE_BYTES: u64 = 1 << 30;
/// Header `layout` bit (version 7): blocks store input ids (as version 6).
pub const LAYOUT_IDS: u32 = 1;
/// Limit on the models of one database.
pub const MAX_MODELS: usize = 1 << 20;
/// Header flag: `vertices` is the size of a mesh's vertex table.
pub const FLAG_MESH: u32 = 1;
/// Header flag: `triangles` and `vertices` are recorded (files written
/// before they were have zeros there).
pub const FLAG_COUNTS: u32 = 2;
pub const HEADER_BYTES: usize = 256;
pub const BLOCK_MAGIC: [u8; 4] = *b"SBLK";
pub const BLOCK_HEADER_BYTES: usize = 32;
/// Objects per aggregate ([`crate::grid::aggregate`]): blocks are cut
/// at multiples of it, so that no aggregate spans two blocks.
pub const AGGREGATE_SIZE: usize = 64;
/// Blocks are closed once they hold this many bytes of records: small
/// enough that a reader's buffers fit a tight memory budget, large enough
/// to read at the disk's sequential speed.
pub const BLOCK_TARGET: usize = 64 << 10;
/// Largest uncompressed block payload (a block holds at least one record,
/// and the largest record, a patch of the most vertices, is below this).
pub const MAX_BLOCK_RAW: usize = 1 << 20;
/// Bytes a compressed block may take beyond its raw size (zstd's bound for
/// incompressible data, with room to spare).
pub fn max_stored(raw: usize) -> usize {
    raw + raw / 128 + 4096
}
/// Words before a record's geometry: kind and count field (kind code in
/// the low byte, the kind's count, e.g. vertices, above it), material,
/// bounding box.
pub const RECORD_HEADER_WORDS: usize = 8;
/// Kinds the header has counts for.
pub const MAX_KINDS: usize = 8;
const _: () = assert!(KINDS <= MAX_KINDS);
/// Limits on the tables, so that a corrupt count cannot ask for memory.
pub const MAX_LIGHTS: usize = 1 << 16;
pub const MAX_MATERIALS: usize = 1 << 22;

/// How block payloads are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compression {
    None,
    /// zstd at the given level (1-22; 3 is zstd's default).
    Zstd(i32),
}

impl Compression {
    pub fn name(self) -> &'static str {
        match self {
            Compression::None => "none",
            Compression::Zstd(_) => "zstd",
        }
    }

    /// Parses `none`, `zstd` or `zstd:LEVEL`.
    pub fn parse(s: &str) -> Result<Compression, String> {
        match s.split_once(':') {
            None if s == "none" => Ok(Compression::None),
            None if s == "zstd" => Ok(Compression::Zstd(3)),
            Some(("zstd", level)) => {
                let l: i32 = level
                    .parse()
                    .map_err(|_| format!("zstd level '{level}' is not a number"))?;
                if !(1..=22).contains(&l) {
                    return Err(format!("zstd level {l} is outside 1..=22"));
                }
                Ok(Compression::Zstd(l))
            }
            _ => Err(format!(
                "unknown compression '{s}' (expected none, zstd or zstd:LEVEL)"
            )),
        }
    }
}

#[derive(Clone, Copy, Pod, Zeroable)]
#[repr(C)]
pub struct RawHeader {
    pub magic: [u8; 8],
    pub version: u32,
    pub header_bytes: u32,
    /// 0 = none, 1 = zstd.
    pub compression: u32,
    pub compression_level: i32,
    /// The largest block's records, expanded: what a reader's buffers
    /// hold (a stored block is never larger).
    pub block_raw_max: u32,
    /// Version 7: [`LAYOUT_IDS`]; zero before (a reserved word).
    pub layout: u32,
    pub object_count: u64,
    /// Objects per kind, by kind code ([`crate::shapes::ShapeKind`]);
    /// room for [`MAX_KINDS`] kinds (files written when there were four
    /// have zeros in the rest, which was reserved space).
    pub counts: [u64; MAX_KINDS],
    pub block_count: u64,
    /// `f` statements seen (materials are stored deduplicated).
    pub material_statements: u64,
    pub tables_offset: u64,
    pub tables_len: u64,
    /// Sum of uncompressed block payload bytes (as stored: runs packed).
    pub raw_bytes: u64,
    pub bbox: [f32; 6],
    pub tables_crc: u32,
    /// The point (world coordinates) that every record's geometry is
    /// relative to: three `f64`, each as two little-endian words. Zero in
    /// version 1 files, where these words were reserved.
    pub origin: [u32; 6],
    /// Triangles the polygons and patches make (`n - 2` each), as two
    /// words, low first.
    pub triangles: [u32; 2],
    /// A mesh's vertex table (with [`FLAG_MESH`]), else the vertices the
    /// polygons and patches list; two words, low first.
    pub vertices: [u32; 2],
    /// [`FLAG_MESH`], [`FLAG_COUNTS`].
    pub flags: u32,
    /// The records' size once runs are expanded, two words, low first
    /// (version 4; before it, `raw_bytes` is that size and these words
    /// were reserved).
    pub decoded_bytes: [u32; 2],
    /// Triangle runs, and the triangles they hold (version 4), each two
    /// words, low first.
    pub runs: [u32; 2],
    pub run_triangles: [u32; 2],
    /// The largest block as stored, before compression (version 4: runs
    /// packed; before it, `block_raw_max`).
    pub block_stored_max: u32,
    /// Bytes of the models appended after the tables (version 5), two
    /// words, low first; zero before (reserved words).
    pub models_bytes: [u32; 2],
    /// CRC-32 of the 252 bytes before it.
    pub header_crc: u32,
}

const _: () = assert!(std::mem::size_of::<RawHeader>() == HEADER_BYTES);

impl RawHeader {
    pub fn compute_crc(&self) -> u32 {
        crc32fast::hash(&bytemuck::bytes_of(self)[..HEADER_BYTES - 4])
    }

    pub fn origin(&self) -> [f64; 3] {
        std::array::from_fn(|i| f64::from_bits(join64(self.origin[2 * i], self.origin[2 * i + 1])))
    }

    pub fn set_origin(&mut self, o: [f64; 3]) {
        for (i, x) in o.iter().enumerate() {
            let b = x.to_bits();
            self.origin[2 * i] = b as u32;
            self.origin[2 * i + 1] = (b >> 32) as u32;
        }
    }
}

/// A `u64` from two words, low first.
pub fn join64(lo: u32, hi: u32) -> u64 {
    lo as u64 | (hi as u64) << 32
}

/// A `u64` as two words, low first.
pub fn split64(v: u64) -> [u32; 2] {
    [v as u32, (v >> 32) as u32]
}

#[derive(Clone, Copy, Pod, Zeroable)]
#[repr(C)]
pub struct RawBlockHeader {
    pub magic: [u8; 4],
    pub index: u32,
    pub first_object: u64,
    pub object_count: u32,
    pub raw_len: u32,
    pub stored_len: u32,
    /// CRC-32 of this header (with `crc` zero) followed by the payload.
    pub crc: u32,
}

const _: () = assert!(std::mem::size_of::<RawBlockHeader>() == BLOCK_HEADER_BYTES);

impl RawBlockHeader {
    pub fn compute_crc(&self, payload: &[u8]) -> u32 {
        let mut h = *self;
        h.crc = 0;
        let mut c = crc32fast::Hasher::new();
        c.update(bytemuck::bytes_of(&h));
        c.update(payload);
        c.finalize()
    }
}

/// Little-endian encoder for the tables.
#[derive(Default)]
pub struct Enc(pub Vec<u8>);

impl Enc {
    pub fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub fn f32(&mut self, v: f32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
}

/// Bounds-checked little-endian decoder for the tables.
pub struct Dec<'a> {
    pub buf: &'a [u8],
    pub pos: usize,
}

impl Dec<'_> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let s = self.buf.get(self.pos..self.pos + N)?;
        self.pos += N;
        s.try_into().ok()
    }
    pub fn u32(&mut self) -> Option<u32> {
        self.take::<4>().map(u32::from_le_bytes)
    }
    pub fn f32(&mut self) -> Option<f32> {
        self.take::<4>().map(f32::from_le_bytes)
    }
    pub fn f64(&mut self) -> Option<f64> {
        self.take::<8>().map(f64::from_le_bytes)
    }
    pub fn u64(&mut self) -> Option<u64> {
        self.take::<8>().map(u64::from_le_bytes)
    }
    /// The next `n` bytes.
    pub fn bytes(&mut self, n: usize) -> Option<&[u8]> {
        let s = self.buf.get(self.pos..self.pos.checked_add(n)?)?;
        self.pos += n;
        Some(s)
    }
    pub fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }
}

//! Opens an object database and reads its blocks strictly front to back,
//! decoding records in place: no allocation per object.

use super::format::*;
use super::packed::PackCounts;
use crate::error::{Error, IoContext};
use crate::hit::PrimId;
use crate::scene::density::MAX_ENTRIES as MAX_DENSITY_ENTRIES;
use crate::scene::{
    Aabb, DENSITY_CELLS, DensitySummary, Light, Material, SIZE_CLASSES, SceneHeader, SizeClass,
    SizeSummary, View,
};
use crate::shapes::{KINDS, KindCounts, Shape, ShapeKind};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::SystemTime;

/// Checksums are verified always, except when fuzzing (`cargo fuzz` builds
/// with `--cfg fuzzing`): there a mutated byte would almost always stop at
/// the checksum, and the fuzzer would never reach the decoding behind it.
const VERIFY_CHECKSUMS: bool = !cfg!(fuzzing);

/// An open object database: header and tables in memory, objects on disk.
#[derive(Clone, Debug)]
pub struct Database {
    path: PathBuf,
    scene: SceneHeader,
    sizes: SizeSummary,
    density: Option<DensitySummary>,
    version: u32,
    counts: KindCounts,
    object_count: u64,
    bbox: Aabb,
    compression: Compression,
    block_count: u64,
    material_statements: u64,
    tables_offset: u64,
    raw_bytes: u64,
    decoded_bytes: u64,
    /// Blocks store triangles as runs (version 4).
    runs: bool,
    /// Blocks store their objects' input ids (version 6: objects in
    /// spatial order).
    ids: bool,
    run_counts: PackCounts,
    /// Scans read every block, as the paper's passes do: none is passed
    /// over ([`Database::set_full_scans`]).
    full_scans: bool,
    file_bytes: u64,
    largest_block: usize,
    /// The largest block as stored, before compression.
    largest_stored: usize,
    origin: [f64; 3],
    /// The view and lights as stored, in world coordinates (`scene` has
    /// them relative to the origin, as the geometry is).
    world_view: View,
    world_lights: Vec<Light>,
    triangles: Option<u64>,
    vertices: Option<u64>,
    mesh: bool,
    /// The file as it was opened: a scan refuses a file changed since.
    stamp: (u64, Option<SystemTime>),
    /// Set once a scan has checked every block's checksum and records:
    /// later scans of the unchanged file skip those checks (they cost a
    /// third of a pass over a large mesh). Shared by clones.
    verified: Arc<AtomicBool>,
    /// Where each block ends and how many objects it holds, learned by
    /// the first complete scan: later scans may pass over a block without
    /// reading it ([`Scan::skip_block`]). Shared by clones.
    layout: Arc<OnceLock<Vec<BlockSpan>>>,
    /// Where this database starts in its file: 0, or a model's place
    /// inside the file of the database that places it.
    base: u64,
    /// The models this database places (version 5).
    models: Vec<ModelEntry>,
}

/// One model of a version 5 database: a database of its own inside the
/// file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelEntry {
    /// Where it starts, relative to the placing database's start.
    pub offset: u64,
    pub bytes: u64,
    /// The margin, in the model's units, its grid keeps around each
    /// triangle (see [`crate::models`]).
    pub pad: f64,
}

/// One block's place in the file.
#[derive(Clone, Copy, Debug)]
struct BlockSpan {
    /// The byte after its payload (where the next block starts).
    end: u64,
    objects: u32,
}

/// Counters of one scan.
#[derive(Clone, Copy, Debug, Default)]
pub struct DbStats {
    pub bytes_read: u64,
    pub blocks_read: u64,
    /// Blocks passed over unread.
    pub blocks_skipped: u64,
}

impl Database {
    pub fn open(path: &Path) -> Result<Database, Error> {
        Self::open_at(path, 0, None)
    }

    /// Model `m` of this database, as a database of its own.
    pub fn open_model(&self, m: usize) -> Result<Database, Error> {
        let e = self.models.get(m).ok_or_else(|| Error::Database {
            file: self.path.clone(),
            location: "tables".into(),
            message: format!(
                "model {m} is not in the database ({} models)",
                self.models.len()
            ),
        })?;
        let db = Self::open_at(&self.path, self.base + e.offset, Some(e.bytes))?;
        if db.stamp != self.stamp {
            return Err(Error::Database {
                file: self.path.clone(),
                location: "file".into(),
                message: "the database changed on disk while it was in use; start the render again"
                    .into(),
            });
        }
        if !db.models.is_empty() || db.counts.get(ShapeKind::Instance) != 0 {
            return Err(Error::Database {
                file: self.path.clone(),
                location: format!("model {m}"),
                message: "a model places models of its own (models do not nest)".into(),
            });
        }
        Ok(db)
    }

    /// The models this database places.
    pub fn models(&self) -> &[ModelEntry] {
        &self.models
    }

    /// Opens the database of `len` bytes (the rest of the file if `None`)
    /// that starts at byte `base` of `path`.
    fn open_at(path: &Path, base: u64, len: Option<u64>) -> Result<Database, Error> {
        let mut f = File::open(path).at(path)?;
        let meta = f.metadata().at(path)?;
        let stamp = (meta.len(), meta.modified().ok());
        let err = |location: &str, message: String| Error::Database {
            file: path.to_path_buf(),
            location: if base == 0 {
                location.into()
            } else {
                format!("model at byte {base}, {location}")
            },
            message,
        };
        let file_bytes = match len {
            Some(l) if base.checked_add(l).is_some_and(|e| e <= meta.len()) => l,
            Some(_) => {
                return Err(err(
                    "header",
                    "the model lies past the end of the file".into(),
                ));
            }
            None => meta.len(),
        };
        f.seek(SeekFrom::Start(base)).at(path)?;
        let mut hb = [0u8; HEADER_BYTES];
        let got = read_up_to(&mut f, &mut hb).at(path)?;
        if got < 8 || hb[..8] != MAGIC {
            return Err(err(
                "header",
                "not an sray object database (wrong magic)".into(),
            ));
        }
        if got < HEADER_BYTES {
            return Err(err(
                "header",
                format!("file is truncated: {got} bytes, the header alone is {HEADER_BYTES}"),
            ));
        }
        let h: RawHeader = bytemuck::pod_read_unaligned(&hb);
        if !(VERSION..=VERSION_IDS).contains(&h.version) {
            return Err(err(
                "header",
                format!(
                    "database version {} is not supported (this sray reads versions {VERSION} to {VERSION_IDS}); regenerate it with `sray convert` or `sray gen`",
                    h.version
                ),
            ));
        }
        if VERIFY_CHECKSUMS && h.header_crc != h.compute_crc() {
            return Err(err(
                "header",
                "checksum mismatch: the header is corrupt".into(),
            ));
        }
        let compression = match (h.compression, h.compression_level) {
            (0, _) => Compression::None,
            (1, l) => Compression::Zstd(l),
            (c, _) => return Err(err("header", format!("unknown compression code {c}"))),
        };
        if h.header_bytes as usize != HEADER_BYTES || h.block_raw_max as usize > MAX_BLOCK_RAW {
            return Err(err("header", "unsupported header or block size".into()));
        }
        let models_bytes = join64(h.models_bytes[0], h.models_bytes[1]);
        if h.version < VERSION_MODELS && models_bytes != 0 {
            return Err(err("header", "reserved words are not zero".into()));
        }
        // Version 5 always has models; version 6 when it says it has.
        let has_models =
            h.version == VERSION_MODELS || (h.version >= VERSION_IDS && models_bytes != 0);
        let tables_end = h
            .tables_offset
            .checked_add(h.tables_len)
            .and_then(|e| e.checked_add(models_bytes));
        if h.tables_offset < HEADER_BYTES as u64 || tables_end.is_none() {
            return Err(err("header", "tables offset is out of range".into()));
        }
        if tables_end != Some(file_bytes) {
            return Err(err(
                "header",
                format!(
                    "file is truncated or has trailing bytes: it is {file_bytes} bytes, the header says {}",
                    h.tables_offset + h.tables_len + models_bytes
                ),
            ));
        }
        if h.tables_len > (64 << 20) + 64 * MAX_MATERIALS as u64 {
            return Err(err("header", "tables are implausibly large".into()));
        }
        if h.counts[KINDS..].iter().any(|&c| c != 0) {
            return Err(err(
                "header",
                "the database holds kinds of primitive this sray does not know; use a newer sray"
                    .into(),
            ));
        }
        if h.counts.iter().try_fold(0u64, |a, &c| a.checked_add(c)) != Some(h.object_count)
            || h.object_count > u32::MAX as u64
        {
            return Err(err("header", "object counts are inconsistent".into()));
        }
        let mut tables = vec![0u8; h.tables_len as usize];
        f.seek(SeekFrom::Start(base + h.tables_offset)).at(path)?;
        f.read_exact(&mut tables).at(path)?;
        if VERIFY_CHECKSUMS && crc32fast::hash(&tables) != h.tables_crc {
            return Err(err(
                "tables",
                "checksum mismatch: the tables are corrupt".into(),
            ));
        }
        let (mut scene, sizes, density, models) =
            decode_tables(&tables, h.version >= VERSION_DENSITY, has_models)
                .ok_or_else(|| err("tables", "malformed tables".into()))?;
        // Each model lies after the tables, in order, and they fill the
        // rest of the file.
        let mut at = h.tables_offset + h.tables_len;
        for (i, m) in models.iter().enumerate() {
            if m.offset != at
                || m.bytes < HEADER_BYTES as u64
                || !(m.pad.is_finite() && m.pad >= 0.0)
            {
                return Err(err("tables", format!("model {i} is out of place")));
            }
            at = at
                .checked_add(m.bytes)
                .ok_or_else(|| err("tables", format!("model {i} is out of place")))?;
        }
        if at != file_bytes || (has_models && models.is_empty()) {
            return Err(err("tables", "the models do not fill the file".into()));
        }
        if counts_instances(&h) > 0 && models.is_empty() {
            return Err(err("tables", "instances with no models".into()));
        }
        let origin = h.origin();
        if !origin.iter().all(|c| c.is_finite()) {
            return Err(err("header", "the origin is not finite".into()));
        }
        let world_view = scene.view;
        let world_lights = scene.lights.clone();
        // Shading and cameras work in the geometry's frame.
        let local = |p: [f64; 3]| std::array::from_fn(|i| p[i] - origin[i]);
        scene.view.from = local(scene.view.from);
        scene.view.at = local(scene.view.at);
        for l in &mut scene.lights {
            l.position = local(l.position);
        }
        let counts_known = h.flags & FLAG_COUNTS != 0;
        if sizes.total() != h.object_count {
            return Err(err(
                "tables",
                "size summary disagrees with the object count".into(),
            ));
        }
        let bbox = Aabb::from_array(h.bbox);
        let run_counts = PackCounts {
            runs: join64(h.runs[0], h.runs[1]),
            run_triangles: join64(h.run_triangles[0], h.run_triangles[1]),
        };
        // A version 4 file without a run stores its records as version 3
        // does: they are read in place (a record with a run's code is an
        // unknown kind there, so a lying count is an error, not a misread).
        // Version 6 blocks always go through the packed path: their ids
        // come first.
        let ids = h.version >= VERSION_IDS;
        let runs = h.version >= VERSION_PACKED && (run_counts.runs > 0 || ids);
        let decoded_bytes = if runs {
            join64(h.decoded_bytes[0], h.decoded_bytes[1])
        } else {
            h.raw_bytes
        };
        // Version 6 blocks store their ids beside the records: at most two
        // words per block and a word per object.
        let ids_bytes = if ids {
            h.block_count
                .saturating_mul(8)
                .saturating_add(h.object_count.saturating_mul(4))
        } else {
            0
        };
        if decoded_bytes.saturating_add(ids_bytes) < h.raw_bytes || !decoded_bytes.is_multiple_of(4)
        {
            return Err(err(
                "header",
                "the records' expanded size is below their stored size".into(),
            ));
        }
        if h.block_count > file_bytes / BLOCK_HEADER_BYTES as u64 {
            return Err(err(
                "header",
                "the block count exceeds what the file has room for".into(),
            ));
        }
        if runs && decoded_bytes > h.block_count.saturating_mul(h.block_raw_max as u64) {
            return Err(err(
                "header",
                "the records' expanded size exceeds what the blocks can hold".into(),
            ));
        }
        let largest_stored = if runs {
            h.block_stored_max as usize
        } else {
            h.block_raw_max as usize
        };
        // A record is at least 8 words, and an id one (version 6), with
        // two words of the ids' header per block.
        let ids_room = if ids {
            h.block_raw_max as usize / 8 + 8
        } else {
            0
        };
        if largest_stored > h.block_raw_max as usize + ids_room {
            return Err(err("header", "unsupported header or block size".into()));
        }
        Ok(Database {
            path: path.to_path_buf(),
            scene,
            sizes,
            density,
            version: h.version,
            counts: KindCounts(std::array::from_fn(|i| h.counts[i])),
            object_count: h.object_count,
            bbox,
            compression,
            block_count: h.block_count,
            material_statements: h.material_statements,
            tables_offset: h.tables_offset,
            raw_bytes: h.raw_bytes,
            decoded_bytes,
            runs,
            ids,
            full_scans: false,
            run_counts,
            file_bytes,
            largest_block: h.block_raw_max as usize,
            largest_stored,
            origin,
            world_view,
            world_lights,
            triangles: counts_known.then(|| join64(h.triangles[0], h.triangles[1])),
            vertices: counts_known.then(|| join64(h.vertices[0], h.vertices[1])),
            mesh: h.flags & FLAG_MESH != 0,
            stamp,
            verified: Arc::new(AtomicBool::new(false)),
            layout: Arc::new(OnceLock::new()),
            base,
            models,
        })
    }

    /// The point (world coordinates) the geometry is relative to; the
    /// view and lights of [`Database::scene`] are relative to it too.
    pub fn origin(&self) -> [f64; 3] {
        self.origin
    }
    /// The view as stored, in world coordinates.
    pub fn world_view(&self) -> &View {
        &self.world_view
    }
    /// The lights as stored, in world coordinates.
    pub fn world_lights(&self) -> &[Light] {
        &self.world_lights
    }
    /// Bounds of all objects in world coordinates (`None` for a scene of
    /// none).
    pub fn world_bounds(&self) -> Option<([f64; 3], [f64; 3])> {
        (!self.bbox.is_empty()).then(|| {
            let o = self.origin;
            (
                std::array::from_fn(|i| self.bbox.min[i] as f64 + o[i]),
                std::array::from_fn(|i| self.bbox.max[i] as f64 + o[i]),
            )
        })
    }
    /// Triangles the polygons and patches make, if recorded (files
    /// written before sray kept it have no record).
    pub fn triangles(&self) -> Option<u64> {
        self.triangles
    }
    /// A mesh's vertex table, or the vertices the polygons and patches
    /// list, if recorded.
    pub fn vertices(&self) -> Option<u64> {
        self.vertices
    }
    /// Whether the scene came from a mesh file.
    pub fn is_mesh(&self) -> bool {
        self.mesh
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
    /// View, background, lights and materials; the view and the lights
    /// relative to [`Database::origin`], like the geometry, which is what
    /// cameras and shading need.
    pub fn scene(&self) -> &SceneHeader {
        &self.scene
    }
    pub fn counts(&self) -> KindCounts {
        self.counts
    }
    /// Object counts and bounds per size class.
    /// Where the objects are, if the database says (version 3 files).
    pub fn density(&self) -> Option<&DensitySummary> {
        self.density.as_ref()
    }

    pub fn sizes(&self) -> &SizeSummary {
        &self.sizes
    }
    pub fn object_count(&self) -> u64 {
        self.object_count
    }
    /// Bounds of all objects (empty for a scene of none).
    pub fn bbox(&self) -> Aabb {
        self.bbox
    }
    pub fn compression(&self) -> Compression {
        self.compression
    }
    /// The format version the file was written in.
    pub fn version(&self) -> u32 {
        self.version
    }
    pub fn block_count(&self) -> u64 {
        self.block_count
    }
    pub fn material_statements(&self) -> u64 {
        self.material_statements
    }
    pub fn file_bytes(&self) -> u64 {
        self.file_bytes
    }
    /// Uncompressed size of all blocks as stored (triangle runs packed).
    pub fn raw_bytes(&self) -> u64 {
        self.raw_bytes
    }

    /// Size of all records once expanded: what holding every object in
    /// memory takes, and what a scan decodes.
    pub fn decoded_bytes(&self) -> u64 {
        self.decoded_bytes
    }

    /// Whether blocks store consecutive triangles as runs (version 4).
    pub fn has_runs(&self) -> bool {
        self.runs && self.run_counts.runs > 0
    }

    /// Whether objects are stored in spatial order, each with its input id
    /// (version 6).
    pub fn is_spatial(&self) -> bool {
        self.ids
    }

    /// Makes every scan read every block, as the paper's passes do, rather
    /// than pass over the blocks a pass has no use for: slower, for
    /// reproducing the paper's figures. Images and counts do not change.
    pub fn set_full_scans(&mut self, on: bool) {
        self.full_scans = on;
    }

    /// Whether scans are the paper's ([`Database::set_full_scans`]): the
    /// breadth-first tracer then also tests objects one by one, without
    /// aggregates, as the paper does.
    pub fn full_scans(&self) -> bool {
        self.full_scans
    }

    /// Bytes of the blocks, headers and payloads: what a full scan reads.
    pub fn blocks_bytes(&self) -> u64 {
        self.tables_offset - HEADER_BYTES as u64
    }

    /// Triangle runs and the triangles they hold (zero before version 4).
    pub fn run_counts(&self) -> PackCounts {
        self.run_counts
    }

    /// Size of the largest block's records, expanded.
    pub fn largest_block(&self) -> usize {
        self.largest_block
    }

    /// Memory a scan holds: buffers for one block's records and for one
    /// stored block (packed, compressed, or both).
    pub fn scan_buffer_bytes(&self) -> usize {
        let packed = if self.runs { self.largest_stored } else { 0 };
        // A block's ids: at most a word per record of its expanded size.
        let ids = if self.ids {
            self.largest_block / RECORD_HEADER_WORDS
        } else {
            0
        };
        let compressed = match self.compression {
            Compression::None => 0,
            Compression::Zstd(_) => max_stored(self.largest_stored),
        };
        self.largest_block + packed + ids + compressed
    }

    /// Starts a sequential scan of the objects. The first scan checks
    /// every block's checksum and records; later scans of the same,
    /// unchanged file trust them.
    pub fn scan(&self) -> Result<Scan<'_>, Error> {
        self.start_scan(!self.verified.load(Ordering::Acquire))
    }

    /// Starts a scan that checks every block, however often the file has
    /// been read (`sray verify`).
    pub fn scan_checked(&self) -> Result<Scan<'_>, Error> {
        self.start_scan(true)
    }

    fn start_scan(&self, verify: bool) -> Result<Scan<'_>, Error> {
        let mut file = File::open(&self.path).at(&self.path)?;
        let meta = file.metadata().at(&self.path)?;
        if (meta.len(), meta.modified().ok()) != self.stamp {
            return Err(Error::Database {
                file: self.path.clone(),
                location: "file".into(),
                message: "the database changed on disk while it was in use; \
                          start the render again"
                    .into(),
            });
        }
        file.seek(SeekFrom::Start(self.base + HEADER_BYTES as u64))
            .at(&self.path)?;
        let decompressor = match self.compression {
            Compression::None => None,
            Compression::Zstd(_) => Some(zstd::bulk::Decompressor::new().at(&self.path)?),
        };
        Ok(Scan {
            db: self,
            file,
            decompressor,
            words: Vec::with_capacity(self.largest_block / 4),
            packed: Vec::new(),
            ids: Vec::new(),
            decoded: 0,
            stored: Vec::new(),
            next_index: 0,
            next_object: 0,
            offset: HEADER_BYTES as u64,
            stats: DbStats::default(),
            verify,
            learned: Vec::new(),
        })
    }
}

fn read_up_to(f: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match f.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// The tables: the scene's header, the size summary, and (`density`: in a
/// version 3 file) the density summary.
/// Instance records the header counts.
fn counts_instances(h: &RawHeader) -> u64 {
    h.counts[ShapeKind::Instance as usize]
}

type Tables = (
    SceneHeader,
    SizeSummary,
    Option<DensitySummary>,
    Vec<ModelEntry>,
);

fn decode_tables(buf: &[u8], density: bool, with_models: bool) -> Option<Tables> {
    let mut d = Dec { buf, pos: 0 };
    let v3 = |d: &mut Dec| -> Option<[f64; 3]> { Some([d.f64()?, d.f64()?, d.f64()?]) };
    let from = v3(&mut d)?;
    let at = v3(&mut d)?;
    let up = v3(&mut d)?;
    let view = View {
        from,
        at,
        up,
        angle: d.f64()?,
        hither: d.f64()?,
        resolution: [d.u32()?, d.u32()?],
    };
    let background = [d.f32()?, d.f32()?, d.f32()?];
    let nl = d.u32()? as usize;
    if nl > MAX_LIGHTS || nl * 40 > d.remaining() {
        return None;
    }
    let mut lights = Vec::with_capacity(nl);
    for _ in 0..nl {
        let position = v3(&mut d)?;
        let has = d.u32()?;
        let c = [d.f32()?, d.f32()?, d.f32()?];
        lights.push(Light {
            position,
            color: (has != 0).then_some(c),
        });
    }
    let nm = d.u32()? as usize;
    if nm > MAX_MATERIALS || nm * 32 > d.remaining() {
        return None;
    }
    let mut materials = Vec::with_capacity(nm);
    for _ in 0..nm {
        let mut m = [0f32; 8];
        for x in &mut m {
            *x = d.f32()?;
        }
        materials.push(Material {
            color: [m[0], m[1], m[2]],
            kd: m[3],
            ks: m[4],
            shine: m[5],
            t: m[6],
            ior: m[7],
        });
    }
    let mut sizes = SizeSummary::default();
    let nc = d.u32()? as usize;
    if nc > SIZE_CLASSES || nc * 36 > d.remaining() || (!density && nc * 36 != d.remaining()) {
        return None;
    }
    for _ in 0..nc {
        let i = d.u32()? as usize;
        let count = d.u64()?;
        let mut b = [0f32; 6];
        for x in &mut b {
            *x = d.f32()?;
        }
        let c = sizes.classes.get_mut(i)?;
        c.count = count;
        c.bounds = Aabb::from_array(b);
    }
    let density = if density {
        let level = d.u32()? as i32;
        let origin = [d.u64()? as i64, d.u64()? as i64, d.u64()? as i64];
        // Cell coordinates stay exact in an f64 (see the writer).
        if origin.iter().any(|o| o.unsigned_abs() > 1 << 52) {
            return None;
        }
        let n = d.u32()? as usize;
        if n > MAX_DENSITY_ENTRIES
            || n * 40 > d.remaining()
            || (!with_models && n * 40 != d.remaining())
        {
            return None;
        }
        let mut entries = Vec::with_capacity(n);
        for _ in 0..n {
            let cell = d.u32()?;
            let class = d.u32()?;
            let count = d.u64()?;
            let mut b = [0f32; 6];
            for x in &mut b {
                *x = d.f32()?;
            }
            if cell >= (DENSITY_CELLS * DENSITY_CELLS * DENSITY_CELLS) as u32
                || class >= SIZE_CLASSES as u32
            {
                return None;
            }
            let bounds = Aabb::from_array(b);
            entries.push(((cell, class as u8), SizeClass { count, bounds }));
        }
        // No more objects than the size summary counts (the writer leaves
        // out only objects with empty boxes).
        let total = entries
            .iter()
            .try_fold(0u64, |a, e| a.checked_add(e.1.count))?;
        if total > sizes.total() {
            return None;
        }
        // Level i32::MIN: the writer kept no summary.
        (level != i32::MIN && (-1100..=1100).contains(&level))
            .then(|| DensitySummary::from_parts(level, origin, entries))
    } else {
        None
    };
    let mut models = Vec::new();
    if with_models {
        let n = d.u32()? as usize;
        if n > MAX_MODELS || n * 32 != d.remaining() {
            return None;
        }
        for _ in 0..n {
            let offset = d.u64()?;
            let bytes = d.u64()?;
            let pad = d.f64()?;
            if d.u64()? != 0 {
                return None;
            }
            models.push(ModelEntry { offset, bytes, pad });
        }
    }
    Some((
        SceneHeader {
            view,
            background,
            lights,
            materials,
        },
        sizes,
        density,
        models,
    ))
}

/// A front-to-back pass over the objects of a [`Database`].
pub struct Scan<'d> {
    db: &'d Database,
    file: File,
    decompressor: Option<zstd::bulk::Decompressor<'static>>,
    /// The decoded block, as 4-byte words.
    words: Vec<u32>,
    /// The block as stored, before its runs are expanded (version 4).
    packed: Vec<u32>,
    /// The block's objects' input ids (version 6), else empty.
    ids: Vec<u32>,
    /// Bytes of records the blocks read so far hold.
    decoded: u64,
    stored: Vec<u8>,
    next_index: u64,
    next_object: u64,
    offset: u64,
    stats: DbStats,
    /// Whether this scan checks checksums and records.
    verify: bool,
    /// The blocks' spans so far, while the database's layout is unknown.
    learned: Vec<BlockSpan>,
}

/// The buffer a block's payload (decompressed) goes to: version 4 blocks
/// to `packed`, to be expanded into `words`; older ones to `words`, as
/// they are.
fn payload<'a>(runs: bool, packed: &'a mut Vec<u32>, words: &'a mut Vec<u32>) -> &'a mut Vec<u32> {
    if runs { packed } else { words }
}

/// One decoded, validated block.
pub struct Block<'a> {
    pub index: u64,
    /// The position in the file of its first object.
    pub first_object: u64,
    pub object_count: u32,
    words: &'a [u32],
    /// Each object's input id (version 6), or empty: the position is the
    /// input id.
    ids: &'a [u32],
}

/// One object of a block, borrowing its geometry from the block buffer.
#[derive(Clone, Copy, Debug)]
pub struct ObjectRef<'a> {
    /// Its position in the database: how tracers, hits and the shading
    /// join name it.
    pub index: u32,
    /// Its id in the input, which decides ties (the same as `index`
    /// unless the database is in spatial order).
    pub rank: u32,
    pub material: u32,
    pub bbox: Aabb,
    pub shape: Shape<'a>,
}

impl Scan<'_> {
    pub fn stats(&self) -> DbStats {
        self.stats
    }

    fn err(&self, message: impl Into<String>) -> Error {
        Error::Database {
            file: self.db.path.clone(),
            location: if self.db.base == 0 {
                format!("block {} (byte {})", self.next_index, self.offset)
            } else {
                format!(
                    "model at byte {}, block {} (byte {})",
                    self.db.base,
                    self.next_index,
                    self.db.base + self.offset
                )
            },
            message: message.into(),
        }
    }

    /// Reads `len` bytes into the compressed block's buffer (`stored`) or
    /// into the payload's.
    fn read_exact_or_err(&mut self, stored: bool, len: usize) -> Result<(), Error> {
        let r = if stored {
            self.file.read_exact(&mut self.stored[..len])
        } else {
            let target = payload(self.db.runs, &mut self.packed, &mut self.words);
            let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut target[..]);
            self.file.read_exact(&mut bytes[..len])
        };
        r.map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                self.err("file ends inside this block (truncated)")
            } else {
                Error::io(&self.db.path, e)
            }
        })
    }

    /// The index of the block [`Scan::next_block`] reads next.
    pub fn next_index(&self) -> u64 {
        self.next_index
    }

    /// The id after the last object of the block [`Scan::next_block`]
    /// reads next, where the block layout is known.
    pub fn next_block_end(&self) -> Option<u64> {
        let span = self.db.layout.get()?.get(self.next_index as usize)?;
        Some(self.next_object + span.objects as u64)
    }

    /// Passes over the next block without reading it (a seek forward),
    /// once a complete scan of this database has learned where its blocks
    /// lie; returns `false`, and does nothing, before then, after the
    /// last block, or when the database asks for full scans.
    pub fn skip_block(&mut self) -> Result<bool, Error> {
        if self.db.full_scans {
            return Ok(false);
        }
        let Some(span) = self
            .db
            .layout
            .get()
            .and_then(|l| l.get(self.next_index as usize))
            .copied()
        else {
            return Ok(false);
        };
        self.file
            .seek(SeekFrom::Start(self.db.base + span.end))
            .map_err(|e| Error::io(&self.db.path, e))?;
        self.stats.blocks_skipped += 1;
        self.offset = span.end;
        self.next_index += 1;
        self.next_object += span.objects as u64;
        Ok(true)
    }

    /// The next block, or `None` after the last one.
    pub fn next_block(&mut self) -> Result<Option<Block<'_>>, Error> {
        if self.next_index == self.db.block_count {
            if self.next_object != self.db.object_count || self.offset != self.db.tables_offset {
                return Err(self.err(format!(
                    "blocks hold {} objects ending at byte {}, the header says {} objects ending at byte {}",
                    self.next_object, self.offset, self.db.object_count, self.db.tables_offset
                )));
            }
            if self.verify
                && self.stats.blocks_skipped == 0
                && self.decoded != self.db.decoded_bytes
            {
                return Err(self.err(format!(
                    "blocks hold {} bytes of records, the header says {}",
                    self.decoded, self.db.decoded_bytes
                )));
            }
            if self.verify {
                self.db.verified.store(true, Ordering::Release);
            }
            if self.db.layout.get().is_none() && self.learned.len() as u64 == self.db.block_count {
                let _ = self.db.layout.set(std::mem::take(&mut self.learned));
            }
            return Ok(None);
        }
        if self.offset + BLOCK_HEADER_BYTES as u64 > self.db.tables_offset {
            return Err(self.err("block runs into the tables (corrupt block count)"));
        }
        let mut hb = [0u8; BLOCK_HEADER_BYTES];
        self.file.read_exact(&mut hb).map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                self.err("file ends inside this block (truncated)")
            } else {
                Error::io(&self.db.path, e)
            }
        })?;
        let h: RawBlockHeader = bytemuck::pod_read_unaligned(&hb);
        if h.magic != BLOCK_MAGIC {
            return Err(self.err("bad block magic: the block is corrupt"));
        }
        let raw_len = h.raw_len as usize;
        let stored_len = h.stored_len as usize;
        if raw_len > self.db.largest_stored
            || !raw_len.is_multiple_of(4)
            || stored_len > max_stored(self.db.largest_stored)
        {
            return Err(self.err("block lengths are out of range: the block is corrupt"));
        }
        let end = self.offset + (BLOCK_HEADER_BYTES + stored_len) as u64;
        if end > self.db.tables_offset {
            return Err(self.err("block runs into the tables: the block is corrupt"));
        }
        let runs = self.db.runs;
        payload(runs, &mut self.packed, &mut self.words).resize(raw_len.div_ceil(4).max(1), 0);
        let compressed = self.decompressor.is_some();
        if compressed {
            self.stored.resize(stored_len, 0);
            self.read_exact_or_err(true, stored_len)?;
            if VERIFY_CHECKSUMS && self.verify && h.compute_crc(&self.stored[..stored_len]) != h.crc
            {
                return Err(self.err("checksum mismatch: the block is corrupt"));
            }
            let target = payload(runs, &mut self.packed, &mut self.words);
            let dst: &mut [u8] = bytemuck::cast_slice_mut(&mut target[..]);
            let n = self
                .decompressor
                .as_mut()
                .expect("compressed")
                .decompress_to_buffer(&self.stored[..stored_len], &mut dst[..raw_len])
                .map_err(|e| self.err(format!("zstd: {e}")))?;
            if n != raw_len {
                return Err(self.err("decompressed size differs from the block header"));
            }
        } else {
            if stored_len != raw_len {
                return Err(self.err("stored and raw lengths differ in an uncompressed block"));
            }
            self.read_exact_or_err(false, raw_len)?;
            let bytes: &[u8] =
                bytemuck::cast_slice(payload(runs, &mut self.packed, &mut self.words));
            if VERIFY_CHECKSUMS && self.verify && h.compute_crc(&bytes[..raw_len]) != h.crc {
                return Err(self.err("checksum mismatch: the block is corrupt"));
            }
        }
        if h.index as u64 != self.next_index || h.first_object != self.next_object {
            return Err(self.err("block is out of sequence"));
        }
        // Before anything is decoded for them: a block holds no more objects
        // than are left, nor more records than its expanded size has room
        // for (a record is at least its header).
        if h.object_count as u64 > self.db.object_count - self.next_object
            || h.object_count as usize > self.db.largest_block / (4 * RECORD_HEADER_WORDS)
        {
            return Err(self.err("blocks hold more objects than the header says"));
        }
        if runs {
            self.packed.truncate(raw_len / 4);
            let at = if self.db.ids {
                super::packed::unpack_ids(
                    &self.packed,
                    h.object_count,
                    self.db.object_count,
                    &mut self.ids,
                )
                .map_err(|m| self.err(m))?
            } else {
                0
            };
            super::packed::unpack(
                &self.packed[at..],
                h.object_count,
                self.db.largest_block / 4,
                &mut self.words,
            )
            .map_err(|m| self.err(m))?;
        } else {
            self.words.truncate(raw_len / 4);
        }
        if self.verify {
            validate_records(
                &self.words,
                h.object_count,
                self.db.scene.materials.len(),
                self.db.models.len(),
            )
            .map_err(|m| self.err(m))?;
        }
        self.stats.bytes_read += (BLOCK_HEADER_BYTES + stored_len) as u64;
        self.decoded += self.words.len() as u64 * 4;
        self.stats.blocks_read += 1;
        self.offset = end;
        let index = self.next_index;
        self.next_index += 1;
        let first = self.next_object;
        self.next_object += h.object_count as u64;
        if self.db.layout.get().is_none() {
            self.learned.push(BlockSpan {
                end,
                objects: h.object_count,
            });
        }
        if self.next_object > self.db.object_count {
            return Err(self.err("blocks hold more objects than the header says"));
        }
        Ok(Some(Block {
            index,
            first_object: first,
            object_count: h.object_count,
            words: &self.words,
            ids: &self.ids,
        }))
    }
}

/// Checks every record of a decoded block so that iteration cannot fail.
fn validate_records(
    words: &[u32],
    count: u32,
    materials: usize,
    models: usize,
) -> Result<(), String> {
    let mut pos = 0usize;
    let mut instances = false;
    for i in 0..count {
        let head = words
            .get(pos..pos + RECORD_HEADER_WORDS)
            .ok_or_else(|| format!("record {i} is cut off"))?;
        let kind = ShapeKind::from_u8((head[0] & 0xff) as u8)
            .ok_or_else(|| format!("record {i} has unknown kind {}", head[0] & 0xff))?;
        let count = head[0] >> 8;
        let payload = kind.payload_words(count).ok_or_else(|| {
            format!(
                "record {i} is a {} with an invalid count {count}",
                kind.name()
            )
        })?;
        if head[1] as usize >= materials {
            return Err(format!(
                "record {i} refers to material {} of {materials}",
                head[1]
            ));
        }
        instances |= kind == ShapeKind::Instance;
        pos += RECORD_HEADER_WORDS + payload;
        if pos > words.len() {
            return Err(format!("record {i} is cut off"));
        }
    }
    if pos != words.len() {
        return Err("block has bytes after its last record".into());
    }
    if instances {
        // An instance's transform is stored as `f64` words, whose low
        // halves are any bit pattern: its record is checked as a shape.
        return validate_with_instances(words, count, models);
    }
    // No number may be NaN or infinite. The integer words (kind and vertex
    // count, material index) are far below the pattern once checked above,
    // so one pass over every word (which vectorizes) covers all the floats.
    const _: () = assert!(MAX_MATERIALS <= 1 << 23);
    const _: () = assert!(crate::shapes::MAX_POLYGON_VERTICES < 1 << 15);
    let bad = words.iter().fold(0u32, |acc, w| {
        acc | ((w & 0x7f80_0000) == 0x7f80_0000) as u32
    });
    if bad != 0 {
        return Err("a record has a non-finite number".into());
    }
    Ok(())
}

/// The finiteness check of [`validate_records`], record by record, for a
/// block holding instances (checked whole, and their model's index).
fn validate_with_instances(words: &[u32], count: u32, models: usize) -> Result<(), String> {
    let finite = |w: &[u32]| w.iter().all(|w| (w & 0x7f80_0000) != 0x7f80_0000);
    let mut pos = 0usize;
    for i in 0..count {
        let (o, len) =
            decode_record(&words[pos..], i).ok_or_else(|| format!("record {i} is cut off"))?;
        let rec = &words[pos..pos + len];
        match o.shape {
            Shape::Instance(inst) => {
                if !finite(&rec[..RECORD_HEADER_WORDS]) {
                    return Err(format!("record {i} has a non-finite number"));
                }
                o.shape.validate().map_err(|e| format!("record {i}: {e}"))?;
                if inst.model() as usize >= models {
                    return Err(format!(
                        "record {i} places model {} of {models}",
                        inst.model()
                    ));
                }
            }
            _ if !finite(rec) => return Err(format!("record {i} has a non-finite number")),
            _ => {}
        }
        pos += len;
    }
    Ok(())
}

impl<'a> Block<'a> {
    /// The objects of the block, in id order.
    pub fn objects(&self) -> ObjectIter<'a> {
        ObjectIter {
            words: self.words,
            ids: self.ids,
            pos: 0,
            first: self.first_object as u32,
            id: self.first_object as u32,
            left: self.object_count,
        }
    }

    /// Each object's place in the block and its bounding box, without
    /// decoding its geometry: what a scan needs to decide whether to look
    /// closer. [`Block::object_at`] decodes one.
    pub fn boxes(&self) -> BoxIter<'a> {
        BoxIter {
            words: self.words,
            ids: self.ids,
            pos: 0,
            first: self.first_object as u32,
            index: self.first_object as u32,
            left: self.object_count,
        }
    }

    /// The object whose record starts at word `at` (as [`Block::boxes`]
    /// gives it), at position `index`, of input id `rank`.
    #[inline(always)]
    pub fn object_at(&self, at: u32, index: u32, rank: u32) -> Option<ObjectRef<'a>> {
        decode_record(self.words.get(at as usize..)?, index).map(|(mut o, _)| {
            o.rank = rank;
            o
        })
    }

    /// Each object's input id, or empty when it is its position.
    pub fn ids(&self) -> &'a [u32] {
        self.ids
    }

    /// The block's records, as words (see the module documentation).
    pub fn words(&self) -> &'a [u32] {
        self.words
    }

    /// A block from words a [`Scan`] has read and checked.
    pub(super) fn from_words(
        index: u64,
        first_object: u64,
        object_count: u32,
        words: &'a [u32],
        ids: &'a [u32],
    ) -> Block<'a> {
        Block {
            index,
            first_object,
            object_count,
            words,
            ids,
        }
    }

    /// Bytes of this block's records (runs expanded).
    pub fn raw_bytes(&self) -> usize {
        self.words.len() * 4
    }
}

/// An object's record position in its block, index and bounding box.
#[derive(Clone, Copy, Debug)]
pub struct BoxRef {
    pub at: u32,
    pub index: u32,
    /// The input id (see [`ObjectRef::rank`]).
    pub rank: u32,
    pub kind: ShapeKind,
    pub bbox: Aabb,
}

pub struct BoxIter<'a> {
    words: &'a [u32],
    ids: &'a [u32],
    pos: usize,
    first: u32,
    index: u32,
    left: u32,
}

/// The input id of the object at position `index` of a block whose first
/// is `first`: from the block's ids, or the position itself.
#[inline(always)]
fn rank(ids: &[u32], first: u32, index: u32) -> u32 {
    match ids.get(index.wrapping_sub(first) as usize) {
        Some(&r) => r,
        None => index,
    }
}

impl Iterator for BoxIter<'_> {
    type Item = BoxRef;

    #[inline]
    fn next(&mut self) -> Option<BoxRef> {
        if self.left == 0 {
            return None;
        }
        // Records were validated when the block was read.
        let w = self.words.get(self.pos..self.pos + RECORD_HEADER_WORDS)?;
        let kind = ShapeKind::from_u8((w[0] & 0xff) as u8)?;
        let len = RECORD_HEADER_WORDS + kind.payload_words(w[0] >> 8)?;
        let f = |i: usize| f32::from_bits(w[i]);
        let r = BoxRef {
            at: self.pos as u32,
            index: self.index,
            rank: rank(self.ids, self.first, self.index),
            kind,
            bbox: Aabb {
                min: [f(2), f(3), f(4)],
                max: [f(5), f(6), f(7)],
            },
        };
        self.pos += len;
        self.index = self.index.wrapping_add(1);
        self.left -= 1;
        Some(r)
    }
}

pub struct ObjectIter<'a> {
    words: &'a [u32],
    ids: &'a [u32],
    pos: usize,
    first: u32,
    id: u32,
    left: u32,
}

impl<'a> Iterator for ObjectIter<'a> {
    type Item = ObjectRef<'a>;

    #[inline]
    fn next(&mut self) -> Option<ObjectRef<'a>> {
        if self.left == 0 {
            return None;
        }
        // Records were validated when the block was read.
        let (mut obj, len) = decode_record(&self.words[self.pos..], self.id)?;
        obj.rank = rank(self.ids, self.first, self.id);
        self.pos += len;
        self.id = self.id.wrapping_add(1);
        self.left -= 1;
        Some(obj)
    }
}

/// Decodes the record at the start of `w` (already validated) as object
/// `id`; returns it and its length in words.
#[inline(always)]
pub(crate) fn decode_record(w: &[u32], index: u32) -> Option<(ObjectRef<'_>, usize)> {
    let head = *w.first()?;
    let kind = ShapeKind::from_u8((head & 0xff) as u8)?;
    let count = head >> 8;
    let len = RECORD_HEADER_WORDS + kind.payload_words(count)?;
    let f: &[f32] = bytemuck::cast_slice(w.get(2..len)?);
    let bbox = Aabb {
        min: [f[0], f[1], f[2]],
        max: [f[3], f[4], f[5]],
    };
    Some((
        ObjectRef {
            index,
            rank: index,
            material: w[1],
            bbox,
            shape: kind.decode(&f[6..], count),
        },
        len,
    ))
}

impl ObjectRef<'_> {
    /// The object's primitive id.
    #[inline(always)]
    pub fn prim(&self) -> PrimId {
        PrimId::object(self.index)
    }

    /// The object's place in the tie order (its input id).
    #[inline(always)]
    pub fn tie(&self) -> PrimId {
        PrimId::object(self.rank)
    }
}

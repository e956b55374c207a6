//! Opening a database: its header read and checked, its tables read and
//! decoded, and every size the header states checked against the file
//! before anything relies on it. The steps run in the order of the
//! file's own dependencies (the header says where the tables are, the
//! tables where the models are), so an error names the first thing wrong.

use super::database::{Database, ModelEntry, VERIFY_CHECKSUMS};
use super::format::*;
use super::packed::PackCounts;
use super::tables::{Tables, TilesSection, decode_tables};
use crate::error::{Error, IoContext};
use crate::scene::{Aabb, Material, SceneHeader};
use crate::shapes::{KINDS, KindCounts, ShapeKind};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, OnceLock};

/// Where the database being opened lies, for its errors: a model's are
/// placed inside the file of the database that places it.
struct At<'a> {
    path: &'a Path,
    base: u64,
}

impl At<'_> {
    fn err(&self, location: &str, message: String) -> Error {
        Error::Database {
            file: self.path.to_path_buf(),
            location: if self.base == 0 {
                location.into()
            } else {
                format!("model at byte {}, {location}", self.base)
            },
            message,
        }
    }
}

/// What the checked header says of the file beyond the blocks.
struct Layout {
    compression: Compression,
    has_models: bool,
}

/// How the blocks store their records, checked against the header's sizes.
struct Storage {
    /// Triangles as runs (version 4).
    runs: bool,
    /// The objects' input ids beside the records (version 6).
    ids: bool,
    run_counts: PackCounts,
    /// The records' size once expanded.
    decoded_bytes: u64,
    /// The largest block as stored, before compression.
    largest_stored: usize,
}

impl Database {
    /// Opens the database of `len` bytes (the rest of the file if `None`)
    /// that starts at byte `base` of `path`.
    pub(super) fn open_at(path: &Path, base: u64, len: Option<u64>) -> Result<Database, Error> {
        let at = At { path, base };
        let mut f = File::open(path).at(path)?;
        let meta = f.metadata().at(path)?;
        let stamp = (meta.len(), meta.modified().ok());
        let file_bytes = match len {
            Some(l) if base.checked_add(l).is_some_and(|e| e <= meta.len()) => l,
            Some(_) => {
                return Err(at.err("header", "the model lies past the end of the file".into()));
            }
            None => meta.len(),
        };
        let h = read_header(&mut f, &at)?;
        let layout = check_header(&h, file_bytes, &at)?;
        let (mut scene, sizes, density, models, tiles) = read_tables(&mut f, &h, &layout, &at)?;
        // Blocks end where the tiles begin (version 9), else at the tables.
        let blocks_end = if tiles == TilesSection::default() {
            h.tables_offset
        } else {
            tiles.offset
        };
        let in_place = tiles == TilesSection::default()
            || tiles.offset.checked_add(tiles.bytes) == Some(h.tables_offset);
        if blocks_end < HEADER_BYTES as u64 || !in_place {
            return Err(at.err("tables", "the texture tiles are out of place".into()));
        }
        check_models(&h, &models, layout.has_models, file_bytes, &at)?;
        // A model's materials bind the world's images (checked when the
        // world opens it); the world's, its own.
        if len.is_none() {
            check_bindings(&scene.materials, scene.textures.len(), &at)?;
        }
        let origin = h.origin();
        if !origin.iter().all(|c| c.is_finite()) {
            return Err(at.err("header", "the origin is not finite".into()));
        }
        let world_view = scene.view;
        let world_lights = scene.lights.clone();
        to_origin(&mut scene, origin);
        let counts_known = h.flags & FLAG_COUNTS != 0;
        if sizes.total() != h.object_count {
            return Err(at.err(
                "tables",
                "size summary disagrees with the object count".into(),
            ));
        }
        let bbox = Aabb::from_array(h.bbox);
        let storage = check_storage(&h, file_bytes, &at)?;
        Ok(Database {
            path: path.to_path_buf(),
            scene,
            sizes,
            density,
            version: h.version,
            counts: KindCounts(std::array::from_fn(|i| h.counts[i])),
            object_count: h.object_count,
            bbox,
            compression: layout.compression,
            block_count: h.block_count,
            material_statements: h.material_statements,
            blocks_end,
            raw_bytes: h.raw_bytes,
            decoded_bytes: storage.decoded_bytes,
            runs: storage.runs,
            ids: storage.ids,
            full_scans: false,
            run_counts: storage.run_counts,
            file_bytes,
            largest_block: h.block_raw_max as usize,
            largest_stored: storage.largest_stored,
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
}

/// Reads the header at the database's start: the magic, a version this
/// sray reads, and (but when fuzzing) its checksum.
fn read_header(f: &mut File, at: &At) -> Result<RawHeader, Error> {
    let path = at.path;
    f.seek(SeekFrom::Start(at.base)).at(path)?;
    let mut hb = [0u8; HEADER_BYTES];
    let got = read_up_to(f, &mut hb).at(path)?;
    if got < 8 || hb[..8] != MAGIC {
        return Err(at.err("header", "not an sray object database (wrong magic)".into()));
    }
    if got < HEADER_BYTES {
        return Err(at.err(
            "header",
            format!("file is truncated: {got} bytes, the header alone is {HEADER_BYTES}"),
        ));
    }
    let h: RawHeader = bytemuck::pod_read_unaligned(&hb);
    if !(VERSION..=VERSION_NEWEST).contains(&h.version) {
        return Err(at.err(
            "header",
            format!(
                "database version {} is not supported (this sray reads versions {VERSION} to {VERSION_NEWEST}); regenerate it with `sray convert` or `sray gen`",
                h.version
            ),
        ));
    }
    if VERIFY_CHECKSUMS && h.header_crc != h.compute_crc() {
        return Err(at.err("header", "checksum mismatch: the header is corrupt".into()));
    }
    Ok(h)
}

/// Checks what the header says of the file's layout: a known compression,
/// the tables (and models) ending the file, object counts that add up.
fn check_header(h: &RawHeader, file_bytes: u64, at: &At) -> Result<Layout, Error> {
    let compression = match (h.compression, h.compression_level) {
        (0, _) => Compression::None,
        (1, l) => Compression::Zstd(l),
        (c, _) => return Err(at.err("header", format!("unknown compression code {c}"))),
    };
    if h.header_bytes as usize != HEADER_BYTES || h.block_raw_max as usize > MAX_BLOCK_RAW {
        return Err(at.err("header", "unsupported header or block size".into()));
    }
    let models_bytes = join64(h.models_bytes[0], h.models_bytes[1]);
    if (h.version < VERSION_MODELS && models_bytes != 0)
        || (h.version < VERSION_APPEARANCE && h.layout != 0)
        || h.layout & !LAYOUT_IDS != 0
    {
        return Err(at.err("header", "reserved words are not zero".into()));
    }
    // Version 5 always has models; version 6 when it says it has.
    let has_models = h.version == VERSION_MODELS || (h.version >= VERSION_IDS && models_bytes != 0);
    let tables_end = h
        .tables_offset
        .checked_add(h.tables_len)
        .and_then(|e| e.checked_add(models_bytes));
    if h.tables_offset < HEADER_BYTES as u64 || tables_end.is_none() {
        return Err(at.err("header", "tables offset is out of range".into()));
    }
    if tables_end != Some(file_bytes) {
        return Err(at.err(
            "header",
            format!(
                "file is truncated or has trailing bytes: it is {file_bytes} bytes, the header says {}",
                h.tables_offset + h.tables_len + models_bytes
            ),
        ));
    }
    if h.tables_len > (64 << 20) + 64 * MAX_MATERIALS as u64 + MAX_IMAGE_BYTES {
        return Err(at.err("header", "tables are implausibly large".into()));
    }
    if h.counts[KINDS..].iter().any(|&c| c != 0) {
        return Err(at.err(
            "header",
            "the database holds kinds of primitive this sray does not know; use a newer sray"
                .into(),
        ));
    }
    if h.counts.iter().try_fold(0u64, |a, &c| a.checked_add(c)) != Some(h.object_count)
        || h.object_count > u32::MAX as u64
    {
        return Err(at.err("header", "object counts are inconsistent".into()));
    }
    Ok(Layout {
        compression,
        has_models,
    })
}

/// Checks that every texture binding of `materials` names one of the
/// `images` images there are.
fn check_bindings(materials: &[Material], images: usize, at: &At) -> Result<(), Error> {
    for (i, m) in materials.iter().enumerate() {
        let mut bound = m.maps.slots().map(|(_, b)| b).to_vec();
        bound.push(m.texture);
        if let Some(b) = bound.iter().flatten().find(|b| b.image as usize >= images) {
            return Err(at.err(
                "tables",
                format!("material {i} binds image {} of {images}", b.image),
            ));
        }
    }
    Ok(())
}

/// Reads the tables, checks their checksum (but when fuzzing) and decodes
/// them.
fn read_tables(f: &mut File, h: &RawHeader, layout: &Layout, at: &At) -> Result<Tables, Error> {
    let path = at.path;
    let mut tables = vec![0u8; h.tables_len as usize];
    f.seek(SeekFrom::Start(at.base + h.tables_offset))
        .at(path)?;
    f.read_exact(&mut tables).at(path)?;
    if VERIFY_CHECKSUMS && crc32fast::hash(&tables) != h.tables_crc {
        return Err(at.err("tables", "checksum mismatch: the tables are corrupt".into()));
    }
    decode_tables(
        &tables,
        h.version >= VERSION_DENSITY,
        h.version >= VERSION_APPEARANCE,
        h.version >= VERSION_TEXTURES,
        h.version >= VERSION_TILED,
        layout.has_models,
    )
    .ok_or_else(|| at.err("tables", "malformed tables".into()))
}

/// Checks that the models lie after the tables, in order, and fill the
/// rest of the file; and that a database placing instances has models.
fn check_models(
    h: &RawHeader,
    models: &[ModelEntry],
    has_models: bool,
    file_bytes: u64,
    at: &At,
) -> Result<(), Error> {
    let mut end = h.tables_offset + h.tables_len;
    for (i, m) in models.iter().enumerate() {
        if m.offset != end || m.bytes < HEADER_BYTES as u64 || !(m.pad.is_finite() && m.pad >= 0.0)
        {
            return Err(at.err("tables", format!("model {i} is out of place")));
        }
        end = end
            .checked_add(m.bytes)
            .ok_or_else(|| at.err("tables", format!("model {i} is out of place")))?;
    }
    if end != file_bytes || (has_models && models.is_empty()) {
        return Err(at.err("tables", "the models do not fill the file".into()));
    }
    if counts_instances(h) > 0 && models.is_empty() {
        return Err(at.err("tables", "instances with no models".into()));
    }
    Ok(())
}

/// Puts the view and the lights in the geometry's frame, relative to
/// `origin`: shading and cameras work there.
fn to_origin(scene: &mut SceneHeader, origin: [f64; 3]) {
    let local = |p: [f64; 3]| std::array::from_fn(|i| p[i] - origin[i]);
    scene.view.from = local(scene.view.from);
    scene.view.at = local(scene.view.at);
    for l in &mut scene.lights {
        l.position = local(l.position);
    }
}

/// How the blocks store their records, and the header's sizes of them
/// checked: expanded no smaller than stored, within what the blocks (and
/// the file) have room for, so that no scan allocates past them.
fn check_storage(h: &RawHeader, file_bytes: u64, at: &At) -> Result<Storage, Error> {
    let run_counts = PackCounts {
        runs: join64(h.runs[0], h.runs[1]),
        run_triangles: join64(h.run_triangles[0], h.run_triangles[1]),
    };
    // A version 4 file without a run stores its records as version 3
    // does: they are read in place (a record with a run's code is an
    // unknown kind there, so a lying count is an error, not a misread).
    // Version 6 blocks always go through the packed path: their ids
    // come first.
    let ids =
        h.version == VERSION_IDS || (h.version >= VERSION_APPEARANCE && h.layout & LAYOUT_IDS != 0);
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
    if decoded_bytes.saturating_add(ids_bytes) < h.raw_bytes || !decoded_bytes.is_multiple_of(4) {
        return Err(at.err(
            "header",
            "the records' expanded size is below their stored size".into(),
        ));
    }
    if h.block_count > file_bytes / BLOCK_HEADER_BYTES as u64 {
        return Err(at.err(
            "header",
            "the block count exceeds what the file has room for".into(),
        ));
    }
    if runs && decoded_bytes > h.block_count.saturating_mul(h.block_raw_max as u64) {
        return Err(at.err(
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
        return Err(at.err("header", "unsupported header or block size".into()));
    }
    Ok(Storage {
        runs,
        ids,
        run_counts,
        decoded_bytes,
        largest_stored,
    })
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

/// Instance records the header counts.
fn counts_instances(h: &RawHeader) -> u64 {
    h.counts[ShapeKind::Instance as usize]
}

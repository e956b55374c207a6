//! An open object database: what its header and tables say (kept in
//! memory), and its models, each a database of its own inside the file.
//! Opening is in [`super::open`], scanning in [`super::scan`].

use super::format::*;
use super::packed::PackCounts;
use crate::error::Error;
use crate::scene::{Aabb, DensitySummary, ImageData, Light, SceneHeader, SizeSummary, View};
use crate::shapes::{KindCounts, ShapeKind};
use crate::texture::{Encoding, Texture, TileRef, TileStore};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, OnceLock};
use std::time::SystemTime;

/// Checksums are verified always, except when fuzzing (`cargo fuzz` builds
/// with `--cfg fuzzing`): there a mutated byte would almost always stop at
/// the checksum, and the fuzzer would never reach the decoding behind it.
pub(super) const VERIFY_CHECKSUMS: bool = !cfg!(fuzzing);

/// An open object database: header and tables in memory, objects on disk.
#[derive(Clone, Debug)]
pub struct Database {
    pub(super) path: PathBuf,
    pub(super) scene: SceneHeader,
    pub(super) sizes: SizeSummary,
    pub(super) density: Option<DensitySummary>,
    pub(super) version: u32,
    pub(super) counts: KindCounts,
    pub(super) object_count: u64,
    pub(super) bbox: Aabb,
    pub(super) compression: Compression,
    pub(super) block_count: u64,
    pub(super) material_statements: u64,
    /// Where the blocks end: the tables, or the texture tiles before them
    /// (version 9).
    pub(super) blocks_end: u64,
    pub(super) raw_bytes: u64,
    pub(super) decoded_bytes: u64,
    /// Blocks store triangles as runs (version 4).
    pub(super) runs: bool,
    /// Blocks store their objects' input ids (version 6: objects in
    /// spatial order).
    pub(super) ids: bool,
    pub(super) run_counts: PackCounts,
    /// Scans read every block, as the paper's passes do: none is passed
    /// over ([`Database::set_full_scans`]).
    pub(super) full_scans: bool,
    pub(super) file_bytes: u64,
    pub(super) largest_block: usize,
    /// The largest block as stored, before compression.
    pub(super) largest_stored: usize,
    pub(super) origin: [f64; 3],
    /// The view and lights as stored, in world coordinates (`scene` has
    /// them relative to the origin, as the geometry is).
    pub(super) world_view: View,
    pub(super) world_lights: Vec<Light>,
    pub(super) triangles: Option<u64>,
    pub(super) vertices: Option<u64>,
    pub(super) mesh: bool,
    /// The file as it was opened: a scan refuses a file changed since.
    pub(super) stamp: (u64, Option<SystemTime>),
    /// Set once a scan has checked every block's checksum and records:
    /// later scans of the unchanged file skip those checks (they cost a
    /// third of a pass over a large mesh). Shared by clones.
    pub(super) verified: Arc<AtomicBool>,
    /// Where each block ends and how many objects it holds, learned by
    /// the first complete scan: later scans may pass over a block without
    /// reading it ([`super::Scan::skip_block`]). Shared by clones.
    pub(super) layout: Arc<OnceLock<Vec<BlockSpan>>>,
    /// Where this database starts in its file: 0, or a model's place
    /// inside the file of the database that places it.
    pub(super) base: u64,
    /// The models this database places (version 5).
    pub(super) models: Vec<ModelEntry>,
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
        let images = self.scene.textures.len();
        if let Some((i, t)) = db.scene.materials.iter().enumerate().find_map(|(i, m)| {
            let mut bound = m.maps.slots().map(|(_, b)| b).to_vec();
            bound.push(m.texture);
            bound
                .into_iter()
                .flatten()
                .find(|t| t.image as usize >= images)
                .map(|t| (i, t))
        }) {
            return Err(Error::Database {
                file: self.path.clone(),
                location: format!("model {m}"),
                message: format!("material {i} binds image {} of {images}", t.image),
            });
        }
        Ok(db)
    }

    /// The models this database places.
    pub fn models(&self) -> &[ModelEntry] {
        &self.models
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

    /// Where the objects are, if the database says (version 3 files).
    pub fn density(&self) -> Option<&DensitySummary> {
        self.density.as_ref()
    }

    /// Object counts and bounds per size class.
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
        self.blocks_end - HEADER_BYTES as u64
    }

    /// The scene's images as textures: tiled images (version 9) read from
    /// this file as shading needs them, through a cache of `cache_bytes`;
    /// images stored whole (version 8) decoded into memory now.
    pub fn textures(&self, cache_bytes: u64) -> Result<Arc<[Texture]>, Error> {
        let images = &self.scene.textures;
        let store = if images.iter().any(|i| matches!(i.data, ImageData::Tiled(_))) {
            Some(Arc::new(TileStore::open(
                &self.path,
                self.compression != Compression::None,
                cache_bytes,
            )?))
        } else {
            None
        };
        images
            .iter()
            .enumerate()
            .map(|(i, im)| match (&im.data, &store) {
                (ImageData::Encoded(bytes), _) => Texture::decode(bytes, &im.name, Encoding::Srgb),
                (ImageData::Tiled(t), Some(store)) => {
                    let refs = t
                        .tiles
                        .iter()
                        .map(|r| TileRef {
                            offset: r.offset + self.base,
                            ..*r
                        })
                        .collect();
                    Texture::stored(t.width, t.height, t.encoding, store.clone(), i as u32, refs)
                        .map_err(|message| Error::Database {
                            file: self.path.clone(),
                            location: "tables".into(),
                            message,
                        })
                }
                (ImageData::Tiled(_), None) => unreachable!("a store is open for tiled images"),
            })
            .collect()
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
}

/// One block's place in the file.
#[derive(Clone, Copy, Debug)]
pub(super) struct BlockSpan {
    /// The byte after its payload (where the next block starts).
    pub(super) end: u64,
    pub(super) objects: u32,
}

//! Streams a scene into an object database, atomically: the file appears
//! under its name only once it is complete.

use super::format::*;
use super::packed::{PackCounts, Packer};
use super::spatial::SpatialSorter;
use super::tables::TilesSection;
use crate::error::{Error, IoContext};
use crate::scene::{
    Aabb, DensitySummary, ImageData, Light, Material, MeshFacts, ModelRef, SceneHeader, SceneSink,
    SizeSummary, TextureImage, TiledImage, View,
};
use crate::shapes::{KindCounts, Shape, ShapeKind};
use crate::texture::mip::{TileTexels, for_each_tile, pack};
use crate::texture::{Encoding, TileRef};
use std::collections::HashMap;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// What a finished database holds.
#[derive(Clone, Debug)]
pub struct WriteSummary {
    pub path: PathBuf,
    pub objects: u64,
    pub counts: KindCounts,
    pub bbox: Aabb,
    pub file_bytes: u64,
    pub raw_bytes: u64,
    /// The records' size once runs are expanded.
    pub decoded_bytes: u64,
    pub blocks: u64,
    pub runs: PackCounts,
}

/// A [`SceneSink`] that writes an object database. Call
/// [`DbWriter::finish`]; dropping it unfinished leaves no file behind.
pub struct DbWriter {
    path: PathBuf,
    out: Option<BufWriter<tempfile::NamedTempFile>>,
    compression: Compression,
    compressor: Option<zstd::bulk::Compressor<'static>>,
    /// Records of the block being filled.
    block: Vec<u32>,
    block_first: u64,
    block_objects: u32,
    /// Stores a block's triangles as runs; `None` writes version 3.
    packer: Option<Packer>,
    /// The block as stored, before compression.
    packed: Vec<u32>,
    stored: Vec<u8>,
    offset: u64,
    blocks: u64,
    raw_bytes: u64,
    decoded_bytes: u64,
    largest_block: usize,
    largest_stored: usize,
    objects: u64,
    counts: KindCounts,
    bbox: Aabb,
    sizes: SizeSummary,
    density: DensitySummary,
    view: Option<View>,
    background: [f32; 3],
    lights: Vec<Light>,
    materials: Vec<Material>,
    material_index: HashMap<crate::scene::MaterialKey, u32>,
    /// The images materials bind (version 8).
    textures: Vec<TextureImage>,
    /// Images bound as colours and as data ([`Encoding`]).
    colour_images: std::collections::HashSet<u32>,
    data_images: std::collections::HashSet<u32>,
    texture_bytes: u64,
    current_material: Option<u32>,
    material_statements: u64,
    origin: [f64; 3],
    /// A mesh's vertex table, when the source is a mesh.
    mesh_vertices: Option<u64>,
    /// Vertices the polygons and patches list.
    listed_vertices: u64,
    triangles: u64,
    /// The models written so far, each a database of its own in a
    /// temporary file beside the output, appended at the end.
    models: Vec<ModelPart>,
    /// The model being written: objects and materials go to it.
    open_model: Option<Box<DbWriter>>,
    /// With the spatial order (version 6), the records waiting to be
    /// sorted; `None` writes them in input order.
    sorter: Option<SpatialSorter>,
    /// Whether blocks store their objects' input ids (version 6).
    ids: bool,
    /// The input ids of the block being filled.
    block_ids: Vec<u32>,
    /// A block's ids and runs, as stored.
    id_words: Vec<u32>,
    /// One record, encoded before the sorter takes it.
    scratch: Vec<u32>,
}

/// A finished model, waiting to be appended.
struct ModelPart {
    file: tempfile::NamedTempFile,
    bytes: u64,
    bbox: Aabb,
    /// The largest `|M^-1| * |p|` over its instances (row-sum norm of the
    /// inverse's linear part, largest coordinate of the placed box): how
    /// far, in the model's units, the rounding of a placed vertex may
    /// move it.
    spread: f64,
}

/// The output buffer of [`DbWriter::create`].
pub const WRITE_BUFFER: usize = 4 << 20;

impl DbWriter {
    /// Starts a database at `path` (written to a temporary file beside it).
    pub fn create(path: &Path, compression: Compression) -> Result<DbWriter, Error> {
        Self::create_with_buffer(path, compression, WRITE_BUFFER)
    }

    /// As [`DbWriter::create`], with an output buffer of `buffer` bytes
    /// (for writers under a tight memory budget).
    pub fn create_with_buffer(
        path: &Path,
        compression: Compression,
        buffer: usize,
    ) -> Result<DbWriter, Error> {
        let tmp = crate::fsutil::temp_beside(path)?;
        let mut out = BufWriter::with_capacity(buffer, tmp);
        out.write_all(&[0u8; HEADER_BYTES]).at(path)?;
        let compressor = match compression {
            Compression::None => None,
            Compression::Zstd(level) => Some(zstd::bulk::Compressor::new(level).at(path)?),
        };
        Ok(DbWriter {
            path: path.to_path_buf(),
            out: Some(out),
            compression,
            compressor,
            block: Vec::with_capacity(BLOCK_TARGET / 4),
            block_first: 0,
            block_objects: 0,
            packer: Some(Packer::default()),
            packed: Vec::with_capacity(BLOCK_TARGET / 4),
            stored: Vec::new(),
            offset: HEADER_BYTES as u64,
            blocks: 0,
            raw_bytes: 0,
            decoded_bytes: 0,
            largest_block: 0,
            largest_stored: 0,
            objects: 0,
            counts: KindCounts::default(),
            bbox: Aabb::EMPTY,
            sizes: SizeSummary::default(),
            density: DensitySummary::default(),
            view: None,
            background: [0.0; 3],
            lights: Vec::new(),
            materials: Vec::new(),
            material_index: HashMap::new(),
            textures: Vec::new(),
            colour_images: Default::default(),
            data_images: Default::default(),
            texture_bytes: 0,
            current_material: None,
            material_statements: 0,
            origin: [0.0; 3],
            mesh_vertices: None,
            listed_vertices: 0,
            triangles: 0,
            models: Vec::new(),
            open_model: None,
            sorter: None,
            ids: false,
            block_ids: Vec::new(),
            id_words: Vec::new(),
            scratch: Vec::new(),
        })
    }

    /// Writes the objects in spatial order (version 6; see
    /// [`super::spatial`]), sorting within `budget` bytes and spilling
    /// sorted chunks to `dir` (the system's temporary directory if
    /// `None`). Models keep their input order.
    pub fn spatial(mut self, budget: usize, dir: Option<&Path>) -> DbWriter {
        self.sort_spatially(budget, dir);
        self
    }

    /// Writes objects sent with their input ids
    /// ([`SceneSink::ranked_object`], a database in spatial order) back in
    /// the order of those ids, as their input had them (version 4 or 5),
    /// sorting within `budget` bytes.
    pub fn sort_by_id(&mut self, budget: usize, dir: Option<&Path>) {
        assert_eq!(
            self.objects, 0,
            "the order is chosen before the first object"
        );
        self.sorter = Some(SpatialSorter::by_id(budget, dir, &self.path));
        self.ids = false;
    }

    /// As [`DbWriter::spatial`], before the first object.
    pub fn sort_spatially(&mut self, budget: usize, dir: Option<&Path>) {
        assert_eq!(
            self.objects, 0,
            "the order is chosen before the first object"
        );
        if self.packer.is_none() {
            self.packer = Some(Packer::default());
        }
        self.sorter = Some(SpatialSorter::new(budget, dir, &self.path));
        self.ids = true;
    }

    /// Writes version 3, triangles as records, as sray did before runs
    /// (for comparisons and for tests of reading old files).
    pub fn without_runs(mut self) -> DbWriter {
        self.packer = None;
        self.sorter = None;
        self.ids = false;
        self
    }

    /// Memory a writer holds besides its output buffer, at most: one
    /// block of records, the block as stored, one compressed block, the
    /// packer's tables, and room for a record and the rest of a group of
    /// objects past the block's target.
    pub const HELD_BYTES: usize = 3 * (BLOCK_TARGET + BLOCK_TARGET / 8) + (96 << 10);

    fn run_counts(&self) -> PackCounts {
        self.packer.as_ref().map(|p| p.counts).unwrap_or_default()
    }

    pub fn objects_written(&self) -> u64 {
        self.objects
    }

    fn out(&mut self) -> &mut BufWriter<tempfile::NamedTempFile> {
        self.out.as_mut().expect("writer used after finish")
    }

    fn flush_block(&mut self) -> Result<(), Error> {
        if self.block_objects == 0 {
            return Ok(());
        }
        let raw: &[u8] = match self.packer.as_mut() {
            Some(p) if self.ids => {
                p.pack(&self.block, &mut self.packed);
                self.id_words.clear();
                super::packed::pack_ids(&self.block_ids, &mut self.id_words);
                self.id_words.extend_from_slice(&self.packed);
                bytemuck::cast_slice(&self.id_words)
            }
            Some(p) => {
                p.pack(&self.block, &mut self.packed);
                bytemuck::cast_slice(&self.packed)
            }
            None => bytemuck::cast_slice(&self.block),
        };
        let decoded_len = self.block.len() * 4;
        let (payload, stored_len): (&[u8], usize) = match self.compressor.as_mut() {
            None => (raw, raw.len()),
            Some(c) => {
                self.stored.clear();
                self.stored
                    .reserve(zstd::zstd_safe::compress_bound(raw.len()));
                let n = c
                    .compress_to_buffer(raw, &mut self.stored)
                    .map_err(|e| Error::io(&self.path, e))?;
                (&self.stored[..], n)
            }
        };
        let mut h = RawBlockHeader {
            magic: BLOCK_MAGIC,
            index: u32::try_from(self.blocks)
                .map_err(|_| Error::Scene("more than 2^32 blocks".into()))?,
            first_object: self.block_first,
            object_count: self.block_objects,
            raw_len: raw.len() as u32,
            stored_len: stored_len as u32,
            crc: 0,
        };
        h.crc = h.compute_crc(&payload[..stored_len]);
        let raw_len = raw.len() as u64;
        self.largest_block = self.largest_block.max(decoded_len);
        self.largest_stored = self.largest_stored.max(raw.len());
        let out = self.out.as_mut().expect("writer used after finish");
        out.write_all(bytemuck::bytes_of(&h)).at(&self.path)?;
        out.write_all(&payload[..stored_len]).at(&self.path)?;
        self.offset += (BLOCK_HEADER_BYTES + stored_len) as u64;
        self.raw_bytes += raw_len;
        self.decoded_bytes += decoded_len as u64;
        self.blocks += 1;
        self.block.clear();
        self.block_ids.clear();
        self.block_first += self.block_objects as u64;
        self.block_objects = 0;
        Ok(())
    }

    /// Adds a record to the block being filled, as object `id` of the
    /// input, in a database in spatial order: the block is closed first if
    /// the record would take it past its target and the record begins a
    /// group of [`AGGREGATE_SIZE`] objects (so that no aggregate is cut,
    /// and a pass that passes over a block passes over whole aggregates),
    /// or if it would take it an eighth past its target all the same.
    fn place(&mut self, id: u32, record: &[u32]) -> Result<(), Error> {
        let bytes = (self.block.len() + record.len()) * 4;
        let group_starts =
            (self.block_first + self.block_objects as u64).is_multiple_of(AGGREGATE_SIZE as u64);
        if self.block_objects > 0
            && ((bytes > BLOCK_TARGET && group_starts) || bytes > BLOCK_TARGET + BLOCK_TARGET / 8)
        {
            self.flush_block()?;
        }
        self.block.extend_from_slice(record);
        if self.ids {
            self.block_ids.push(id);
        }
        self.block_objects += 1;
        Ok(())
    }

    fn tables(&self) -> Vec<u8> {
        let mut e = Enc::default();
        let v = self.view.expect("checked in finish");
        for x in v.from.iter().chain(&v.at).chain(&v.up) {
            e.f64(*x);
        }
        e.f64(v.angle);
        e.f64(v.hither);
        e.u32(v.resolution[0]);
        e.u32(v.resolution[1]);
        for c in self.background {
            e.f32(c);
        }
        e.u32(self.lights.len() as u32);
        for l in &self.lights {
            for p in l.position {
                e.f64(p);
            }
            e.u32(l.color.is_some() as u32);
            for c in l.color.unwrap_or([0.0; 3]) {
                e.f32(c);
            }
        }
        e.u32(self.materials.len() as u32);
        for m in &self.materials {
            for x in [
                m.color[0], m.color[1], m.color[2], m.kd, m.ks, m.shine, m.t, m.ior,
            ] {
                e.f32(x);
            }
        }
        let used: Vec<_> = (0..self.sizes.classes.len())
            .filter(|&i| self.sizes.classes[i].count > 0)
            .collect();
        e.u32(used.len() as u32);
        for i in used {
            let c = &self.sizes.classes[i];
            e.u32(i as u32);
            e.u64(c.count);
            for x in c.bounds.to_array() {
                e.f32(x);
            }
        }
        // The density summary: its lattice, then its entries (none if it
        // was dropped or the scene is empty; level i32::MIN marks that).
        let d = &self.density;
        let sorted = if d.usable() { d.sorted() } else { Vec::new() };
        e.u32(if d.usable() {
            d.level as u32
        } else {
            i32::MIN as u32
        });
        for o in d.origin {
            e.u64(o as u64);
        }
        e.u32(sorted.len() as u32);
        for ((cell, class), c) in sorted {
            e.u32(cell);
            e.u32(class as u32);
            e.u64(c.count);
            for x in c.bounds.to_array() {
                e.f32(x);
            }
        }
        e.0
    }

    /// Completes the file and moves it into place.
    pub fn finish(self) -> Result<WriteSummary, Error> {
        let path = self.path.clone();
        let (tmp, summary) = self.complete()?;
        crate::fsutil::persist(tmp, &path)?;
        Ok(summary)
    }

    /// Completes the file, leaving it in its temporary place.
    fn complete(mut self) -> Result<(tempfile::NamedTempFile, WriteSummary), Error> {
        if self.open_model.is_some() {
            return Err(Error::Scene("a model was begun and not ended".into()));
        }
        if self.view.is_none() {
            return Err(Error::Scene("the scene has no view ('v')".into()));
        }
        if let Some(sorter) = self.sorter.take() {
            sorter.finish(|id, record| self.place(id, record))?;
        }
        self.flush_block()?;
        let mut tables = self.tables();
        // The appearance (version 7), before the models' table: only a
        // scene with glTF materials or lights has it.
        let appearance = super::tables::encode_appearance(&self.lights, &self.materials);
        // Textures (version 9) go on after the rest of the appearance
        // (empty lists when the scene has none of it): the images' tiles
        // are written after the last block, and the tables list them.
        let textured = !self.textures.is_empty() || self.counts.get(ShapeKind::Textured) > 0;
        let appearance = match (appearance, textured) {
            (a, true) => {
                let (images, section) = self.write_tiles()?;
                let mut a = a.unwrap_or_else(|| vec![0; 8]);
                a.extend(super::tables::encode_bindings(&self.materials));
                a.extend(super::tables::encode_tiled_images(section, &images));
                Some(a)
            }
            (a, false) => a,
        };
        if let Some(a) = &appearance {
            tables.extend_from_slice(a);
        }
        let tables_offset = self.offset;
        // The models' table closes the tables (version 5): where each
        // model's database lies, relative to the start of this file.
        if !self.models.is_empty() {
            let mut e = Enc::default();
            let table_bytes = 4 + self.models.len() * 32;
            let mut at = tables_offset + (tables.len() + table_bytes) as u64;
            e.u32(self.models.len() as u32);
            for m in &self.models {
                e.u64(at);
                e.u64(m.bytes);
                // The margin a model's grid keeps around each triangle,
                // in its units (see `crate::models`): four times the
                // rounding of a placed corner (half an ulp of the
                // largest placed coordinate, 2^-24 of it, taken back
                // into the model by the inverse), and a millionth of the
                // model's size, as a grid keeps around every box.
                let extent = (0..3)
                    .map(|i| (m.bbox.max[i] - m.bbox.min[i]) as f64)
                    .fold(0.0, f64::max);
                e.f64(1e-6 * extent + 4.0 * m.spread * f64::powi(2.0, -24));
                e.u64(0);
                at += m.bytes;
            }
            debug_assert_eq!(e.0.len(), table_bytes);
            tables.extend(e.0);
        }
        let path = self.path.clone();
        self.out().write_all(&tables).at(path)?;
        let mut models_bytes = 0u64;
        for m in &mut self.models {
            let path = self.path.clone();
            let f = m.file.as_file_mut();
            f.seek(SeekFrom::Start(0)).at(&path)?;
            let n = std::io::copy(f, self.out.as_mut().expect("open")).at(&path)?;
            if n != m.bytes {
                return Err(Error::Scene(format!(
                    "a model's database changed size while it was appended ({n} bytes of {})",
                    m.bytes
                )));
            }
            models_bytes += n;
        }
        let c = self.counts;
        let mut h = RawHeader {
            magic: MAGIC,
            version: if textured {
                VERSION_TILED
            } else if appearance.is_some() {
                VERSION_APPEARANCE
            } else if self.ids {
                VERSION_IDS
            } else if !self.models.is_empty() {
                VERSION_MODELS
            } else if self.packer.is_some() {
                VERSION_PACKED
            } else {
                VERSION_DENSITY
            },
            header_bytes: HEADER_BYTES as u32,
            compression: match self.compression {
                Compression::None => 0,
                Compression::Zstd(_) => 1,
            },
            compression_level: match self.compression {
                Compression::None => 0,
                Compression::Zstd(l) => l,
            },
            block_raw_max: self.largest_block as u32,
            layout: if appearance.is_some() && self.ids {
                LAYOUT_IDS
            } else {
                0
            },
            object_count: self.objects,
            counts: {
                let mut counts = [0; MAX_KINDS];
                counts[..c.0.len()].copy_from_slice(&c.0);
                counts
            },
            block_count: self.blocks,
            material_statements: self.material_statements,
            tables_offset,
            tables_len: tables.len() as u64,
            raw_bytes: self.raw_bytes,
            bbox: self.bbox.to_array(),
            tables_crc: crc32fast::hash(&tables),
            origin: [0; 6],
            triangles: split64(self.triangles),
            vertices: split64(self.mesh_vertices.unwrap_or(self.listed_vertices)),
            flags: FLAG_COUNTS
                | if self.mesh_vertices.is_some() {
                    FLAG_MESH
                } else {
                    0
                },
            decoded_bytes: if self.packer.is_some() {
                split64(self.decoded_bytes)
            } else {
                [0; 2]
            },
            runs: split64(self.run_counts().runs),
            run_triangles: split64(self.run_counts().run_triangles),
            block_stored_max: if self.packer.is_some() {
                self.largest_stored as u32
            } else {
                0
            },
            models_bytes: split64(models_bytes),
            header_crc: 0,
        };
        h.set_origin(self.origin);
        h.header_crc = h.compute_crc();
        let path = self.path.clone();
        let mut out = self.out.take().expect("finish runs once");
        out.seek(SeekFrom::Start(0)).at(&path)?;
        out.write_all(bytemuck::bytes_of(&h)).at(&path)?;
        let tmp = out
            .into_inner()
            .map_err(|e| Error::io(&path, e.into_error()))?;
        let file_bytes = tables_offset + tables.len() as u64 + models_bytes;
        Ok((
            tmp,
            WriteSummary {
                path,
                objects: self.objects,
                counts: self.counts,
                bbox: self.bbox,
                file_bytes,
                raw_bytes: self.raw_bytes,
                decoded_bytes: self.decoded_bytes,
                blocks: self.blocks,
                runs: self.run_counts(),
            },
        ))
    }

    /// Writes each image's mip chain as tiles after the last block (each
    /// compressed as the blocks are), one image decoded at a time; returns
    /// the images as the tables list them and where the tiles lie.
    fn write_tiles(&mut self) -> Result<(Vec<TextureImage>, TilesSection), Error> {
        let start = self.offset;
        let images = std::mem::take(&mut self.textures);
        let mut tiled = Vec::with_capacity(images.len());
        let level = match self.compression {
            Compression::None => None,
            Compression::Zstd(l) => Some(l),
        };
        let path = self.path.clone();
        for (i, im) in images.iter().enumerate() {
            let ImageData::Encoded(bytes) = &im.data else {
                unreachable!("the writer takes encoded images only");
            };
            let (width, height, texels) = crate::texture::decode_rgba8(bytes, &im.name)?;
            let mut tiles = Vec::new();
            // An image bound only as data (metallic-roughness, normals)
            // holds linear values; one bound as a colour anywhere is sRGB.
            let i = i as u32;
            let encoding = if self.data_images.contains(&i) && !self.colour_images.contains(&i) {
                Encoding::Linear
            } else {
                Encoding::Srgb
            };
            let tiling = |t: &TileTexels, cols, rows| -> Result<(), Error> {
                let packed = pack(t, cols, rows);
                let compressed;
                let stored = match level {
                    Some(l) => {
                        compressed = zstd::bulk::compress(&packed, l)
                            .map_err(|e| Error::Scene(format!("{}: {e}", im.name)))?;
                        &compressed[..]
                    }
                    None => &packed[..],
                };
                tiles.push(TileRef {
                    offset: self.offset,
                    stored: stored.len() as u32,
                    crc: crc32fast::hash(stored),
                });
                self.out().write_all(stored).at(&path)?;
                self.offset += stored.len() as u64;
                Ok(())
            };
            for_each_tile(texels, width, height, encoding, tiling)?;
            tiled.push(TextureImage {
                name: im.name.clone(),
                data: ImageData::Tiled(TiledImage {
                    width,
                    height,
                    encoding,
                    tiles,
                }),
            });
        }
        self.textures = images;
        let section = TilesSection {
            offset: start,
            bytes: self.offset - start,
        };
        Ok((tiled, section))
    }

    /// The scene header as it stands (for callers that render what they
    /// just wrote).
    pub fn header(&self) -> Option<SceneHeader> {
        Some(SceneHeader {
            view: self.view?,
            background: self.background,
            lights: self.lights.clone(),
            materials: self.materials.clone(),
            textures: self.textures.clone(),
        })
    }
}

impl DbWriter {
    fn begin_model_impl(&mut self) -> Result<(), Error> {
        if self.open_model.is_some() {
            return Err(Error::Scene("a model begun inside another".into()));
        }
        if self.models.len() >= MAX_MODELS {
            return Err(Error::Scene(format!("more than {MAX_MODELS} models")));
        }
        let mut w = DbWriter::create_with_buffer(&self.path, self.compression, 1 << 20)?;
        if self.packer.is_none() {
            w = w.without_runs();
        }
        self.open_model = Some(Box::new(w));
        Ok(())
    }

    fn end_model_impl(&mut self) -> Result<ModelRef, Error> {
        let mut w = self
            .open_model
            .take()
            .ok_or_else(|| Error::Scene("a model ended that was not begun".into()))?;
        // A model has no camera of its own; its tables need one.
        w.view = Some(View {
            from: [0.0, 0.0, 1.0],
            at: [0.0; 3],
            up: [0.0, 1.0, 0.0],
            angle: 45.0,
            hither: 0.0,
            resolution: [1, 1],
        });
        let (file, summary) = w.complete()?;
        let index = self.models.len() as u32;
        let bbox = summary.bbox;
        self.models.push(ModelPart {
            file,
            bytes: summary.file_bytes,
            bbox,
            spread: 0.0,
        });
        Ok(ModelRef {
            index,
            bbox,
            triangles: summary.counts.0.iter().sum(),
        })
    }

    fn instance_impl(&mut self, model: u32, m: &glam::DAffine3) -> Result<(), Error> {
        if self.open_model.is_some() {
            return Err(Error::Scene(
                "an instance inside a model (models do not nest)".into(),
            ));
        }
        let part = self.models.get(model as usize).ok_or_else(|| {
            Error::Scene(format!(
                "an instance of model {model}, of {}",
                self.models.len()
            ))
        })?;
        if part.bbox.is_empty() {
            // A model of no triangles: nothing to place.
            return Ok(());
        }
        let words = crate::shapes::instance_words(model, &part.bbox, m);
        let shape = Shape::Instance(crate::shapes::Instance { words: &words });
        shape
            .validate()
            .map_err(|e| Error::Scene(format!("instance of model {model}: {e}")))?;
        let placed = shape.bounds();
        let reach = placed
            .min
            .iter()
            .chain(&placed.max)
            .fold(0.0f64, |a, &c| a.max((c as f64).abs()));
        let inv = m.inverse().matrix3;
        let norm = (0..3)
            .map(|r| (0..3).map(|c| inv.col(c)[r].abs()).sum::<f64>())
            .fold(0.0, f64::max);
        let part = &mut self.models[model as usize];
        part.spread = part.spread.max(norm * reach);
        self.object(&shape)
    }
}

impl SceneSink for DbWriter {
    fn begin_model(&mut self) -> Result<(), Error> {
        self.begin_model_impl()
    }

    fn end_model(&mut self) -> Result<ModelRef, Error> {
        self.end_model_impl()
    }

    fn instance(&mut self, model: u32, m: &glam::DAffine3) -> Result<(), Error> {
        self.instance_impl(model, m)
    }

    fn takes_models(&self) -> bool {
        true
    }

    fn background(&mut self, rgb: [f32; 3]) -> Result<(), Error> {
        self.background = rgb;
        Ok(())
    }

    fn view(&mut self, view: &View) -> Result<(), Error> {
        self.view = Some(*view);
        Ok(())
    }

    fn light(&mut self, light: &Light) -> Result<(), Error> {
        if self.lights.len() >= MAX_LIGHTS {
            return Err(Error::Scene(format!("more than {MAX_LIGHTS} lights")));
        }
        self.lights.push(*light);
        Ok(())
    }

    fn texture(&mut self, image: &TextureImage) -> Result<u32, Error> {
        if self.textures.len() >= MAX_IMAGES {
            return Err(Error::Scene(format!("more than {MAX_IMAGES} textures")));
        }
        if !matches!(image.data, ImageData::Encoded(_)) {
            return Err(Error::Scene(format!(
                "{}: a database's tiled image cannot be copied into another",
                image.name
            )));
        }
        self.texture_bytes += image.held_bytes();
        if self.texture_bytes > MAX_IMAGE_BYTES {
            return Err(Error::Scene(format!(
                "the scene's textures take more than {} MiB, the most a database holds",
                MAX_IMAGE_BYTES >> 20
            )));
        }
        self.textures.push(image.clone());
        Ok(self.textures.len() as u32 - 1)
    }

    fn material(&mut self, m: &Material) -> Result<(), Error> {
        // How each image is bound, the world's and the models' materials
        // alike: colours (sRGB) or data (linear values).
        for b in [m.texture, m.maps.emissive].into_iter().flatten() {
            self.colour_images.insert(b.image);
        }
        for b in [m.maps.metallic_roughness, m.maps.normal]
            .into_iter()
            .flatten()
        {
            self.data_images.insert(b.image);
        }
        if let Some(model) = self.open_model.as_mut() {
            return model.material(m);
        }
        self.material_statements += 1;
        let next = self.materials.len() as u32;
        let idx = *self.material_index.entry(m.key()).or_insert(next);
        if idx == next {
            if self.materials.len() >= MAX_MATERIALS {
                return Err(Error::Scene(format!(
                    "more than {MAX_MATERIALS} distinct materials"
                )));
            }
            self.materials.push(*m);
        }
        self.current_material = Some(idx);
        Ok(())
    }

    fn origin(&mut self, origin: [f64; 3]) -> Result<(), Error> {
        if self.objects > 0 {
            return Err(Error::Scene(
                "the scene's origin comes after its first object".into(),
            ));
        }
        if !origin.iter().all(|c| c.is_finite()) {
            return Err(Error::Scene("the scene's origin is not finite".into()));
        }
        self.origin = origin;
        Ok(())
    }

    fn mesh(&mut self, facts: &MeshFacts) -> Result<(), Error> {
        if let Some(model) = self.open_model.as_mut() {
            return model.mesh(facts);
        }
        self.mesh_vertices = Some(self.mesh_vertices.unwrap_or(0) + facts.vertices);
        Ok(())
    }

    fn object(&mut self, shape: &Shape<'_>) -> Result<(), Error> {
        self.object_ranked(shape, None)
    }

    fn ranked_object(&mut self, shape: &Shape<'_>, rank: u32) -> Result<(), Error> {
        self.object_ranked(shape, Some(rank))
    }
}

impl DbWriter {
    /// Writes an object, of input id `rank` if given (kept only in
    /// spatial order), else numbered by its place.
    fn object_ranked(&mut self, shape: &Shape<'_>, rank: Option<u32>) -> Result<(), Error> {
        if let Some(model) = self.open_model.as_mut() {
            let triangle = match shape {
                Shape::Polygon(_) | Shape::Patch(_) => shape.count() == 3,
                Shape::Textured(_) => true,
                _ => false,
            };
            if !triangle {
                return Err(Error::Scene(format!(
                    "a model holds triangles only (a {} with count {} was given)",
                    shape.kind().name(),
                    shape.count()
                )));
            }
            return model.object(shape);
        }
        if self.objects >= u32::MAX as u64 {
            return Err(Error::Scene(format!("more than {} objects", u32::MAX)));
        }
        let material = match self.current_material {
            Some(m) => m,
            None => {
                // Objects before any `f` get the default material.
                self.material(&Material::DEFAULT)?;
                self.material_statements -= 1;
                self.current_material.expect("just set")
            }
        };
        let kind = shape.kind();
        let count = shape.count();
        let words = RECORD_HEADER_WORDS
            + kind
                .payload_words(count)
                .ok_or_else(|| Error::Scene(format!("a {} with count {count}", kind.name())))?;
        let bbox = shape.bounds();
        self.bbox.union(&bbox);
        self.sizes.add(&bbox);
        self.density.add(&bbox);
        let encode = |b: &mut Vec<u32>| {
            b.push(kind as u32 | (count << 8));
            b.push(material);
            b.extend(bbox.to_array().iter().map(|f| f.to_bits()));
            shape.encode(b);
        };
        let id = rank.unwrap_or(self.objects as u32);
        if let Some(sorter) = self.sorter.as_mut() {
            self.scratch.clear();
            encode(&mut self.scratch);
            sorter.push(id, &self.scratch)?;
        } else {
            // In input order the record goes straight to its block.
            if self.block_objects > 0 && (self.block.len() + words) * 4 > BLOCK_TARGET {
                self.flush_block()?;
            }
            encode(&mut self.block);
            self.block_objects += 1;
        }
        let triangles = shape.triangles();
        if triangles > 0 {
            self.triangles += triangles;
            self.listed_vertices += shape.listed_vertices();
        }
        self.counts.add(kind);
        self.objects += 1;
        Ok(())
    }
}

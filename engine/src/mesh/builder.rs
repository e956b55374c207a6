//! A mesh in bounded memory: the tables a reader fills, and the join of
//! faces with vertices that streams the mesh into a scene sink.
//!
//! **Phase 1** (the reader): vertex positions (`f64`, as read), normals
//! and colours, faces (a record each) and their corners (a vertex index
//! each) are appended to tables. Tables live in memory, in chunks charged
//! to the budget; when a chunk does not fit, the face tables go to disk
//! first (they are read in order anyway), then the vertex tables.
//!
//! **Phase 2** ([`MeshBuilder::finish`]): the origin is the world's, or
//! for a model far from it the centre of its bounds ([`choose_origin`]);
//! each corner gets its vertex's position relative to it
//! (in `f32`), normal and colour, and the faces stream out in file order.
//! With the vertex tables in memory that is a lookup per corner. Without,
//! it is an external join: the corners, numbered in file order, are sorted
//! by vertex index ([`ExternalSorter`], runs on disk) and merged with the
//! vertex table read front to back; OBJ's separately indexed normals get a
//! second such join; a last sort by corner number restores file order.
//! Every sort holds at most half the budget.

use super::geometry::{self, Plan};
use crate::error::Error;
use crate::progress::Progress;
use crate::scene::{Material, MeshFacts, SceneSink, TextureImage};
use crate::shapes::{Patch, Polygon, Shape, Textured};
use crate::spill::{ExternalSorter, RecordFile, RecordReader, RecordWriter, SpillDir};
use bytemuck::{Pod, Zeroable};
use std::path::{Path, PathBuf};

/// A corner without a normal index.
pub const NO_INDEX: u64 = u64::MAX;
/// A face without a material of the file's.
pub const NO_MATERIAL: u32 = u32::MAX;

/// The material of faces that a file gives none: light grey, purely
/// diffuse (NFF `f 0.8 0.8 0.8 1 0 0 0 1`).
pub const NEUTRAL: Material = Material {
    pbr: None,
    texture: None,
    maps: crate::scene::Maps::NONE,
    color: [0.8, 0.8, 0.8],
    kd: 1.0,
    ks: 0.0,
    shine: 0.0,
    t: 0.0,
    ior: 1.0,
};

#[derive(Clone, Copy, Debug, Pod, Zeroable)]
#[repr(C)]
struct FaceRec {
    corners: u32,
    material: u32,
    color: [f32; 3],
    flags: u32,
}
const FACE_COLOR: u32 = 1;

#[derive(Clone, Copy, Debug, Pod, Zeroable)]
#[repr(C)]
struct CornerRec {
    v: u64,
    n: u64,
    /// Index in the texture coordinates' table, or [`NO_INDEX`].
    t: u64,
}

/// A corner on its way through the external join.
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
#[repr(C)]
struct Joined {
    /// The corner's number in file order.
    seq: u64,
    v: u64,
    n: u64,
    t: u64,
    pos: [f32; 3],
    normal: [f32; 3],
    color: [f32; 3],
    uv: [f32; 2],
    flags: u32,
}
const HAS_NORMAL: u32 = 1;
const HAS_COLOR: u32 = 2;
const HAS_UV: u32 = 4;

/// A corner of a face, resolved.
#[derive(Clone, Copy, Debug)]
struct Corner {
    pos: [f32; 3],
    normal: Option<[f32; 3]>,
    color: Option<[f32; 3]>,
    uv: Option<[f32; 2]>,
}

/// Records per chunk of a table in memory.
const CHUNK: usize = 4096;

enum Store<T: Pod> {
    Memory(Vec<Vec<T>>),
    File(RecordWriter<T>),
}

/// A table filled in order, in memory chunks or in a spill file.
struct Table<T: Pod> {
    what: &'static str,
    store: Store<T>,
    len: u64,
}

impl<T: Pod> Table<T> {
    fn new(what: &'static str) -> Self {
        Table {
            what,
            store: Store::Memory(Vec::new()),
            len: 0,
        }
    }

    const CHUNK_BYTES: u64 = (CHUNK * std::mem::size_of::<T>()) as u64;

    fn needs_chunk(&self) -> bool {
        matches!(&self.store, Store::Memory(c) if c.last().is_none_or(|l| l.len() == CHUNK))
    }

    fn memory_bytes(&self) -> u64 {
        match &self.store {
            Store::Memory(c) => c.len() as u64 * Self::CHUNK_BYTES,
            Store::File(_) => 0,
        }
    }

    fn push(&mut self, r: T) -> Result<(), Error> {
        match &mut self.store {
            Store::Memory(c) => {
                if c.last().is_none_or(|l| l.len() == CHUNK) {
                    c.push(Vec::with_capacity(CHUNK));
                }
                c.last_mut().expect("just pushed").push(r);
            }
            Store::File(w) => w.push(&r)?,
        }
        self.len += 1;
        Ok(())
    }

    /// Moves the table to a file; returns the memory given back.
    fn spill(&mut self, dir: &SpillDir) -> Result<u64, Error> {
        let freed = self.memory_bytes();
        if let Store::Memory(chunks) = &self.store {
            let mut w = RecordWriter::create(dir, self.what)?;
            for c in chunks {
                w.extend(c)?;
            }
            self.store = Store::File(w);
        }
        Ok(freed)
    }

    fn finish(self) -> Result<Done<T>, Error> {
        Ok(match self.store {
            Store::Memory(c) => Done::Memory(c),
            Store::File(w) => Done::File(w.finish()?),
        })
    }
}

/// A filled table.
enum Done<T: Pod> {
    Memory(Vec<Vec<T>>),
    File(RecordFile<T>),
}

impl<T: Pod> Done<T> {
    fn is_memory(&self) -> bool {
        matches!(self, Done::Memory(_))
    }

    /// Record `i` of a table in memory.
    #[inline]
    fn get(&self, i: u64) -> T {
        match self {
            Done::Memory(c) => c[i as usize / CHUNK][i as usize % CHUNK],
            Done::File(_) => unreachable!("random access to a table on disk"),
        }
    }

    fn reader(&self) -> Result<TableReader<'_, T>, Error> {
        Ok(match self {
            Done::Memory(c) => TableReader::Memory { chunks: c, at: 0 },
            Done::File(f) => TableReader::File(f.reader()?),
        })
    }
}

enum TableReader<'a, T: Pod> {
    Memory { chunks: &'a [Vec<T>], at: usize },
    File(RecordReader<T>),
}

impl<T: Pod> TableReader<'_, T> {
    fn next(&mut self) -> Result<Option<T>, Error> {
        match self {
            TableReader::Memory { chunks, at } => {
                let r = chunks
                    .get(*at / CHUNK)
                    .and_then(|c| c.get(*at % CHUNK))
                    .copied();
                *at += 1;
                Ok(r)
            }
            TableReader::File(r) => r.next(),
        }
    }
}

/// What a mesh held, and what became of its faces.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MeshSummary {
    pub vertices: u64,
    /// Faces as the file lists them (a triangle strip's triangles count
    /// one each).
    pub faces: u64,
    /// Faces skipped: repeated or collinear vertices, no area.
    pub degenerate: u64,
    /// Polygons of more than three corners kept whole.
    pub polygons_kept: u64,
    /// Polygons cut into triangles (not planar, or a non-convex patch).
    pub triangulated: u64,
    /// Objects written.
    pub objects: u64,
    /// Whether the external join ran (the vertices did not fit).
    pub joined_on_disk: bool,
    /// Models stored once (glTF meshes placed more than once), and the
    /// instances placing them.
    pub models: u64,
    pub instances: u64,
    /// glTF primitives of points or lines, skipped.
    pub skipped_primitives: u64,
}

/// Collects a mesh as a reader parses it (phase 1); [`MeshBuilder::finish`]
/// streams it into a sink (phase 2).
pub struct MeshBuilder<'a> {
    name: PathBuf,
    progress: &'a dyn Progress,
    budget: u64,
    used: u64,
    spill_parent: Option<PathBuf>,
    spill: Option<SpillDir>,
    positions: Table<[f64; 3]>,
    normals: Table<[f32; 3]>,
    colors: Table<[f32; 3]>,
    /// Texture coordinates (glTF's convention: v down the image),
    /// indexed by the corners' `t`.
    uvs: Table<[f32; 2]>,
    faces: Table<FaceRec>,
    corners: Table<CornerRec>,
    /// Normals are per vertex, indexed like the positions (PLY, OFF);
    /// else they are a table of their own that corners index (OBJ).
    vertex_normals: bool,
    materials: Vec<Material>,
    /// The images the materials bind, by [`MeshBuilder::add_image`]'s
    /// numbers; sent to the sink first, the bindings renumbered.
    images: Vec<TextureImage>,
    lo: [f64; 3],
    hi: [f64; 3],
    up: Option<[f64; 3]>,
}

/// The least memory a mesh reader works with: below it, the sorts would
/// spill runs of a few records.
pub const MIN_MEMORY: u64 = 256 << 10;

fn spill_dir<'s>(
    spill: &'s mut Option<SpillDir>,
    parent: &Option<PathBuf>,
) -> Result<&'s SpillDir, Error> {
    if spill.is_none() {
        *spill = Some(SpillDir::new(parent.as_deref())?);
    }
    Ok(spill.as_ref().expect("just made"))
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Vertex,
    Face,
}

impl<'a> MeshBuilder<'a> {
    /// A builder holding at most `memory` bytes of tables and sort
    /// buffers, spilling to `spill_parent` (the system's temp directory
    /// if `None`). `vertex_normals`: see the field. (Callers give at least
    /// [`MIN_MEMORY`]; tests give less to force every table to disk.)
    pub fn new(
        name: &Path,
        memory: u64,
        spill_parent: Option<&Path>,
        vertex_normals: bool,
        progress: &'a dyn Progress,
    ) -> Self {
        MeshBuilder {
            name: name.to_path_buf(),
            progress,
            budget: memory,
            used: 0,
            spill_parent: spill_parent.map(Path::to_path_buf),
            spill: None,
            positions: Table::new("mesh-positions"),
            normals: Table::new("mesh-normals"),
            colors: Table::new("mesh-colors"),
            uvs: Table::new("mesh-uvs"),
            faces: Table::new("mesh-faces"),
            corners: Table::new("mesh-corners"),
            vertex_normals,
            materials: Vec::new(),
            images: Vec::new(),
            lo: [f64::INFINITY; 3],
            hi: [f64::NEG_INFINITY; 3],
            up: None,
        }
    }

    pub fn vertex_count(&self) -> u64 {
        self.positions.len
    }

    pub fn normal_count(&self) -> u64 {
        self.normals.len
    }

    /// Records the up direction the file declares (the first one wins).
    pub fn declare_up(&mut self, up: [f64; 3]) {
        self.up.get_or_insert(up);
    }

    /// Makes room for a chunk of `bytes` of a table of `kind`: from the
    /// budget, else by moving the face tables to disk, else (for a vertex
    /// table) the vertex tables too, after which no chunk is needed.
    fn room(&mut self, kind: Kind, bytes: u64) -> Result<(), Error> {
        if self.used + bytes <= self.budget {
            self.used += bytes;
            return Ok(());
        }
        if self.faces.memory_bytes() + self.corners.memory_bytes() > 0 {
            let dir = spill_dir(&mut self.spill, &self.spill_parent)?;
            self.used -= self.faces.spill(dir)?;
            self.used -= self.corners.spill(dir)?;
        }
        if kind == Kind::Face {
            // The face tables are files now; they need no chunk.
            self.faces
                .spill(spill_dir(&mut self.spill, &self.spill_parent)?)?;
            self.corners
                .spill(spill_dir(&mut self.spill, &self.spill_parent)?)?;
            return Ok(());
        }
        if self.used + bytes <= self.budget {
            self.used += bytes;
            return Ok(());
        }
        let dir = spill_dir(&mut self.spill, &self.spill_parent)?;
        self.used -= self.positions.spill(dir)?;
        self.used -= self.normals.spill(dir)?;
        self.used -= self.colors.spill(dir)?;
        self.used -= self.uvs.spill(dir)?;
        Ok(())
    }

    /// Appends a vertex position (already checked: finite, in range).
    pub fn add_vertex(&mut self, p: [f64; 3]) -> Result<(), Error> {
        if self.positions.needs_chunk() {
            self.room(Kind::Vertex, Table::<[f64; 3]>::CHUNK_BYTES)?;
        }
        for i in 0..3 {
            self.lo[i] = self.lo[i].min(p[i]);
            self.hi[i] = self.hi[i].max(p[i]);
        }
        self.positions.push(p)
    }

    /// Appends a normal: of the last vertex (PLY, OFF), or the next of
    /// the normal table (OBJ).
    pub fn add_normal(&mut self, n: [f32; 3]) -> Result<(), Error> {
        if self.normals.needs_chunk() {
            self.room(Kind::Vertex, Table::<[f32; 3]>::CHUNK_BYTES)?;
        }
        self.normals.push(n)
    }

    /// Appends the colour of the last vertex (components 0 to 1).
    pub fn add_color(&mut self, c: [f32; 3]) -> Result<(), Error> {
        if self.colors.needs_chunk() {
            self.room(Kind::Vertex, Table::<[f32; 3]>::CHUNK_BYTES)?;
        }
        self.colors.push(c)
    }

    /// A material faces may refer to by the index returned.
    /// Adds texture coordinates (glTF's convention) that corners name by
    /// their place in the order added ([`MeshBuilder::add_face_uv`]).
    pub fn add_uv(&mut self, uv: [f32; 2]) -> Result<(), Error> {
        if self.uvs.needs_chunk() {
            self.room(Kind::Vertex, Table::<[f32; 2]>::CHUNK_BYTES)?;
        }
        self.uvs.push(uv)
    }

    pub fn uv_count(&self) -> u64 {
        self.uvs.len
    }

    /// Adds an image materials may bind by the number returned
    /// ([`crate::scene::TextureBinding::image`]).
    pub fn add_image(&mut self, image: TextureImage) -> u32 {
        self.images.push(image);
        (self.images.len() - 1) as u32
    }

    pub fn add_material(&mut self, m: Material) -> u32 {
        self.materials.push(m);
        (self.materials.len() - 1) as u32
    }

    /// Appends a face: vertex indices (checked against the vertex count)
    /// and normal indices ([`NO_INDEX`] for none) of its corners, a
    /// material of [`MeshBuilder::add_material`] (or [`NO_MATERIAL`]),
    /// and a colour of its own.
    pub fn add_face(
        &mut self,
        corners: &[(u64, u64)],
        material: u32,
        color: Option<[f32; 3]>,
    ) -> Result<(), Error> {
        self.push_face(
            corners
                .iter()
                .map(|&(v, n)| CornerRec { v, n, t: NO_INDEX }),
            corners.len(),
            material,
            color,
        )
    }

    /// A face whose corners are (vertex, normal, texture coordinates)
    /// indices, either of the last two [`NO_INDEX`].
    pub fn add_face_uv(
        &mut self,
        corners: &[(u64, u64, u64)],
        material: u32,
        color: Option<[f32; 3]>,
    ) -> Result<(), Error> {
        self.push_face(
            corners.iter().map(|&(v, n, t)| CornerRec { v, n, t }),
            corners.len(),
            material,
            color,
        )
    }

    fn push_face(
        &mut self,
        corners: impl Iterator<Item = CornerRec>,
        n: usize,
        material: u32,
        color: Option<[f32; 3]>,
    ) -> Result<(), Error> {
        if self.faces.needs_chunk() {
            self.room(Kind::Face, Table::<FaceRec>::CHUNK_BYTES)?;
        }
        self.faces.push(FaceRec {
            corners: n as u32,
            material,
            color: color.unwrap_or([0.0; 3]),
            flags: if color.is_some() { FACE_COLOR } else { 0 },
        })?;
        for c in corners {
            if self.corners.needs_chunk() {
                self.room(Kind::Face, Table::<CornerRec>::CHUNK_BYTES)?;
            }
            self.corners.push(c)?;
        }
        Ok(())
    }

    /// Streams the mesh into `sink`: its origin, its facts, then a
    /// material statement wherever the material changes and the objects
    /// of its faces, in file order.
    pub fn finish(mut self, sink: &mut dyn SceneSink) -> Result<MeshSummary, Error> {
        let nv = self.positions.len;
        let origin = if nv == 0 {
            [0.0; 3]
        } else {
            choose_origin(self.lo, self.hi)
        };
        let has_normals = if self.vertex_normals {
            self.normals.len == nv && nv > 0
        } else {
            self.normals.len > 0
        };
        let has_colors = self.colors.len == nv && nv > 0;
        let has_uvs = self.uvs.len > 0;
        // The images first, the bindings renumbered as the sink numbers
        // them.
        let mut numbers = Vec::with_capacity(self.images.len());
        for im in std::mem::take(&mut self.images) {
            numbers.push(sink.texture(&im)?);
        }
        for m in &mut self.materials {
            if let Some(t) = m.texture.as_mut() {
                t.image = numbers.get(t.image as usize).copied().unwrap_or(t.image);
            }
        }
        let nfaces = self.faces.len;
        let ncorners = self.corners.len;
        let positions = self.positions.finish()?;
        let normals = self.normals.finish()?;
        let colors = self.colors.finish()?;
        let uvs = self.uvs.finish()?;
        let faces = self.faces.finish()?;
        let corners = self.corners.finish()?;
        let mut em = Emitter {
            materials: std::mem::take(&mut self.materials),
            last: None,
            summary: MeshSummary {
                vertices: nv,
                faces: nfaces,
                ..Default::default()
            },
            pos: Vec::new(),
            nrm: Vec::new(),
            uv: Vec::new(),
            tris: Vec::new(),
            corners: Vec::new(),
        };
        let local =
            |p: [f64; 3]| -> [f32; 3] { std::array::from_fn(|i| (p[i] - origin[i]) as f32) };
        let progress = self.progress;
        let mut bounds = Bounds::default();
        let facts = |bounds: &Bounds| MeshFacts {
            vertices: nv,
            bounds: bounds.get(),
            up: self.up,
        };

        if positions.is_memory() && normals.is_memory() && colors.is_memory() && uvs.is_memory() {
            progress.set_message("resolving faces");
            let mut cr = corners.reader()?;
            while let Some(c) = cr.next()? {
                bounds.add(positions.get(c.v));
            }
            sink.origin(origin)?;
            sink.mesh(&facts(&bounds))?;
            progress.set_unit("faces");
            progress.set_total(nfaces);
            let mut fr = faces.reader()?;
            let mut cr = corners.reader()?;
            let mut done = 0u64;
            while let Some(f) = fr.next()? {
                em.corners.clear();
                for _ in 0..f.corners {
                    let c = cr.next()?.ok_or_else(|| truncated_table(&self.name))?;
                    let normal = if !has_normals {
                        None
                    } else if self.vertex_normals {
                        Some(normals.get(c.v))
                    } else if c.n != NO_INDEX {
                        Some(normals.get(c.n))
                    } else {
                        None
                    };
                    em.corners.push(Corner {
                        pos: local(positions.get(c.v)),
                        normal,
                        color: has_colors.then(|| colors.get(c.v)),
                        uv: (has_uvs && c.t != NO_INDEX).then(|| uvs.get(c.t)),
                    });
                }
                em.face(&f, sink)?;
                done += 1;
                if done.is_multiple_of(1 << 16) {
                    progress.inc(1 << 16);
                }
            }
            progress.inc(done % (1 << 16));
            return Ok(em.summary);
        }

        // The external join.
        em.summary.joined_on_disk = true;
        let dir = spill_dir(&mut self.spill, &self.spill_parent)?.clone();
        // Two sorts are alive at a time (one read, one filled): half the
        // budget each, the radix sort's 24 bytes a record included.
        let cap =
            ((self.budget / 2) / (std::mem::size_of::<Joined>() as u64 + 24)).max(16) as usize;
        type Key = fn(&Joined) -> u64;
        let by_vertex: Key = |j| j.v;
        let by_normal: Key = |j| j.n;
        let by_uv: Key = |j| j.t;
        let by_seq: Key = |j| j.seq;
        let separate_normals = has_normals && !self.vertex_normals;
        // After the vertices: the normals' join, the texture
        // coordinates', then file order.
        let after_normals = if has_uvs { by_uv } else { by_seq };

        // 1. Corners, numbered in file order, sorted by vertex index and
        // merged with the vertex tables read front to back.
        progress.set_unit("corners");
        progress.set_message("sorting corners by vertex");
        progress.set_total(ncorners);
        let mut sorter = ExternalSorter::new(&dir, "mesh-sort", cap, by_vertex);
        {
            let mut cr = corners.reader()?;
            let mut seq = 0u64;
            while let Some(c) = cr.next()? {
                sorter.push(Joined {
                    seq,
                    v: c.v,
                    n: c.n,
                    t: c.t,
                    ..Zeroable::zeroed()
                })?;
                seq += 1;
                if seq.is_multiple_of(1 << 16) {
                    progress.inc(1 << 16);
                }
            }
            progress.inc(seq % (1 << 16));
        }
        progress.set_message("joining corners with vertices");
        progress.set_total(ncorners);
        let mut next = ExternalSorter::new(
            &dir,
            "mesh-sort",
            cap,
            if separate_normals {
                by_normal
            } else {
                after_normals
            },
        );
        {
            let mut sorted = sorter.finish()?;
            let mut pr = positions.reader()?;
            let mut nr = if has_normals && self.vertex_normals {
                Some(normals.reader()?)
            } else {
                None
            };
            let mut kr = if has_colors {
                Some(colors.reader()?)
            } else {
                None
            };
            let mut at = 0u64;
            let mut cur = ([0.0f64; 3], [0.0f32; 3], [0.0f32; 3]);
            let mut done = 0u64;
            while let Some(mut j) = sorted.next()? {
                while at <= j.v {
                    cur.0 = pr.next()?.ok_or_else(|| truncated_table(&self.name))?;
                    if let Some(r) = nr.as_mut() {
                        cur.1 = r.next()?.ok_or_else(|| truncated_table(&self.name))?;
                    }
                    if let Some(r) = kr.as_mut() {
                        cur.2 = r.next()?.ok_or_else(|| truncated_table(&self.name))?;
                    }
                    at += 1;
                }
                bounds.add(cur.0);
                j.pos = local(cur.0);
                if nr.is_some() {
                    j.normal = cur.1;
                    j.flags |= HAS_NORMAL;
                }
                if kr.is_some() {
                    j.color = cur.2;
                    j.flags |= HAS_COLOR;
                }
                next.push(j)?;
                done += 1;
                if done.is_multiple_of(1 << 16) {
                    progress.inc(1 << 16);
                }
            }
            progress.inc(done % (1 << 16));
        }

        // 2. OBJ: sorted by normal index (corners without one last) and
        // merged with the normal table.
        if separate_normals {
            progress.set_message("joining corners with normals");
            let sorted = next.finish()?;
            next = ExternalSorter::new(&dir, "mesh-sort", cap, after_normals);
            join_table(
                sorted,
                &mut next,
                normals.reader()?,
                |j| j.n,
                |j, n| {
                    j.normal = n;
                    j.flags |= HAS_NORMAL;
                },
                (&self.name, progress, ncorners),
            )?;
        }

        // 3. Sorted by texture coordinates' index (corners without one
        // last) and merged with their table.
        if has_uvs {
            progress.set_message("joining corners with texture coordinates");
            let sorted = next.finish()?;
            next = ExternalSorter::new(&dir, "mesh-sort", cap, by_seq);
            join_table(
                sorted,
                &mut next,
                uvs.reader()?,
                |j| j.t,
                |j, uv| {
                    j.uv = uv;
                    j.flags |= HAS_UV;
                },
                (&self.name, progress, ncorners),
            )?;
        }

        // 4. Back into file order, and out.
        sink.origin(origin)?;
        sink.mesh(&facts(&bounds))?;
        progress.set_message("writing faces");
        progress.set_unit("faces");
        progress.set_total(nfaces);
        let mut joined = next.finish()?;
        let mut fr = faces.reader()?;
        let mut done = 0u64;
        while let Some(f) = fr.next()? {
            em.corners.clear();
            for _ in 0..f.corners {
                let j = joined.next()?.ok_or_else(|| truncated_table(&self.name))?;
                em.corners.push(Corner {
                    pos: j.pos,
                    normal: (j.flags & HAS_NORMAL != 0).then_some(j.normal),
                    color: (j.flags & HAS_COLOR != 0).then_some(j.color),
                    uv: (j.flags & HAS_UV != 0).then_some(j.uv),
                });
            }
            em.face(&f, sink)?;
            done += 1;
            if done.is_multiple_of(1 << 16) {
                progress.inc(1 << 16);
            }
        }
        progress.inc(done % (1 << 16));
        Ok(em.summary)
    }
}

/// Merges corners sorted by their index into `table` (`index`; corners
/// without one, [`NO_INDEX`], come last) with the table read front to
/// back, `set` giving each its entry, into `next`; progress counts the
/// `total` corners.
fn join_table<T: Pod + Default>(
    mut sorted: crate::spill::Sorted<Joined, u64, fn(&Joined) -> u64>,
    next: &mut ExternalSorter<Joined, u64, fn(&Joined) -> u64>,
    mut table: TableReader<'_, T>,
    index: impl Fn(&Joined) -> u64,
    set: impl Fn(&mut Joined, T),
    (name, progress, total): (&Path, &dyn Progress, u64),
) -> Result<(), Error> {
    progress.set_total(total);
    let mut at = 0u64;
    let mut cur = T::default();
    let mut done = 0u64;
    while let Some(mut j) = sorted.next()? {
        let i = index(&j);
        if i != NO_INDEX {
            while at <= i {
                cur = table.next()?.ok_or_else(|| truncated_table(name))?;
                at += 1;
            }
            set(&mut j, cur);
        }
        next.push(j)?;
        done += 1;
        if done.is_multiple_of(1 << 16) {
            progress.inc(1 << 16);
        }
    }
    progress.inc(done % (1 << 16));
    Ok(())
}

/// The origin of a mesh whose vertices span `lo..hi`: the world's own
/// when the model is about as large as its distance from it (then `f32`
/// coordinates are as precise relative to the model as they can be), else
/// its centre, rounded to a multiple of the largest power of two below its
/// size. The rounding keeps round coordinates round: a vertex at 0 stays
/// at 0 in world coordinates, exactly.
pub fn choose_origin(lo: [f64; 3], hi: [f64; 3]) -> [f64; 3] {
    let size = (0..3).map(|i| (hi[i] - lo[i]).powi(2)).sum::<f64>().sqrt();
    let far = (0..3)
        .map(|i| lo[i].abs().max(hi[i].abs()))
        .fold(0.0, f64::max);
    let centre: [f64; 3] = std::array::from_fn(|i| lo[i] + (hi[i] - lo[i]) / 2.0);
    if !(far > 2.0 * size) {
        return [0.0; 3];
    }
    if !(size > 0.0) {
        return centre;
    }
    let q = 2f64.powi(size.log2().floor() as i32);
    centre.map(|c| (c / q).round() * q)
}

fn truncated_table(name: &Path) -> Error {
    Error::Scene(format!(
        "{}: internal error: a spilled mesh table ended early",
        name.display()
    ))
}

/// Bounds of points, in `f64`.
#[derive(Clone, Copy)]
struct Bounds {
    lo: [f64; 3],
    hi: [f64; 3],
}

impl Default for Bounds {
    fn default() -> Self {
        Bounds {
            lo: [f64::INFINITY; 3],
            hi: [f64::NEG_INFINITY; 3],
        }
    }
}

impl Bounds {
    #[inline]
    fn add(&mut self, p: [f64; 3]) {
        for i in 0..3 {
            self.lo[i] = self.lo[i].min(p[i]);
            self.hi[i] = self.hi[i].max(p[i]);
        }
    }
    fn get(&self) -> Option<([f64; 3], [f64; 3])> {
        (self.lo[0] <= self.hi[0]).then_some((self.lo, self.hi))
    }
}

/// Turns faces into objects, by the polygon policy.
struct Emitter {
    materials: Vec<Material>,
    last: Option<crate::scene::MaterialKey>,
    summary: MeshSummary,
    pos: Vec<[f32; 3]>,
    nrm: Vec<[f32; 3]>,
    uv: Vec<[f32; 2]>,
    tris: Vec<[usize; 3]>,
    corners: Vec<Corner>,
}

/// A colour rounded to 8 bits per channel, so that averaged vertex
/// colours do not make a material per face.
fn quantize(c: [f32; 3]) -> [f32; 3] {
    c.map(|x| (x.clamp(0.0, 1.0) * 255.0).round() / 255.0)
}

impl Emitter {
    fn material(&self, f: &FaceRec) -> Material {
        if f.flags & FACE_COLOR != 0 {
            return Material {
                pbr: None,
                texture: None,
                maps: crate::scene::Maps::NONE,
                color: quantize(f.color),
                ..NEUTRAL
            };
        }
        if !self.corners.is_empty() && self.corners.iter().all(|c| c.color.is_some()) {
            let mut s = [0.0f32; 3];
            for c in &self.corners {
                let k = c.color.expect("checked");
                for i in 0..3 {
                    s[i] += k[i];
                }
            }
            let n = self.corners.len() as f32;
            return Material {
                pbr: None,
                texture: None,
                maps: crate::scene::Maps::NONE,
                color: quantize(s.map(|x| x / n)),
                ..NEUTRAL
            };
        }
        match self.materials.get(f.material as usize) {
            Some(m) => *m,
            None => NEUTRAL,
        }
    }

    /// A face of a textured material whose every corner has texture
    /// coordinates: its triangles (a polygon triangulated as
    /// [`geometry::triangulate`] does) as textured triangles, smooth if
    /// every corner has a normal.
    fn textured_face(&mut self, f: &FaceRec, sink: &mut dyn SceneSink) -> Result<(), Error> {
        self.pos.clear();
        self.nrm.clear();
        self.uv.clear();
        let smooth = self.corners.iter().all(|c| c.normal.is_some());
        // Repeated corners dropped as `geometry::merge_repeats` drops
        // them: one equal to the next, and the last if equal to the first
        // kept.
        let same = |a: &[f32; 3], b: &[f32; 3]| a.map(f32::to_bits) == b.map(f32::to_bits);
        let n = self.corners.len();
        let mut first: Option<usize> = None;
        for i in 0..n {
            let c = &self.corners[i];
            let dup = if i + 1 < n {
                same(&c.pos, &self.corners[i + 1].pos)
            } else {
                n > 1 && first.is_some_and(|f| same(&c.pos, &self.corners[f].pos))
            };
            if dup {
                continue;
            }
            first.get_or_insert(i);
            self.pos.push(c.pos);
            self.uv.push(c.uv.expect("checked"));
            if smooth {
                self.nrm.push(c.normal.expect("checked"));
            }
        }
        if self.pos.len() < 3 || geometry::plan(&self.pos, smooth) == Plan::Degenerate {
            self.summary.degenerate += 1;
            return Ok(());
        }
        let m = self.material(f);
        if self.last != Some(m.key()) {
            sink.material(&m)?;
            self.last = Some(m.key());
        }
        let mut tris = std::mem::take(&mut self.tris);
        tris.clear();
        if self.pos.len() == 3 {
            tris.push([0, 1, 2]);
        } else {
            self.summary.triangulated += 1;
            geometry::triangulate(&self.pos, &mut tris);
        }
        let mut r = Ok(());
        for &[a, b, c] in &tris {
            let v = [self.pos[a], self.pos[b], self.pos[c]];
            if !geometry::has_area(v[0], v[1], v[2]) {
                continue;
            }
            let uv = [self.uv[a], self.uv[b], self.uv[c]];
            let nrm = if smooth {
                [self.nrm[a], self.nrm[b], self.nrm[c]]
            } else {
                [[0.0; 3]; 3]
            };
            r = self.emit(
                sink,
                &Shape::Textured(Textured {
                    vertices: &v,
                    normals: if smooth { &nrm } else { &[] },
                    uvs: &uv,
                    colors: &[],
                }),
            );
            if r.is_err() {
                break;
            }
        }
        self.tris = tris;
        r
    }

    fn emit(&mut self, sink: &mut dyn SceneSink, shape: &Shape<'_>) -> Result<(), Error> {
        shape
            .validate()
            .map_err(|m| Error::Scene(format!("internal error: a mesh face is invalid: {m}")))?;
        sink.object(shape)?;
        self.summary.objects += 1;
        Ok(())
    }

    fn face(&mut self, f: &FaceRec, sink: &mut dyn SceneSink) -> Result<(), Error> {
        let textured = self
            .materials
            .get(f.material as usize)
            .is_some_and(|m| m.texture.is_some())
            && f.flags & FACE_COLOR == 0
            && self.corners.iter().all(|c| c.uv.is_some());
        if textured {
            return self.textured_face(f, sink);
        }
        self.pos.clear();
        self.nrm.clear();
        let smooth = self.corners.iter().all(|c| c.normal.is_some());
        for c in &self.corners {
            self.pos.push(c.pos);
            if smooth {
                self.nrm.push(c.normal.expect("checked"));
            }
        }
        geometry::merge_repeats(&mut self.pos, smooth.then_some(&mut self.nrm));
        let plan = geometry::plan(&self.pos, smooth);
        if plan == Plan::Degenerate {
            self.summary.degenerate += 1;
            return Ok(());
        }
        let m = self.material(f);
        if self.last != Some(m.key()) {
            sink.material(&m)?;
            self.last = Some(m.key());
        }
        match plan {
            Plan::Degenerate => unreachable!(),
            Plan::Keep { start } => {
                if self.pos.len() > 3 {
                    self.summary.polygons_kept += 1;
                }
                self.pos.rotate_left(start);
                if smooth {
                    self.nrm.rotate_left(start);
                }
                let pos = std::mem::take(&mut self.pos);
                let nrm = std::mem::take(&mut self.nrm);
                let shape = if smooth {
                    Shape::Patch(Patch {
                        vertices: &pos,
                        normals: &nrm,
                    })
                } else {
                    Shape::Polygon(Polygon { vertices: &pos })
                };
                let r = self.emit(sink, &shape);
                self.pos = pos;
                self.nrm = nrm;
                r
            }
            Plan::Triangulate => {
                self.summary.triangulated += 1;
                let mut tris = std::mem::take(&mut self.tris);
                geometry::triangulate(&self.pos, &mut tris);
                let mut r = Ok(());
                for &[a, b, c] in &tris {
                    let (pa, pb, pc) = (self.pos[a], self.pos[b], self.pos[c]);
                    if !geometry::has_area(pa, pb, pc) {
                        continue;
                    }
                    let v = [pa, pb, pc];
                    let shape;
                    let n;
                    if smooth {
                        n = [self.nrm[a], self.nrm[b], self.nrm[c]];
                        shape = Shape::Patch(Patch {
                            vertices: &v,
                            normals: &n,
                        });
                    } else {
                        shape = Shape::Polygon(Polygon { vertices: &v });
                    }
                    r = self.emit(sink, &shape);
                    if r.is_err() {
                        break;
                    }
                }
                self.tris = tris;
                r
            }
        }
    }
}

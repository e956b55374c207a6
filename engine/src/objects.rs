//! Every object of a scene in memory, for the depth-first tracer: meshes
//! as shared corners and small indices, everything else as the database's
//! records.
//!
//! A triangle record is 68 bytes (header, box, three vertices); held that
//! way, with a decoded view and a box per object, the full Stanford dragon
//! took 205 bytes per triangle. Here consecutive triangles of one material
//! (and triangular patches) are gathered as the writer gathers a version 4
//! run ([`RunGather`]), but into runs of up to 65,536 corners: their
//! distinct corners once, then three two-byte indices per face. A face's box is not kept: it is rebuilt from the
//! corners by [`Aabb::of_face`], and a face is gathered only if that box is
//! the one its record holds, so every tracer sees the same numbers, bit for
//! bit, whichever way a database was written (version 3 records are
//! gathered the same way).
//!
//! Objects are found by id through *segments*: stretches of consecutive
//! ids held one way (the faces of one gathered run, or records), looked up
//! through the segment of every 16th id.

use crate::error::Error;
use crate::progress::Progress;
use crate::scene::Aabb;
use crate::sdb::{
    Database, Expand, MAX_RUN_VERTICES, ObjectRef, PackCounts, RECORD_HEADER_WORDS, RunGather,
    StoredRun, decode_record,
};

/// Most corners of a run held in memory: a mesh of up to this many
/// vertices is one run whatever the order of its faces (runs of a file
/// close at 256 corners, so a vertex on a run's edge is stored again;
/// the dragon's 437,645 vertices took 1,024,854 corners that way).
const RUN_CORNERS: usize = 1 << 16;

/// Ids per entry of the segment lookup table.
const GROUP_SHIFT: u32 = 4;

/// How a segment's objects are held.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Form {
    Records,
    Triangles,
    /// Triangular patches: each corner's normal follows its position in
    /// `points`.
    Patches,
}

#[derive(Clone, Copy, Debug)]
struct Segment {
    /// Its first object id; the next segment's first ends it.
    first: u32,
    /// Faces: the index in `points` of the run's first corner. Records:
    /// the record index of the first object.
    base: u32,
    /// Faces' material (records keep their own).
    material: u32,
    form: Form,
}

/// Where object `id` is held.
#[derive(Clone, Copy, Debug)]
pub enum Slot {
    Face(Face),
    /// The index of its record (see [`ObjectStore::record`]).
    Record(u32),
}

/// A face held by its corners.
#[derive(Clone, Copy, Debug)]
pub struct Face {
    pub patch: bool,
    pub material: u32,
    /// Index in `points` of the run's first corner, and of this face's
    /// corners within the run.
    base: u32,
    idx: [u16; 3],
}

pub struct ObjectStore {
    /// In id order, ended by a sentinel segment that starts at `u32::MAX`.
    segments: Vec<Segment>,
    /// The segment holding id `g << GROUP_SHIFT`, for each `g`.
    seg_at: Vec<u32>,
    /// Each object's corner indices within its run (zeros for records).
    corners: Vec<[u16; 3]>,
    /// The runs' distinct corners.
    points: Vec<[f32; 3]>,
    /// The records of the objects not held as faces, concatenated, and
    /// each one's word offset.
    words: Vec<u32>,
    offsets: Vec<u32>,
    /// Each object's input id, when the database is in spatial order
    /// (version 6); empty when ids are positions. Ties go by these.
    ranks: Vec<u32>,
}

impl Face {
    /// The kind of primitive a face is (a triangle, or a triangular
    /// patch: the same intersection test).
    #[inline(always)]
    pub fn kind(&self) -> crate::shapes::ShapeKind {
        if self.patch {
            crate::shapes::ShapeKind::Patch
        } else {
            crate::shapes::ShapeKind::Polygon
        }
    }
}

impl ObjectStore {
    /// Bytes an in-memory copy of `db` takes, about: faces in runs as
    /// six bytes and their runs' corners (at most those of the file's
    /// runs, which close at 256 corners), every other object as its record
    /// (patches' records are larger than the triangles' subtracted here,
    /// their corners twice as large as counted).
    pub fn estimate_bytes(db: &Database) -> u64 {
        let PackCounts {
            runs,
            run_triangles,
        } = db.run_counts();
        let n = db.object_count();
        // A triangle's record (patches are larger: this errs high).
        let face_record = 4 * (RECORD_HEADER_WORDS as u64 + 9);
        let records = db
            .decoded_bytes()
            .saturating_sub(run_triangles * face_record);
        let corners = (runs * MAX_RUN_VERTICES as u64).min(3 * run_triangles);
        let ranks = if db.is_spatial() { 4 * n } else { 0 };
        6 * n + 12 * corners + records + 4 * (n - run_triangles) + ranks
    }

    /// Each object's input id, by position; empty when they are equal.
    #[inline(always)]
    pub fn ranks(&self) -> &[u32] {
        &self.ranks
    }

    pub fn load(db: &Database, progress: &dyn Progress) -> Result<ObjectStore, Error> {
        Self::load_in_runs_of::<RUN_CORNERS>(db, progress)
    }

    /// [`Self::load`], gathering runs of at most `MOST` corners.
    fn load_in_runs_of<const MOST: usize>(
        db: &Database,
        progress: &dyn Progress,
    ) -> Result<ObjectStore, Error> {
        let too_many = |what: &str| {
            Error::Invalid(format!(
                "{}: {what} are too many to hold in memory for the depth-first tracer; use --mode bf",
                db.path().display(),
            ))
        };
        let n = db.object_count();
        if n >= u32::MAX as u64 {
            return Err(too_many(&format!("{n} objects")));
        }
        let mut b = Builder::<MOST> {
            store: ObjectStore {
                segments: Vec::new(),
                seg_at: Vec::new(),
                corners: Vec::with_capacity(n as usize),
                points: Vec::new(),
                words: Vec::new(),
                offsets: Vec::new(),
                ranks: Vec::new(),
            },
            run: RunGather::default(),
            run_first: 0,
            next_id: 0,
            too_many: None,
            scratch: Vec::new(),
        };
        let mut scan = db.scan()?;
        progress.set_total(n);
        // The blocks' triangle runs come as runs, not expanded into
        // records only to be gathered again (which took a third of the
        // dragon's preprocessing).
        loop {
            match scan.next_block_with(&mut b) {
                Ok(Some((_, count))) => {
                    b.store.ranks.extend_from_slice(scan.ids());
                    progress.inc(count as u64);
                }
                Ok(None) => break,
                Err(e) => return Err(b.too_many.take().map_or(e, |what| too_many(&what))),
            }
        }
        b.flush().map_err(|what| too_many(&what))?;
        Ok(b.finish())
    }

    pub fn len(&self) -> usize {
        self.corners.len()
    }

    pub fn is_empty(&self) -> bool {
        self.corners.is_empty()
    }

    /// Where object `id` (below `len()`) is held.
    #[inline(always)]
    pub fn slot(&self, id: u32) -> Slot {
        let mut s = self.seg_at[(id >> GROUP_SHIFT) as usize] as usize;
        // The sentinel starts at u32::MAX, above every id.
        while self.segments[s + 1].first <= id {
            s += 1;
        }
        let seg = self.segments[s];
        match seg.form {
            Form::Records => Slot::Record(seg.base + (id - seg.first)),
            form => Slot::Face(Face {
                patch: form == Form::Patches,
                material: seg.material,
                base: seg.base,
                idx: self.corners[id as usize],
            }),
        }
    }

    /// The positions of a face's corners.
    #[inline(always)]
    pub fn positions(&self, f: &Face) -> [[f32; 3]; 3] {
        let stride = 1 + f.patch as usize;
        f.idx
            .map(|i| self.points[f.base as usize + stride * i as usize])
    }

    /// The normals of a patch's corners.
    pub fn normals(&self, f: &Face) -> [[f32; 3]; 3] {
        debug_assert!(f.patch);
        f.idx
            .map(|i| self.points[f.base as usize + 2 * i as usize + 1])
    }

    /// Record `r` (of [`Slot::Record`]) as object `id`.
    #[inline(always)]
    pub fn record(&self, r: u32, id: u32) -> ObjectRef<'_> {
        decode_record(&self.words[self.offsets[r as usize] as usize..], id)
            .expect("validated record")
            .0
    }

    /// Number of objects held as records.
    pub fn records(&self) -> usize {
        self.offsets.len()
    }

    /// Object `id`'s bounding box, as its record holds it.
    #[inline(always)]
    pub fn bbox(&self, id: u32) -> Aabb {
        match self.slot(id) {
            Slot::Face(f) => Aabb::of_face(&self.positions(&f)),
            Slot::Record(r) => self.record(r, id).bbox,
        }
    }

    /// Gives `f` every object's id and box, in id order.
    #[inline]
    pub fn each_bbox(&self, f: impl FnMut(u32, Aabb)) {
        self.each_bbox_in(0..self.len() as u32, f)
    }

    /// Gives `f` the id and box of each object of `ids`, in id order
    /// (walking the segments rather than looking each id up).
    #[inline]
    pub fn each_bbox_in(&self, ids: std::ops::Range<u32>, mut f: impl FnMut(u32, Aabb)) {
        let end = ids.end.min(self.len() as u32);
        // The segment holding the first id, and those after it.
        let from = self
            .segments
            .partition_point(|s| s.first <= ids.start)
            .saturating_sub(1);
        for (k, seg) in self.segments.iter().enumerate().skip(from) {
            let Some(next) = self.segments.get(k + 1) else {
                break;
            };
            if seg.first >= end {
                break;
            }
            // The sentinel starts at u32::MAX, not at the end.
            for id in seg.first.max(ids.start)..next.first.min(end) {
                let b = match seg.form {
                    Form::Records => {
                        let r = seg.base + (id - seg.first);
                        self.record(r, id).bbox
                    }
                    form => Aabb::of_face(&self.positions(&Face {
                        patch: form == Form::Patches,
                        material: seg.material,
                        base: seg.base,
                        idx: self.corners[id as usize],
                    })),
                };
                f(id, b);
            }
        }
    }

    /// Object `id`'s material.
    pub fn material(&self, id: u32) -> u32 {
        match self.slot(id) {
            Slot::Face(f) => f.material,
            Slot::Record(r) => self.record(r, id).material,
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> u64 {
        (self.segments.len() * size_of::<Segment>()
            + self.seg_at.len() * 4
            + self.corners.len() * 6
            + self.points.len() * 12
            + self.words.len() * 4
            + self.offsets.len() * 4) as u64
    }

    /// Objects held as faces, and their runs' corners.
    pub fn face_counts(&self) -> (u64, u64) {
        (
            (self.len() - self.records()) as u64,
            self.points.len() as u64,
        )
    }
}

/// Gathers objects, in id order, into an [`ObjectStore`].
struct Builder<const MOST: usize> {
    store: ObjectStore,
    run: RunGather<MOST>,
    /// Id of the run's first face.
    run_first: u32,
    /// Id of the next object.
    next_id: u32,
    /// What there were too many of to hold, once the scan was stopped for it.
    too_many: Option<String>,
    /// A textured triangle's record.
    scratch: Vec<u32>,
}

impl<const MOST: usize> Expand for Builder<MOST> {
    fn records(&mut self, words: &[u32], count: u32) -> Result<(), String> {
        let mut pos = 0;
        for _ in 0..count {
            let (_, len) = decode_record(&words[pos..], self.next_id).expect("validated block");
            let r = self.push(&words[pos..pos + len]);
            self.note(r)?;
            pos += len;
        }
        Ok(())
    }

    fn run(&mut self, run: &StoredRun<'_>) -> Result<(), String> {
        if run.textured() {
            // Held as records.
            let mut rec = std::mem::take(&mut self.scratch);
            rec.resize(run.record_words(), 0);
            for t in 0..run.faces() {
                run.write_record(t, &mut rec);
                let r = self.push(&rec);
                self.note(r)?;
            }
            self.scratch = rec;
            return Ok(());
        }
        let mut t = 0;
        while t < run.faces() {
            if self.run.is_empty() {
                self.run_first = self.next_id;
            }
            let mut took = self.run.take_run(run, t);
            if took == 0 {
                let r = self.flush();
                self.note(r)?;
                self.run_first = self.next_id;
                took = self.run.take_run(run, t);
                assert!(
                    took > 0,
                    "an empty gather takes any face but a textured one"
                );
            }
            t += took;
            self.next_id += took as u32;
        }
        Ok(())
    }
}

impl<const MOST: usize> Builder<MOST> {
    /// Keeps what there were too many of, if anything, for `load` to
    /// tell apart from a corrupt block.
    fn note(&mut self, r: Result<(), String>) -> Result<(), String> {
        if let Err(what) = &r {
            self.too_many = Some(what.clone());
        }
        r
    }
}

impl<const MOST: usize> Builder<MOST> {
    /// Adds record `r` as the next object; records what there were too
    /// many of when it does not fit.
    fn push(&mut self, r: &[u32]) -> Result<(), String> {
        let id = self.next_id;
        self.next_id += 1;
        let empty = self.run.is_empty();
        if self.run.take(r, 0) {
            if empty {
                self.run_first = id;
            }
            return Ok(());
        }
        self.flush()?;
        if self.run.take(r, 0) {
            self.run_first = id;
            return Ok(());
        }
        let s = &mut self.store;
        if s.segments.last().is_none_or(|g| g.form != Form::Records) {
            s.segments.push(Segment {
                first: id,
                base: s.offsets.len() as u32,
                material: 0,
                form: Form::Records,
            });
        }
        if s.words.len() + r.len() > u32::MAX as usize {
            return Err(format!("{} words of records", s.words.len() + r.len()));
        }
        s.offsets.push(s.words.len() as u32);
        s.words.extend_from_slice(r);
        s.corners.push([0; 3]);
        Ok(())
    }

    /// Stores the run gathered so far.
    fn flush(&mut self) -> Result<(), String> {
        if self.run.is_empty() {
            return Ok(());
        }
        let s = &mut self.store;
        let patch = self.run.is_patch();
        let at = s.points.len();
        let more = self.run.corners().len() << patch as usize;
        if at + more > u32::MAX as usize {
            return Err(format!("{} corners of triangles", at + more));
        }
        s.segments.push(Segment {
            first: self.run_first,
            base: at as u32,
            material: self.run.material(),
            form: if patch {
                Form::Patches
            } else {
                Form::Triangles
            },
        });
        let f = |b: &[u32]| [b[0], b[1], b[2]].map(f32::from_bits);
        for c in self.run.corners() {
            s.points.push(f(&c[..3]));
            if patch {
                s.points.push(f(&c[3..]));
            }
        }
        s.corners.extend_from_slice(self.run.faces());
        self.run.clear();
        Ok(())
    }

    fn finish(self) -> ObjectStore {
        let mut s = self.store;
        s.segments.push(Segment {
            first: u32::MAX,
            base: 0,
            material: 0,
            form: Form::Records,
        });
        let groups = s.corners.len().div_ceil(1 << GROUP_SHIFT);
        let mut at = 0usize;
        s.seg_at = (0..groups)
            .map(|g| {
                let id = (g << GROUP_SHIFT) as u32;
                while s.segments[at + 1].first <= id {
                    at += 1;
                }
                at as u32
            })
            .collect();
        s.segments.shrink_to_fit();
        s.points.shrink_to_fit();
        s.words.shrink_to_fit();
        s.offsets.shrink_to_fit();
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nff::read_nff_from;
    use crate::progress::NoProgress;
    use crate::sdb::{Compression, DbWriter};
    use crate::shapes::Shape;
    use std::fmt::Write;
    use std::path::Path;

    /// A scene of every way an object can be held: a mesh of shared
    /// corners (runs close at 256 corners) whose material changes, patches,
    /// lone triangles between spheres, many-sided polygons, and triangles
    /// with signed zeros (whose written box may or may not be the one
    /// their corners give).
    fn mixed_scene() -> String {
        let mut s = String::from(
            "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 0.01\nresolution 8 8\n\
             b 0 0 0\nl 1 1 1\n",
        );
        let mut x: u64 = 11;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let corner =
            |i: usize, j: usize| format!("{} {} {}\n", i as f64 * 0.1, j as f64 * 0.1, 0.3);
        for m in 0..3 {
            writeln!(s, "f {} 0.5 0.5 1 0 0 0 1", 0.2 + 0.3 * m as f64).unwrap();
            // A 20 x 20 sheet: 441 corners, more than a run holds.
            for i in 0..20 {
                for j in 0..20 {
                    s += "p 3\n";
                    s += &(corner(i, j) + &corner(i + 1, j) + &corner(i, j + 1));
                    s += "p 3\n";
                    s += &(corner(i + 1, j) + &corner(i + 1, j + 1) + &corner(i, j + 1));
                }
            }
            for _ in 0..30 {
                s += "pp 3\n";
                for _ in 0..3 {
                    writeln!(
                        s,
                        "{} {} {} {} {} 1",
                        next(),
                        next(),
                        next(),
                        next(),
                        next()
                    )
                    .unwrap();
                }
            }
            writeln!(s, "s {} {} {} 0.1", next(), next(), next()).unwrap();
            s += "p 3\n0 0 0\n1 0 0\n0 1 0\n";
            writeln!(s, "s {} {} {} 0.1", next(), next(), next()).unwrap();
            s += "p 5\n0 0 0\n1 0 0\n1 1 0\n0.5 1.5 0\n0 1 0\n";
            s += "p 3\n-0 0 1\n0 -0 1\n1 1 -0\np 3\n0 -0 0\n-0 0 0\n1 1 1\n";
        }
        s
    }

    fn write(dir: &Path, name: &str, runs: bool, c: Compression) -> Database {
        let path = dir.join(name);
        let mut w = DbWriter::create(&path, c).unwrap();
        if !runs {
            w = w.without_runs();
        }
        read_nff_from(
            mixed_scene().as_bytes(),
            Path::new("mixed.nff"),
            &mut w,
            &NoProgress,
        )
        .unwrap();
        w.finish().unwrap();
        Database::open(&path).unwrap()
    }

    /// Every object reads back from the store as its record holds it:
    /// the same corners, normals, material and box, bit for bit, and
    /// records word for word; meshes are held as faces, whichever version
    /// wrote the file.
    #[test]
    fn the_store_gives_back_every_record_bit_for_bit() {
        let dir = tempfile::tempdir().unwrap();
        for (name, runs, c) in [
            ("v4.sdb", true, Compression::None),
            ("v4z.sdb", true, Compression::Zstd(3)),
            ("v3.sdb", false, Compression::None),
        ] {
            let db = write(dir.path(), name, runs, c);
            let store = ObjectStore::load(&db, &NoProgress).unwrap();
            assert_eq!(store.len() as u64, db.object_count());
            let bits = |v: &[[f32; 3]]| v.iter().flatten().map(|c| c.to_bits()).collect::<Vec<_>>();
            let mut scan = db.scan().unwrap();
            let (mut id, mut faces) = (0u32, 0);
            while let Some(b) = scan.next_block().unwrap() {
                for o in b.objects() {
                    assert_eq!(
                        store.bbox(id).to_array().map(f32::to_bits),
                        o.bbox.to_array().map(f32::to_bits),
                        "{name}: box of {id}"
                    );
                    assert_eq!(store.material(id), o.material, "{name}: material of {id}");
                    match store.slot(id) {
                        Slot::Face(f) => {
                            faces += 1;
                            let p = store.positions(&f);
                            match o.shape {
                                Shape::Polygon(r) => {
                                    assert!(!f.patch);
                                    assert_eq!(
                                        bits(&p),
                                        bits(r.vertices),
                                        "{name}: corners of {id}"
                                    );
                                }
                                Shape::Patch(r) => {
                                    assert!(f.patch);
                                    assert_eq!(
                                        bits(&p),
                                        bits(r.vertices),
                                        "{name}: corners of {id}"
                                    );
                                    assert_eq!(
                                        bits(&store.normals(&f)),
                                        bits(r.normals),
                                        "{name}: normals of {id}"
                                    );
                                }
                                other => panic!("{name}: {id} is held as a face but is {other:?}"),
                            }
                        }
                        Slot::Record(r) => {
                            let h = store.record(r, id);
                            assert_eq!(h.shape, o.shape, "{name}: record {id}");
                            assert_eq!(
                                h.bbox.to_array().map(f32::to_bits),
                                o.bbox.to_array().map(f32::to_bits)
                            );
                        }
                    }
                    id += 1;
                }
            }
            let mut walked = 0;
            store.each_bbox(|id, b: Aabb| {
                assert_eq!(id, walked, "{name}: ids in order");
                assert_eq!(
                    b.to_array().map(f32::to_bits),
                    store.bbox(id).to_array().map(f32::to_bits)
                );
                walked += 1;
            });
            assert_eq!(walked as usize, store.len(), "{name}: every object walked");
            // The sheets and patches are faces; the spheres and the
            // five-sided polygons are not.
            assert!(faces >= 3 * (800 + 30), "{name}: {faces} faces");
            assert_eq!(store.records() as u64, db.object_count() - faces as u64);
            // Corners are shared: fewer held than three per face.
            let (f, points) = store.face_counts();
            assert!(points < 2 * f, "{name}: {points} points for {f} faces");
        }
    }

    /// Everything a store holds, comparable.
    #[allow(clippy::type_complexity)]
    fn held(
        s: &ObjectStore,
    ) -> (
        Vec<(u32, u32, u32, Form)>,
        &[u32],
        &[[u16; 3]],
        Vec<[u32; 3]>,
        &[u32],
        &[u32],
        &[u32],
    ) {
        (
            s.segments
                .iter()
                .map(|g| (g.first, g.base, g.material, g.form))
                .collect(),
            &s.seg_at,
            &s.corners,
            s.points.iter().map(|p| p.map(f32::to_bits)).collect(),
            &s.words,
            &s.offsets,
            &s.ranks,
        )
    }

    /// Taking a file's runs whole gathers what taking their records one
    /// by one gathers (from a file written without runs): the same
    /// corners in the same order, the same faces, segments and records,
    /// also where a gather fills in the middle of a stored run (runs of
    /// 3, 7, 300 and 65,536 corners; the sheets' runs hold up to 256).
    #[test]
    fn stored_runs_are_gathered_as_their_records_are() {
        let dir = tempfile::tempdir().unwrap();
        let v4 = write(dir.path(), "v4.sdb", true, Compression::Zstd(3));
        let v3 = write(dir.path(), "v3.sdb", false, Compression::None);
        assert!(v4.run_counts().runs > 0, "the file has runs");
        assert_eq!(v3.run_counts().runs, 0, "the file has none");
        fn both<const MOST: usize>(a: &Database, b: &Database) {
            let x = ObjectStore::load_in_runs_of::<MOST>(a, &NoProgress).unwrap();
            let y = ObjectStore::load_in_runs_of::<MOST>(b, &NoProgress).unwrap();
            assert!(held(&x) == held(&y), "runs of {MOST} corners");
            assert!(x.face_counts().0 > 0, "faces gathered");
        }
        both::<3>(&v4, &v3);
        both::<7>(&v4, &v3);
        both::<300>(&v4, &v3);
        both::<RUN_CORNERS>(&v4, &v3);
    }

    /// The boxes of a stretch of ids are those of the whole walk, wherever
    /// the stretch starts and ends among the segments (runs of 7 corners
    /// make many, records among them).
    #[test]
    fn a_stretch_of_ids_gives_the_boxes_of_the_whole_walk() {
        let dir = tempfile::tempdir().unwrap();
        let db = write(dir.path(), "v4.sdb", true, Compression::None);
        let store = ObjectStore::load_in_runs_of::<7>(&db, &NoProgress).unwrap();
        let mut all = Vec::new();
        store.each_bbox(|id, b| all.push((id, b)));
        let n = store.len() as u32;
        assert_eq!(all.len(), n as usize);
        assert!(
            store.segments.len() > 10,
            "{} segments",
            store.segments.len()
        );
        for (a, b) in [
            (0, n),
            (0, 0),
            (1, 2),
            (5, 17),
            (n / 3, 2 * n / 3),
            (n - 1, n),
            (3, n + 5),
        ] {
            let mut got = Vec::new();
            store.each_bbox_in(a..b, |id, b| got.push((id, b)));
            let want: Vec<_> = all
                .iter()
                .filter(|(id, _)| (a..b).contains(id))
                .copied()
                .collect();
            assert!(got == want, "ids {a}..{b}");
        }
    }

    #[test]
    fn an_empty_database_gives_an_empty_store() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("empty.sdb");
        let mut w = DbWriter::create(&path, Compression::None).unwrap();
        let nff = "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 40\nhither 0.01\nresolution 8 8\n";
        read_nff_from(nff.as_bytes(), Path::new("empty.nff"), &mut w, &NoProgress).unwrap();
        w.finish().unwrap();
        let store = ObjectStore::load(&Database::open(&path).unwrap(), &NoProgress).unwrap();
        assert!(store.is_empty());
    }
}

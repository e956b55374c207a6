//! Triangle runs: how version 4 stores a mesh without repeating what its
//! records can imply.
//!
//! A block is still built as records (see the module documentation of
//! [`super`]), but before it is stored every stretch of consecutive
//! triangles of one material, of triangular patches (a normal per
//! vertex), or of textured triangles carrying the same attributes (version
//! 8), becomes a *run*, as GPU meshlets are:
//!
//! ```text
//! word 0   RUN (triangles), RUN_PATCH or RUN_TEXTURED + mask | faces << 8
//! word 1   material
//! word 2   corners (1..=256): distinct vertices, with their normals
//! word 3   bit widths of x | y << 8 | z << 16 (patches: one more word,
//!          the normals' widths; textured triangles: three more, for
//!          normals, texture coordinates and colours, each 0 where the
//!          mask has none)
//! ...      base keys: x, y, z (patches: and the normal's three; textured
//!          triangles: and the normal's, the coordinates' and the colour
//!          words')
//! ...      the corners, each number as (key - base) in its width,
//!          packed low bit first into words
//! ...      three one-byte corner indices per face, padded to a word
//! ```
//!
//! A coordinate's *key* is its bit pattern mapped so that integer order is
//! the order of the numbers ([`key`]); within a run the keys of an axis
//! span few values, so a vertex takes some 60 bits instead of 96. Nothing
//! is rounded: reading a block expands each run back into exactly the
//! records it came from, bounding boxes recomputed as the writer computed
//! them, so every tracer sees the same words, bit for bit, as from a
//! version 3 file. A face whose stored box is not the one its vertices
//! imply, and a lone face, stay records.

use crate::scene::Aabb;
use crate::shapes::ShapeKind;

/// The codes in a run's first word where a record has its kind; no kind
/// has them.
pub const RUN: u32 = 0xff;
pub const RUN_PATCH: u32 = 0xfe;
/// Textured triangles: this plus their count field's mask (1 to 7).
pub const RUN_TEXTURED: u32 = 0xf0;
const _: () = assert!(crate::shapes::KINDS < RUN_TEXTURED as usize);
/// Numbers a corner may have: position, normal, texture coordinates and
/// the two words of a colour.
const CORNER_NUMBERS: usize = 10;
/// Corner indices are one byte.
pub const MAX_RUN_VERTICES: usize = 256;
const RECORD_HEADER_WORDS: usize = super::format::RECORD_HEADER_WORDS;

/// The faces a run holds: records of three vertices, with or without a
/// normal per vertex.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Face {
    Triangle,
    Patch,
    /// A textured triangle, with its count field's mask
    /// ([`crate::shapes::Textured`]).
    Textured(u32),
}

impl Face {
    fn of_head(head: u32) -> Option<Face> {
        if head == ShapeKind::Polygon as u32 | 3 << 8 {
            Some(Face::Triangle)
        } else if head == ShapeKind::Patch as u32 | 3 << 8 {
            Some(Face::Patch)
        } else if head & 0xff == ShapeKind::Textured as u32 && (1..8).contains(&(head >> 8)) {
            Some(Face::Textured(head >> 8))
        } else {
            None
        }
    }

    fn of_code(code: u32) -> Option<Face> {
        match code {
            RUN => Some(Face::Triangle),
            RUN_PATCH => Some(Face::Patch),
            c if (RUN_TEXTURED + 1..RUN_TEXTURED + 8).contains(&c) => {
                Some(Face::Textured(c - RUN_TEXTURED))
            }
            _ => None,
        }
    }

    fn code(self) -> u32 {
        match self {
            Face::Triangle => RUN,
            Face::Patch => RUN_PATCH,
            Face::Textured(mask) => RUN_TEXTURED + mask,
        }
    }

    /// The first word of the face's record.
    fn head(self) -> u32 {
        match self {
            Face::Triangle => ShapeKind::Polygon as u32 | 3 << 8,
            Face::Patch => ShapeKind::Patch as u32 | 3 << 8,
            Face::Textured(mask) => ShapeKind::Textured as u32 | mask << 8,
        }
    }

    /// Numbers per corner: a position, a normal for a patch; all ten for
    /// a textured triangle (those its mask leaves out are zeros, which
    /// take no bits).
    fn numbers(self) -> usize {
        match self {
            Face::Triangle => 3,
            Face::Patch => 6,
            Face::Textured(_) => CORNER_NUMBERS,
        }
    }

    /// Words of the face's record.
    fn record_words(self) -> usize {
        match self {
            Face::Textured(mask) => {
                RECORD_HEADER_WORDS
                    + ShapeKind::Textured
                        .payload_words(mask)
                        .expect("a mask of 1 to 7")
            }
            _ => RECORD_HEADER_WORDS + 3 * self.numbers(),
        }
    }

    /// Words before a run's corners: code and count, material, corners,
    /// widths (a word per three numbers), base keys.
    fn run_header_words(self) -> usize {
        3 + self.numbers().div_ceil(3) + self.numbers()
    }

    /// Where each part of a corner lies in the face's record geometry, as
    /// (first number of the corner, numbers, first word of the part in
    /// the geometry): positions, then what the face has of normals,
    /// texture coordinates and colours.
    fn parts(self) -> impl Iterator<Item = (usize, usize, usize)> {
        let mask = match self {
            Face::Triangle => 0,
            Face::Patch => crate::shapes::NORMALS,
            Face::Textured(mask) => mask,
        };
        let all = [
            (0, 3, true),
            (3, 3, mask & crate::shapes::NORMALS != 0),
            (6, 2, mask & crate::shapes::UVS != 0),
            (8, 2, mask & crate::shapes::COLORS != 0),
        ];
        let mut at = 0;
        all.into_iter().filter(|p| p.2).map(move |(first, n, _)| {
            let part = (first, n, at);
            at += 3 * n;
            part
        })
    }
}

/// A corner's numbers as bits: position, normal, texture coordinates,
/// colour words (zeros for what a face does not have).
type Corner = [u32; CORNER_NUMBERS];

/// The order-preserving integer of a finite `f32`'s bits (negative
/// numbers reversed below the positive ones).
#[inline]
pub(crate) fn key(bits: u32) -> u32 {
    if bits >> 31 == 0 {
        bits | 0x8000_0000
    } else {
        !bits
    }
}

#[inline]
fn unkey(k: u32) -> u32 {
    if k >> 31 == 1 { k & 0x7fff_ffff } else { !k }
}

/// The box of a face's positions (normals aside), as bits in a record's
/// order (least x, y, z, then greatest), as a reader rebuilds it: by plain
/// comparisons, whose result is the same on every machine (`f32::min`
/// leaves open which of +0 and -0 it returns). A writer packs a face only
/// if this is the box its record holds, so the reader gives back that
/// record's very bits.
#[inline(always)]
fn face_box(c: [&Corner; 3]) -> [u32; 6] {
    let v = c.map(|p| [p[0], p[1], p[2]].map(f32::from_bits));
    Aabb::of_face(&v).to_array().map(f32::to_bits)
}

/// The record of a face of `material` with corners `c`.
#[inline]
#[cfg(test)]
fn push_record(out: &mut Vec<u32>, face: Face, material: u32, c: &[Corner; 3]) {
    let at = out.len();
    out.resize(at + face.record_words(), 0);
    write_record(&mut out[at..], face, material, [&c[0], &c[1], &c[2]]);
}

/// Writes the record of a face of `material` with corners `c` into `rec`
/// (exactly the record's length). The corners are read where they are,
/// not copied first: see `unpack`.
#[inline(always)]
fn write_record(rec: &mut [u32], face: Face, material: u32, c: [&Corner; 3]) {
    rec[0] = face.head();
    rec[1] = material;
    rec[2..RECORD_HEADER_WORDS].copy_from_slice(&face_box(c));
    let g = &mut rec[RECORD_HEADER_WORDS..];
    if face == Face::Triangle {
        // Positions only, in copies of a known length: the general loop's
        // copies of a length known only at run time were library calls,
        // nine a triangle (a fifth of an out-of-core render of mount11).
        for (i, p) in c.iter().enumerate() {
            let v: &mut [u32; 3] = (&mut g[3 * i..3 * i + 3]).try_into().expect("a corner");
            *v = [p[0], p[1], p[2]];
        }
        return;
    }
    for (first, n, at) in face.parts() {
        for (i, p) in c.iter().enumerate() {
            g[at + n * i..at + n * (i + 1)].copy_from_slice(&p[first..first + n]);
        }
    }
}

/// The corners of the face whose record geometry is `g`.
#[inline(always)]
fn read_corners(face: Face, g: &[u32]) -> [Corner; 3] {
    let mut corners = [[0u32; CORNER_NUMBERS]; 3];
    for (first, n, at) in face.parts() {
        for (i, c) in corners.iter_mut().enumerate() {
            c[first..first + n].copy_from_slice(&g[at + n * i..at + n * (i + 1)]);
        }
    }
    corners
}

/// Appends bits to words, low bit first.
struct BitWriter<'a> {
    out: &'a mut Vec<u32>,
    acc: u64,
    bits: u32,
}

impl BitWriter<'_> {
    fn put(&mut self, value: u32, width: u32) {
        if width == 0 {
            return;
        }
        self.acc |= (value as u64) << self.bits;
        self.bits += width;
        if self.bits >= 32 {
            self.out.push(self.acc as u32);
            self.acc >>= 32;
            self.bits -= 32;
        }
    }

    fn finish(self) {
        if self.bits > 0 {
            self.out.push(self.acc as u32);
        }
    }
}

/// Reads bits from words, low bit first; the caller has checked that
/// the words hold every bit it asks for.
struct BitReader<'a> {
    words: &'a [u32],
    next: usize,
    acc: u64,
    bits: u32,
}

impl BitReader<'_> {
    #[inline]
    fn get(&mut self, width: u32) -> u32 {
        if width == 0 {
            return 0;
        }
        if self.bits < width {
            self.acc |= (self.words[self.next] as u64) << self.bits;
            self.next += 1;
            self.bits += 32;
        }
        let v = (self.acc & ((1u64 << width) - 1)) as u32;
        self.acc >>= width;
        self.bits -= width;
        v
    }
}

/// Decodes a run's corners from `words`: corner after corner, each number
/// `a` an offset of `width[a]` bits from `base[a]`, packed low bit first
/// (as [`BitWriter`] writes them). Each number is read from its own place
/// rather than by a reader that keeps its position: that reader's position
/// is a chain of dependent steps through every number of the run, where
/// separate reads run side by side (on mount11, the chain was the largest
/// part of `unpack`'s samples once the corners' copy below was gone).
#[inline(always)]
fn decode_corners(words: &[u32], corners: &mut [Corner], base: &[u32], width: &[u32]) {
    let mut first = [0u32; CORNER_NUMBERS];
    let mut mask = [0u64; CORNER_NUMBERS];
    let mut stride = 0u32;
    for (a, &w) in width.iter().enumerate() {
        first[a] = stride;
        mask[a] = (1u64 << w) - 1;
        stride += w;
    }
    let word = |j: usize| words.get(j).copied().unwrap_or(0) as u64;
    for (i, c) in corners.iter_mut().enumerate() {
        let at = i as u64 * stride as u64;
        for a in 0..base.len() {
            let bit = at + first[a] as u64;
            let j = (bit / 32) as usize;
            let pair = word(j) | word(j + 1) << 32;
            let v = (pair >> (bit % 32)) & mask[a];
            c[a] = unkey(base[a].wrapping_add(v as u32));
        }
    }
}

/// Stores the input ids of a block's objects (version 6, objects in
/// spatial order) at the front of its payload: the smallest id, the bit
/// width of the offsets from it, then each object's offset in that width,
/// packed low bit first.
pub fn pack_ids(ids: &[u32], out: &mut Vec<u32>) {
    let lo = ids.iter().copied().min().unwrap_or(0);
    let hi = ids.iter().copied().max().unwrap_or(0);
    let width = 32 - (hi - lo).leading_zeros();
    out.push(lo);
    out.push(width);
    let mut w = BitWriter {
        out,
        acc: 0,
        bits: 0,
    };
    for &id in ids {
        w.put(id - lo, width);
    }
    w.finish();
}

/// Reads the ids [`pack_ids`] stored for `objects` objects into `out`;
/// returns the words they took. Each id must be below `limit` (the
/// database's object count). Nothing in `packed` can make it panic.
pub fn unpack_ids(
    packed: &[u32],
    objects: u32,
    limit: u64,
    out: &mut Vec<u32>,
) -> Result<usize, String> {
    out.clear();
    let (&lo, &width) = match packed {
        [lo, width, ..] => (lo, width),
        _ => return Err("the block's object ids are cut off".into()),
    };
    if width > 32 {
        return Err(format!(
            "the block's object ids have a width of {width} bits"
        ));
    }
    let words = (objects as u64 * width as u64).div_ceil(32) as usize;
    let body = packed
        .get(2..2 + words)
        .ok_or("the block's object ids are cut off")?;
    let mut r = BitReader {
        words: body,
        next: 0,
        acc: 0,
        bits: 0,
    };
    out.reserve(objects as usize);
    for _ in 0..objects {
        let id = lo as u64 + r.get(width) as u64;
        if id >= limit {
            return Err(format!(
                "an object id of {id} in a database of {limit} objects"
            ));
        }
        out.push(id as u32);
    }
    Ok(2 + words)
}

/// What packing a block did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PackCounts {
    pub runs: u64,
    pub run_triangles: u64,
}

/// Where each distinct corner of the run being gathered is: open
/// addressing over a table four times the largest run, emptied by a new
/// stamp rather than by clearing it (a writer looks up three corners per
/// triangle, a billion triangles for tetra 15).
struct CornerIndex {
    stamp: u32,
    /// Stamp and corner index of each slot (a power of two of them); a
    /// slot of an older stamp is empty.
    slots: Box<[(u32, u16)]>,
}

/// A corner's hash: its numbers in pairs, each pair multiplied by a
/// constant of its own and the products mixed once. (Multiplied in turn,
/// a chain of ten products, finding corners was an eighth of a dragon
/// render's samples; which slot a corner takes changes no output, the
/// runs' corners being numbered in the order they come.)
#[inline(always)]
fn corner_hash(c: &Corner) -> u64 {
    const K: [u64; CORNER_NUMBERS / 2] = [
        0x9e37_79b9_7f4a_7c15,
        0xc2b2_ae3d_27d4_eb4f,
        0x1656_67b1_9e37_79f9,
        0x85eb_ca77_c2b2_ae63,
        0x27d4_eb2f_1656_67c5,
    ];
    let h = (0..CORNER_NUMBERS / 2).fold(0u64, |h, p| {
        h ^ (c[2 * p] as u64 | (c[2 * p + 1] as u64) << 32).wrapping_mul(K[p])
    });
    (h ^ h >> 29).wrapping_mul(0x517c_c1b7_2722_0a95)
}

/// Whether two corners are the same bits, compared word by word together
/// (an array's `==` here was a library call per comparison).
#[inline(always)]
fn same_corner(a: &Corner, b: &Corner) -> bool {
    a.iter().zip(b).fold(0, |d, (x, y)| d | (x ^ y)) == 0
}

/// Slots an index starts with: four per corner of a written run.
const FIRST_SLOTS: usize = 4 * MAX_RUN_VERTICES;

impl CornerIndex {
    fn new() -> CornerIndex {
        CornerIndex {
            stamp: 1,
            slots: vec![(0, 0); FIRST_SLOTS].into_boxed_slice(),
        }
    }

    /// Makes room for `more` corners beyond `corners` (keeping at most a
    /// quarter of the slots full), doubling the table as a large run
    /// grows: a scene of a few triangles does not pay for the table of a
    /// run of 65,536 corners.
    fn reserve(&mut self, corners: &[Corner], more: usize) {
        if 4 * (corners.len() + more) <= self.slots.len() {
            return;
        }
        let size = (4 * (corners.len() + more)).next_power_of_two();
        self.slots = vec![(0, 0); size].into_boxed_slice();
        self.stamp = 1;
        for (i, c) in corners.iter().enumerate() {
            let slot = self
                .find(&corners[..i], c)
                .expect_err("corners are distinct");
            self.insert(slot, i as u16);
        }
    }

    fn clear(&mut self) {
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.slots.fill((0, 0));
            self.stamp = 1;
        }
    }

    /// The index of `c` among `corners`, or the empty slot where it goes.
    #[inline]
    fn find(&self, corners: &[Corner], c: &Corner) -> Result<u16, usize> {
        let mask = self.slots.len() - 1;
        let mut slot = (corner_hash(c) >> 32) as usize & mask;
        // At most a quarter of the slots are full: the probe ends.
        loop {
            let (stamp, i) = self.slots[slot];
            if stamp != self.stamp {
                return Err(slot);
            }
            if same_corner(&corners[i as usize], c) {
                return Ok(i);
            }
            slot = (slot + 1) & mask;
        }
    }

    fn insert(&mut self, slot: usize, i: u16) {
        self.slots[slot] = (self.stamp, i);
    }
}

/// Consecutive faces of one kind and material gathered with their
/// distinct corners (at most `MOST`, at most 65,536): what a writer stores
/// as a run (of at most [`MAX_RUN_VERTICES`]), and what the depth-first
/// tracer holds in memory for a mesh (larger runs).
pub struct RunGather<const MOST: usize> {
    /// The faces' kind, material and first record's word offset (none
    /// while the run is empty).
    face: Option<Face>,
    material: u32,
    first: usize,
    corners: Vec<Corner>,
    local: CornerIndex,
    faces: Vec<[u16; 3]>,
    /// Whether textured triangles are gathered too (a writer's runs; the
    /// depth-first tracer holds them as records).
    textured: bool,
    /// For each corner of the stored run being taken ([`Self::take_run`]),
    /// its index among `corners` if `stamp` is `stored_stamp`: a stored
    /// corner is looked up once, not once per face that names it.
    stored: Box<[(u32, u16); MAX_RUN_VERTICES]>,
    stored_stamp: u32,
}

impl<const MOST: usize> Default for RunGather<MOST> {
    fn default() -> Self {
        const { assert!(MOST <= 1 << 16, "corner indices are 16 bits") };
        RunGather {
            face: None,
            material: 0,
            first: 0,
            corners: Vec::new(),
            local: CornerIndex::new(),
            faces: Vec::new(),
            textured: false,
            stored: Box::new([(0, 0); MAX_RUN_VERTICES]),
            stored_stamp: 1,
        }
    }
}

impl<const MOST: usize> RunGather<MOST> {
    pub fn clear(&mut self) {
        self.face = None;
        self.corners.clear();
        self.local.clear();
        self.faces.clear();
        self.forget_stored();
    }

    /// Forgets where the corners of a stored run are among `corners`.
    fn forget_stored(&mut self) {
        self.stored_stamp = self.stored_stamp.wrapping_add(1);
        if self.stored_stamp == 0 {
            self.stored.fill((0, 0));
            self.stored_stamp = 1;
        }
    }

    pub fn is_empty(&self) -> bool {
        self.face.is_none()
    }

    /// Whether the run's faces are patches (a normal per corner).
    pub fn is_patch(&self) -> bool {
        self.face == Some(Face::Patch)
    }

    pub fn material(&self) -> u32 {
        self.material
    }

    /// The distinct corners as bits: position, then normal (zeros for a
    /// triangle), then (zeros) what only textured triangles have.
    pub fn corners(&self) -> &[[u32; CORNER_NUMBERS]] {
        &self.corners
    }

    /// Each face's three indices into [`Self::corners`].
    pub fn faces(&self) -> &[[u16; 3]] {
        &self.faces
    }

    /// Adds the record `r` (at word `pos` of its block) to the run if it is
    /// a face whose box is the one its vertices imply, of the run's kind
    /// and material, and its new corners fit; `false` leaves the run as it
    /// was.
    pub fn take(&mut self, r: &[u32], pos: usize) -> bool {
        let Some(face) = Face::of_head(r[0]) else {
            return false;
        };
        if matches!(face, Face::Textured(_)) && !self.textured {
            return false;
        }
        let corners = read_corners(face, &r[RECORD_HEADER_WORDS..]);
        if face_box([&corners[0], &corners[1], &corners[2]])[..] != r[2..RECORD_HEADER_WORDS] {
            return false;
        }
        if self.face.is_some_and(|f| f != face) || (self.face.is_some() && r[1] != self.material) {
            return false;
        }
        let c = [&corners[0], &corners[1], &corners[2]];
        let found = [0, 1, 2].map(|i| self.local.find(&self.corners, c[i]));
        self.add_face(face, r[1], pos, c, found).is_some()
    }

    /// Adds a face of kind `face` and `material` (the run's, if it has
    /// faces) whose corners `c` were looked up among `corners` as `found`,
    /// if its new corners fit: its three indices. `first` is the word
    /// offset of its record, kept if it is the run's first face.
    // Always inlined: called for each of a mesh's faces, and its caller's
    // lookups are what it branches on (a call cost the dragon's load 8 %
    // more instructions).
    #[inline(always)]
    fn add_face(
        &mut self,
        face: Face,
        material: u32,
        first: usize,
        c: [&Corner; 3],
        found: [Result<u16, usize>; 3],
    ) -> Option<[u16; 3]> {
        // A corner not found is new, once however many of the face's
        // corners have its bits.
        let mut new = 0;
        for i in 0..3 {
            if found[i].is_err() && !(0..i).any(|j| same_corner(c[j], c[i])) {
                new += 1;
            }
        }
        if self.corners.len() + new > MOST {
            return None;
        }
        self.local.reserve(&self.corners, new);
        if self.face.is_none() {
            self.face = Some(face);
            self.material = material;
            self.first = first;
        }
        // A new corner is looked up again when it goes in: an earlier
        // corner of the face may have taken its slot.
        let mut idx = [0u16; 3];
        for i in 0..3 {
            idx[i] = match found[i] {
                Ok(k) => k,
                Err(_) => match self.local.find(&self.corners, c[i]) {
                    Ok(k) => k,
                    Err(slot) => {
                        let k = self.corners.len() as u16;
                        self.local.insert(slot, k);
                        self.corners.push(*c[i]);
                        k
                    }
                },
            };
        }
        self.faces.push(idx);
        Some(idx)
    }

    /// Adds the faces of the stored run `run` from face `from` on, as
    /// [`Self::take`] would add their records one by one (the same corners
    /// in the same order, the same indices), until one does not fit: the
    /// number of faces taken. A run of textured triangles is taken only
    /// if they are gathered ([`Self::take`]'s rule). `from` is 0 for a new
    /// stored run, else where the last call for the same run stopped.
    ///
    /// What `take` does per face, three lookups in a table of up to
    /// 65,536 corners, is done here once per stored corner (at most 256,
    /// for some 500 faces); each face's box needs no check, a run's faces
    /// having the boxes their corners imply by construction.
    pub fn take_run(&mut self, run: &StoredRun<'_>, from: usize) -> usize {
        if from == 0 {
            self.forget_stored();
        }
        let face = run.face;
        if (matches!(face, Face::Textured(_)) && !self.textured)
            || self.face.is_some_and(|f| f != face)
            || (self.face.is_some() && run.material != self.material)
        {
            return 0;
        }
        let mut taken = 0;
        for t in run.index[3 * from..].chunks_exact(3) {
            let t = [t[0] as usize, t[1] as usize, t[2] as usize];
            let c = [&run.corners[t[0]], &run.corners[t[1]], &run.corners[t[2]]];
            let look = |i: usize| match self.stored[t[i]] {
                (stamp, k) if stamp == self.stored_stamp => Ok(k),
                _ => self.local.find(&self.corners, c[i]),
            };
            let found = [look(0), look(1), look(2)];
            let Some(idx) = self.add_face(face, run.material, 0, c, found) else {
                break;
            };
            for i in 0..3 {
                self.stored[t[i]] = (self.stored_stamp, idx[i]);
            }
            taken += 1;
        }
        taken
    }
}

/// Builds runs from a block's records; reused across blocks.
pub struct Packer {
    run: RunGather<MAX_RUN_VERTICES>,
    pub counts: PackCounts,
}

impl Default for Packer {
    fn default() -> Self {
        Packer {
            run: RunGather {
                textured: true,
                ..Default::default()
            },
            counts: PackCounts::default(),
        }
    }
}

impl Packer {
    /// Stores the block whose records are `records` (as a writer built
    /// them) into `out`, with runs for its triangles and patches.
    pub fn pack(&mut self, records: &[u32], out: &mut Vec<u32>) {
        out.clear();
        self.run.clear();
        let mut pos = 0;
        while pos < records.len() {
            let head = records[pos];
            let kind = ShapeKind::from_u8((head & 0xff) as u8).expect("a record the writer built");
            let len = RECORD_HEADER_WORDS
                + kind
                    .payload_words(head >> 8)
                    .expect("a record the writer built");
            let r = &records[pos..pos + len];
            if !self.run.take(r, pos) {
                self.close(records, out);
                if !self.run.take(r, pos) {
                    out.extend_from_slice(r);
                }
            }
            pos += len;
        }
        self.close(records, out);
    }

    /// Writes the run gathered so far (a lone face as its record).
    fn close(&mut self, records: &[u32], out: &mut Vec<u32>) {
        let Some(face) = self.run.face else {
            return;
        };
        let n = self.run.faces.len();
        if n == 1 {
            out.extend_from_slice(&records[self.run.first..self.run.first + face.record_words()]);
        } else {
            let numbers = face.numbers();
            let mut lo = [u32::MAX; CORNER_NUMBERS];
            let mut hi = [0u32; CORNER_NUMBERS];
            for c in &self.run.corners {
                for a in 0..numbers {
                    lo[a] = lo[a].min(key(c[a]));
                    hi[a] = hi[a].max(key(c[a]));
                }
            }
            // Numbers a face does not have (a triangle's normal) take none.
            let width: [u32; CORNER_NUMBERS] = std::array::from_fn(|a| {
                if a < numbers {
                    32 - (hi[a] - lo[a]).leading_zeros()
                } else {
                    0
                }
            });
            out.push(face.code() | (n as u32) << 8);
            out.push(self.run.material);
            out.push(self.run.corners.len() as u32);
            for w in width[..numbers].chunks(3) {
                let w = |i: usize| w.get(i).copied().unwrap_or(0);
                out.push(w(0) | w(1) << 8 | w(2) << 16);
            }
            out.extend_from_slice(&lo[..numbers]);
            let mut w = BitWriter {
                out,
                acc: 0,
                bits: 0,
            };
            for c in &self.run.corners {
                for a in 0..numbers {
                    w.put(key(c[a]) - lo[a], width[a]);
                }
            }
            w.finish();
            for quad in self.run.faces.as_flattened().chunks(4) {
                let mut b = [0u8; 4];
                for (b, &i) in b.iter_mut().zip(quad) {
                    // A run of at most 256 corners: indices are a byte.
                    *b = i as u8;
                }
                out.push(u32::from_le_bytes(b));
            }
            self.counts.runs += 1;
            self.counts.run_triangles += n as u64;
        }
        self.run.clear();
    }
}

/// Whether a stored block (`packed`, past its ids) holds only records
/// stored as they are, `objects` of them in at most `max_words`: then it
/// is its own expansion, and [`unpack`] would only copy it (mount's
/// blocks: a copy of every block read was 5 % of an out-of-core render).
/// `false` for anything else, runs or a corrupt block, which [`unpack`]
/// expands or describes.
pub fn is_plain(packed: &[u32], objects: u32, max_words: usize) -> bool {
    if packed.len() > max_words {
        return false;
    }
    let (mut pos, mut seen) = (0usize, 0u64);
    while pos < packed.len() {
        let head = packed[pos];
        if Face::of_code(head & 0xff).is_some() {
            return false;
        }
        let Some(len) = ShapeKind::from_u8((head & 0xff) as u8)
            .and_then(|k| k.payload_words(head >> 8))
            .map(|p| p + RECORD_HEADER_WORDS)
        else {
            return false;
        };
        pos += len;
        seen += 1;
    }
    pos == packed.len() && seen == objects as u64
}

/// A run of a stored block as [`expand`] reads it: its faces' kind and
/// material, its distinct corners (their numbers the faces do not have
/// are zeros, as [`RunGather`] holds them), and three indices into them
/// per face (each checked to name one of the corners).
pub struct StoredRun<'a> {
    face: Face,
    material: u32,
    corners: &'a [Corner],
    index: &'a [u8],
}

impl StoredRun<'_> {
    /// Faces in the run.
    pub fn faces(&self) -> usize {
        self.index.len() / 3
    }

    /// Whether the faces are textured triangles (which the depth-first
    /// tracer holds as records).
    pub fn textured(&self) -> bool {
        matches!(self.face, Face::Textured(_))
    }

    /// The faces' material.
    pub fn material(&self) -> u32 {
        self.material
    }

    /// Whether every number of every corner is finite (the faces' records
    /// then have no other floats that are not).
    pub fn finite(&self) -> bool {
        let n = self.face.numbers();
        self.corners
            .iter()
            .all(|c| c[..n].iter().all(|w| w & 0x7f80_0000 != 0x7f80_0000))
    }

    /// Words of each face's record.
    pub fn record_words(&self) -> usize {
        self.face.record_words()
    }

    /// Writes face `t`'s record, exactly as [`unpack`] expands it, into
    /// `rec` (of [`Self::record_words`] words).
    #[inline(always)]
    pub fn write_record(&self, t: usize, rec: &mut [u32]) {
        let i = &self.index[3 * t..3 * t + 3];
        let c = [
            &self.corners[i[0] as usize],
            &self.corners[i[1] as usize],
            &self.corners[i[2] as usize],
        ];
        write_record(rec, self.face, self.material, c);
    }
}

/// What a stored block holds, in order, as [`expand`] hands it out.
pub trait Expand {
    /// `count` records stored as they are (their kinds and lengths
    /// checked, nothing else).
    fn records(&mut self, words: &[u32], count: u32) -> Result<(), String>;
    /// A run of faces.
    fn run(&mut self, run: &StoredRun<'_>) -> Result<(), String>;
}

/// Reads a stored block (`packed`, past its ids, holding `objects`
/// objects whose records take at most `max_words`), handing its records
/// and runs to `to` in order; the words its records take once expanded,
/// or the first problem of a corrupt block. Nothing in `packed` can make
/// it panic.
#[inline(always)]
pub fn expand(
    packed: &[u32],
    objects: u32,
    max_words: usize,
    to: &mut impl Expand,
) -> Result<usize, String> {
    let mut pos = 0usize;
    let mut seen = 0u64;
    let mut expanded = 0usize;
    let mut corners = [[0u32; CORNER_NUMBERS]; MAX_RUN_VERTICES];
    // Numbers per corner that some run has written into `corners`.
    let mut written = 0;
    // Records stored as they are go out a stretch at a time, not one by
    // one: mount's polygons are all such records, and a copy per record
    // (13 words) was 13 % of an out-of-core render's time.
    let (mut plain_from, mut plain_seen) = (0usize, 0u64);
    while pos < packed.len() {
        let head = packed[pos];
        let Some(face) = Face::of_code(head & 0xff) else {
            let kind = ShapeKind::from_u8((head & 0xff) as u8)
                .ok_or_else(|| format!("record {seen} has unknown kind {}", head & 0xff))?;
            let len = kind
                .payload_words(head >> 8)
                .map(|p| p + RECORD_HEADER_WORDS)
                .ok_or_else(|| {
                    format!("record {seen} is a {} with an invalid count", kind.name())
                })?;
            if pos + len > packed.len() {
                return Err(format!("record {seen} is cut off"));
            }
            if expanded + len > max_words {
                return Err("the block expands beyond its largest size".into());
            }
            expanded += len;
            pos += len;
            seen += 1;
            continue;
        };
        if pos > plain_from {
            to.records(&packed[plain_from..pos], (seen - plain_seen) as u32)?;
        }
        let n = (head >> 8) as usize;
        let numbers = face.numbers();
        let header = face.run_header_words();
        let h = packed
            .get(pos..pos + header)
            .ok_or_else(|| format!("the run at object {seen} is cut off"))?;
        let (material, nv) = (h[1], h[2] as usize);
        let width: [u32; CORNER_NUMBERS] = std::array::from_fn(|a| match h.get(3 + a / 3) {
            Some(w) if a < numbers => w >> (8 * (a % 3)) & 0xff,
            _ => 0,
        });
        if n < 2
            || !(1..=MAX_RUN_VERTICES).contains(&nv)
            || width.iter().any(|&w| w > 32)
            || h[3..3 + numbers.div_ceil(3)].iter().any(|w| w >> 24 != 0)
            || (numbers % 3 != 0 && h[2 + numbers.div_ceil(3)] >> (8 * (numbers % 3)) != 0)
        {
            return Err(format!("the run at object {seen} has an invalid header"));
        }
        let base = &h[3 + numbers.div_ceil(3)..];
        let corner_words = (nv * width.iter().sum::<u32>() as usize).div_ceil(32);
        let index_words = (3 * n).div_ceil(4);
        let start = pos + header;
        let body = packed
            .get(start..start + corner_words + index_words)
            .ok_or_else(|| format!("the run at object {seen} is cut off"))?;
        if expanded + n * face.record_words() > max_words {
            return Err("the block expands beyond its largest size".into());
        }
        let index: &[u8] = &bytemuck::cast_slice(&body[corner_words..])[..3 * n];
        // The largest index, in a loop without an exit (it vectorizes,
        // where `any` went byte by byte: a tenth of `unpack`).
        if index.iter().fold(0, |m, &i| m.max(i)) as usize >= nv {
            return Err(format!(
                "the run at object {seen} names a corner it does not have"
            ));
        }
        decode_corners(
            &body[..corner_words],
            &mut corners[..nv],
            &base[..numbers],
            &width[..numbers],
        );
        if numbers < written {
            // A corner's numbers a face does not have are zeros (a
            // patch's run before left normals here).
            for c in &mut corners[..nv] {
                c[numbers..written].fill(0);
            }
        }
        written = written.max(numbers);
        to.run(&StoredRun {
            face,
            material,
            corners: &corners[..nv],
            index,
        })?;
        expanded += n * face.record_words();
        pos = start + corner_words + index_words;
        seen += n as u64;
        (plain_from, plain_seen) = (pos, seen);
    }
    if pos > plain_from {
        to.records(&packed[plain_from..pos], (seen - plain_seen) as u32)?;
    }
    if seen != objects as u64 {
        return Err(format!(
            "the block holds {seen} objects, its header says {objects}"
        ));
    }
    Ok(expanded)
}

/// Expands a stored block (`packed`, holding `objects` objects) into its
/// records, at most `max_words` of them; describes the first problem of a
/// corrupt block. Nothing in `packed` can make it panic.
#[inline(never)]
pub fn unpack(
    packed: &[u32],
    objects: u32,
    max_words: usize,
    out: &mut Vec<u32>,
) -> Result<(), String> {
    out.clear();
    expand(packed, objects, max_words, &mut Records(out)).map(|_| ())
}

/// Records written out as [`unpack`] expands them.
struct Records<'a>(&'a mut Vec<u32>);

impl Expand for Records<'_> {
    #[inline(always)]
    fn records(&mut self, words: &[u32], _: u32) -> Result<(), String> {
        self.0.extend_from_slice(words);
        Ok(())
    }

    #[inline(always)]
    fn run(&mut self, run: &StoredRun<'_>) -> Result<(), String> {
        // Each record is written where it goes. (Written on the stack word
        // by word and then copied in 16-byte moves, each load of the copy
        // spanned 4-byte stores still in the store buffer, which cannot
        // be forwarded to it, and waited for them to reach the cache:
        // half of this function's samples were that copy's first load.)
        // Its corners are read from the run's table, not first copied
        // beside each other: the copy's 16-byte stores, read back by
        // 8-byte loads at other offsets, were not forwarded either (30 %
        // of this function's samples on mount11).
        let words = run.record_words();
        let at = self.0.len();
        self.0.resize(at + run.faces() * words, 0);
        for (t, rec) in self.0[at..].chunks_exact_mut(words).enumerate() {
            run.write_record(t, rec);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TRIANGLE_HEAD_FOR_TESTS: u32 = ShapeKind::Polygon as u32 | 3 << 8;

    fn triangle(out: &mut Vec<u32>, material: u32, v: [[f32; 3]; 3]) {
        let c = v.map(|p| {
            let mut c = [0; CORNER_NUMBERS];
            c[..3].copy_from_slice(&p.map(f32::to_bits));
            c
        });
        push_record(out, Face::Triangle, material, &c);
    }

    /// A patch with the normals `n`.
    fn patch(out: &mut Vec<u32>, material: u32, v: [[f32; 3]; 3], n: [[f32; 3]; 3]) {
        let c: [Corner; 3] = std::array::from_fn(|i| {
            let mut c = [0; CORNER_NUMBERS];
            c[..3].copy_from_slice(&v[i].map(f32::to_bits));
            c[3..6].copy_from_slice(&n[i].map(f32::to_bits));
            c
        });
        push_record(out, Face::Patch, material, &c);
    }

    fn sphere(out: &mut Vec<u32>, material: u32) {
        let kind = ShapeKind::Sphere;
        out.push(kind as u32);
        out.push(material);
        out.extend([-1f32, -1., -1., 1., 1., 1.].map(f32::to_bits));
        out.extend((0..kind.payload_words(0).unwrap()).map(|i| (i as f32).to_bits()));
    }

    /// Records and their objects, packed and unpacked again.
    fn round_trip(records: &[u32], objects: u32) -> (Vec<u32>, PackCounts) {
        let mut p = Packer::default();
        let mut packed = Vec::new();
        p.pack(records, &mut packed);
        let mut back = Vec::new();
        unpack(&packed, objects, records.len(), &mut back).unwrap();
        assert_eq!(back, records);
        (packed, p.counts)
    }

    /// A strip of `n` triangles over awkward numbers: signed zeros, both
    /// signs, subnormals, the largest finite values.
    fn strip(n: usize, material: u32, out: &mut Vec<u32>) {
        strip_of(Face::Triangle, n, material, out)
    }

    fn strip_of(face: Face, n: usize, material: u32, out: &mut Vec<u32>) {
        // +0 and -0 three apart: no face has both on an axis (such a face
        // stays a record; see `a_run_of_256_corners_and_faces_of_both_zeros`).
        let odd = [
            0.0f32,
            1e-45,
            f32::MAX,
            -0.0,
            -1e-45,
            -f32::MAX,
            1.5,
            -2.25,
            0.1,
        ];
        for i in 0..n {
            let p = |j: usize| -> [f32; 3] {
                let k = i + j;
                [
                    odd[k % odd.len()],
                    k as f32 * 0.5,
                    odd[(k * 7) % odd.len()] - k as f32,
                ]
            };
            let v = [p(0), p(1), p(2)];
            match face {
                Face::Triangle => triangle(out, material, v),
                // Normals as awkward as the vertices, and shared less.
                Face::Patch => patch(out, material, v, [p(1), p(3), p(i % 4)]),
                Face::Textured(mask) => textured(out, material, mask, i),
            }
        }
    }

    /// Collects what [`expand`] hands out, as records.
    struct Collect(Vec<u32>);

    impl Expand for Collect {
        fn records(&mut self, words: &[u32], _: u32) -> Result<(), String> {
            self.0.extend_from_slice(words);
            Ok(())
        }

        fn run(&mut self, run: &StoredRun<'_>) -> Result<(), String> {
            let at = self.0.len();
            self.0.resize(at + run.faces() * run.record_words(), 0);
            for (t, rec) in self.0[at..]
                .chunks_exact_mut(run.record_words())
                .enumerate()
            {
                run.write_record(t, rec);
            }
            Ok(())
        }
    }

    /// A block's runs, handed out as runs and checked as such, are
    /// refused exactly when their records would be: a material past the
    /// scene's, a number that is not finite (in a triangle's, a patch's
    /// or a textured triangle's run, after a patch's run has left normals
    /// in the corners' table); what passes is the records `unpack` gives.
    #[test]
    fn runs_checked_as_runs_are_refused_as_their_records_are() {
        use crate::sdb::validate::{Checked, validate_records};
        let (materials, models) = (2, 0);
        for case in 0..8usize {
            let mut records = Vec::new();
            strip_of(Face::Patch, 7, 0, &mut records);
            strip_of(Face::Triangle, 9, (case % 3) as u32, &mut records);
            sphere(&mut records, 1);
            strip_of(Face::Textured(7), 5, 1, &mut records);
            let objects = 7 + 9 + 1 + 5;
            if case >= 3 {
                // A NaN in one of the runs (box and corner alike).
                // Its box is the one its corners give, so that the face
                // stays in its run.
                let first = [0, 7, 17][case % 3] + 1;
                let mut pos = 0;
                for _ in 0..first {
                    let head = records[pos];
                    let kind = ShapeKind::from_u8((head & 0xff) as u8).unwrap();
                    pos += RECORD_HEADER_WORDS + kind.payload_words(head >> 8).unwrap();
                }
                records[pos + RECORD_HEADER_WORDS + 1 + 6 * (case % 2)] = f32::NAN.to_bits();
                let face = Face::of_head(records[pos]).unwrap();
                let c = read_corners(face, &records[pos + RECORD_HEADER_WORDS..]);
                let b = face_box([&c[0], &c[1], &c[2]]);
                records[pos + 2..pos + RECORD_HEADER_WORDS].copy_from_slice(&b);
            }
            let mut packed = Vec::new();
            let mut packer = Packer::default();
            packer.pack(&records, &mut packed);
            assert_eq!(
                packer.counts.run_triangles,
                7 + 9 + 5,
                "case {case}: all in runs"
            );
            let mut back = Vec::new();
            let unpacked = unpack(&packed, objects, records.len(), &mut back);
            let by_records = unpacked
                .clone()
                .and_then(|_| validate_records(&back, objects, materials, models));
            let mut got = Collect(Vec::new());
            let by_runs = expand(
                &packed,
                objects,
                records.len(),
                &mut Checked::new(&mut got, Some((materials, models))),
            );
            assert!(unpacked.is_ok(), "case {case}");
            assert_eq!(
                by_records.is_err(),
                case % 3 == 2 || case >= 3,
                "case {case}"
            );
            assert_eq!(
                by_runs.is_ok(),
                by_records.is_ok(),
                "case {case}: {by_runs:?} {by_records:?}"
            );
            if by_runs.is_ok() {
                assert_eq!(got.0, back, "case {case}");
            }
        }
    }

    /// Corners read number by number from their own places are those a
    /// reader keeping its position reads, for every width from 0 to 32
    /// (the last corner's numbers end at the last word).
    #[test]
    fn corners_read_in_place_are_those_read_in_turn() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for case in 0..200 {
            let numbers = [3, 6, CORNER_NUMBERS][case % 3];
            let width: Vec<u32> = (0..numbers)
                .map(|a| match (case + a) % 5 {
                    0 => 0,
                    1 => 32,
                    _ => (next() % 33) as u32,
                })
                .collect();
            let base: Vec<u32> = (0..numbers).map(|_| next() as u32).collect();
            let nv = 1 + (next() % MAX_RUN_VERTICES as u64) as usize;
            let mut words = Vec::new();
            let mut w = BitWriter {
                out: &mut words,
                acc: 0,
                bits: 0,
            };
            for _ in 0..nv {
                for &wa in &width {
                    w.put(next() as u32 & ((1u64 << wa) - 1) as u32, wa);
                }
            }
            w.finish();
            let mut turn = BitReader {
                words: &words,
                next: 0,
                acc: 0,
                bits: 0,
            };
            let mut corners = vec![[0u32; CORNER_NUMBERS]; nv];
            decode_corners(&words, &mut corners, &base, &width);
            for c in &corners {
                for a in 0..numbers {
                    assert_eq!(c[a], unkey(base[a].wrapping_add(turn.get(width[a]))));
                }
            }
        }
    }

    #[test]
    fn runs_give_back_their_records_bit_for_bit() {
        let mut r = Vec::new();
        strip(40, 0, &mut r);
        sphere(&mut r, 1);
        strip(1, 0, &mut r);
        sphere(&mut r, 1);
        strip(30, 2, &mut r);
        strip(30, 3, &mut r);
        strip_of(Face::Patch, 25, 3, &mut r);
        strip_of(Face::Patch, 1, 4, &mut r);
        strip(30, 3, &mut r);
        let (packed, counts) = round_trip(&r, 40 + 1 + 1 + 1 + 30 + 30 + 25 + 1 + 30);
        assert_eq!(
            counts,
            PackCounts {
                runs: 5,
                run_triangles: 155
            }
        );
        assert!(
            packed.len() * 2 < r.len(),
            "{} of {} words",
            packed.len(),
            r.len()
        );
    }

    /// A textured triangle of `mask` (see [`crate::shapes::Textured`])
    /// whose attributes are as awkward as `strip`'s numbers.
    fn textured(out: &mut Vec<u32>, material: u32, mask: u32, k: usize) {
        use crate::shapes::{COLORS, NORMALS, Shape, Textured, UVS, pack_color};
        let p = |j: usize| [(k + j) as f32 * 0.5, -((k * j) as f32), 1e-45 * j as f32];
        let v = [p(0), p(1), p(2)];
        let n = [p(2), p(1), [0.0, -0.0, 1.0]];
        let uv = [[0.1, -7.5], [(k % 3) as f32, 1e30], [0.0, -0.0]];
        let c = [
            pack_color([1.0, 0.5, 0.0, 1.0]),
            pack_color([0.25, (k % 5) as f32 / 5.0, 1.0, 0.0]),
            [u32::MAX, 0x7f80_0001],
        ];
        let t = Textured {
            vertices: &v,
            normals: if mask & NORMALS != 0 { &n } else { &[] },
            uvs: if mask & UVS != 0 { &uv } else { &[] },
            colors: if mask & COLORS != 0 { &c } else { &[] },
        };
        let shape = Shape::Textured(t);
        out.push(ShapeKind::Textured as u32 | shape.count() << 8);
        out.push(material);
        let c3 = v.map(|q| {
            let mut c = [0; CORNER_NUMBERS];
            c[..3].copy_from_slice(&q.map(f32::to_bits));
            c
        });
        out.extend(face_box([&c3[0], &c3[1], &c3[2]]));
        shape.encode(out);
    }

    #[test]
    fn textured_runs_give_back_their_records_bit_for_bit() {
        let mut r = Vec::new();
        let mut n = 0;
        for mask in 1..8 {
            for k in 0..20 {
                textured(&mut r, mask % 3, mask, k);
                n += 1;
            }
            strip(3, 0, &mut r);
            n += 3;
        }
        // A lone one stays a record.
        textured(&mut r, 0, 2, 99);
        n += 1;
        let (packed, counts) = round_trip(&r, n);
        assert_eq!(counts.runs, 14, "{counts:?}");
        // Few corners are shared here: a real mesh's runs save more.
        assert!(
            packed.len() < r.len(),
            "{} of {} words",
            packed.len(),
            r.len()
        );
        // The depth-first tracer's gathering leaves them records.
        let mut g = RunGather::<MAX_RUN_VERTICES>::default();
        assert!(!g.take(&r, 0));
    }

    #[test]
    fn a_run_closes_at_256_vertices() {
        let mut r = Vec::new();
        for i in 0..200 {
            let x = i as f32;
            triangle(&mut r, 0, [[x, 0., 0.], [x, 1., 0.], [x, 0., 1.]]);
        }
        let (_, counts) = round_trip(&r, 200);
        // 85 triangles use 255 vertices; the 86th would need 258.
        assert_eq!(counts.runs, 3);
        assert_eq!(counts.run_triangles, 200);
    }

    #[test]
    fn a_block_of_plain_records_is_its_own_expansion() {
        // Triangles whose boxes are not their corners' stay records: a
        // block with no runs.
        let mut r = Vec::new();
        for _ in 0..5 {
            let at = r.len();
            strip(1, 0, &mut r);
            r[at + 2] = (-1000f32).to_bits();
        }
        let mut packed = Vec::new();
        Packer::default().pack(&r, &mut packed);
        assert_eq!(packed, r);
        assert!(is_plain(&packed, 5, r.len()));
        assert!(!is_plain(&packed, 4, r.len()));
        assert!(!is_plain(&packed, 5, r.len() - 1));
        assert!(!is_plain(&packed[..packed.len() - 1], 5, r.len()));
        // A block with runs is not; nor is any change that `unpack` would
        // not read back as the same words.
        let mut runs = Vec::new();
        strip(20, 0, &mut runs);
        let mut with_runs = Vec::new();
        Packer::default().pack(&runs, &mut with_runs);
        assert!(!is_plain(&with_runs, 20, runs.len()));
        let mut out = Vec::new();
        for i in 0..packed.len() {
            for v in [0, 1, 0xff, 0x100, 0xffff_ffff, packed[i] ^ 0x80] {
                let mut p = packed.clone();
                p[i] = v;
                if is_plain(&p, 5, r.len()) {
                    unpack(&p, 5, r.len(), &mut out).unwrap();
                    assert_eq!(out, p);
                }
            }
        }
    }

    #[test]
    fn a_triangle_whose_box_is_not_its_vertices_stays_a_record() {
        let mut r = Vec::new();
        strip(3, 0, &mut r);
        let at = r.len();
        strip(1, 0, &mut r);
        r[at + 2] = (-1000f32).to_bits();
        strip(3, 0, &mut r);
        let (packed, counts) = round_trip(&r, 7);
        assert_eq!(counts.run_triangles, 6);
        let words = Face::Triangle.record_words();
        assert!(packed.windows(words).any(|w| w == &r[at..at + words]));
    }

    #[test]
    fn corrupt_runs_are_errors_not_panics() {
        let mut r = Vec::new();
        strip(20, 0, &mut r);
        let mut patches = Vec::new();
        strip_of(Face::Patch, 20, 0, &mut patches);
        let mut packed = Vec::new();
        Packer::default().pack(&patches, &mut packed);
        let mut out = Vec::new();
        for cut in 0..packed.len() {
            let _ = unpack(&packed[..cut], 20, patches.len(), &mut out);
        }
        for i in 0..packed.len() {
            for v in [0, 0xfe, 0x21, 0xffff_ffff, packed[i] ^ 0x80] {
                let mut p = packed.clone();
                p[i] = v;
                let _ = unpack(&p, 20, patches.len(), &mut out);
            }
        }
        let mut packed = Vec::new();
        Packer::default().pack(&r, &mut packed);
        let mut out = Vec::new();
        // Every truncation, and every single-word change to a few patterns.
        for cut in 0..packed.len() {
            let _ = unpack(&packed[..cut], 20, r.len(), &mut out);
        }
        for i in 0..packed.len() {
            for v in [
                0,
                1,
                0xff,
                0x100,
                0xffff_ffff,
                0x2121_2121,
                packed[i] ^ 0x80,
            ] {
                let mut p = packed.clone();
                p[i] = v;
                let _ = unpack(&p, 20, r.len(), &mut out);
            }
        }
        assert!(unpack(&packed, 21, r.len(), &mut out).is_err());
        assert!(unpack(&packed, 20, r.len() - 1, &mut out).is_err());
        // An index past the run's vertices.
        let mut p = packed.clone();
        let last = p.len() - 1;
        p[last] = 0xffff_ffff;
        assert!(
            unpack(&p, 20, r.len(), &mut out)
                .unwrap_err()
                .contains("corner")
        );
    }

    #[test]
    fn a_run_of_256_corners_and_faces_of_both_zeros() {
        // 85 triangles of three new corners, then one of one new corner:
        // the run holds exactly 256, the last index 255.
        let mut r = Vec::new();
        for i in 0..85 {
            let x = i as f32;
            triangle(&mut r, 0, [[x, 0., 0.], [x, 1., 0.], [x, 0., 1.]]);
        }
        triangle(&mut r, 0, [[0., 0., 0.], [0., 1., 0.], [9., 9., 9.]]);
        let (packed, counts) = round_trip(&r, 86);
        assert_eq!(counts.runs, 1);
        assert_eq!(packed[2], 256);
        // Faces with +0 and -0 on one axis, whose boxes `Shape::bounds`
        // made (with `f32::min` and `max`, which leave open which zero
        // they return): whether packed or kept, they read back as stored.
        let mut r = Vec::new();
        strip(3, 0, &mut r);
        for v in [
            [[0., 1., 2.], [-0., 1., 3.], [1., 2., 2.]],
            [[-0., 1., 2.], [0., 1., 3.], [-1., 2., 2.]],
            [[5., -0., 2.], [6., 0., 3.], [5., 2., 2.]],
            [[5., 0., 2.], [6., -0., 3.], [5., -2., 2.]],
        ] {
            let shape = crate::shapes::Shape::Polygon(crate::shapes::Polygon { vertices: &v });
            r.push(TRIANGLE_HEAD_FOR_TESTS);
            r.push(0);
            r.extend(shape.bounds().to_array().map(f32::to_bits));
            r.extend(v.as_flattened().iter().map(|x| x.to_bits()));
        }
        strip(3, 0, &mut r);
        round_trip(&r, 10);
    }

    #[test]
    fn invalid_run_headers_are_errors() {
        let mut r = Vec::new();
        strip(20, 0, &mut r);
        let mut packed = Vec::new();
        Packer::default().pack(&r, &mut packed);
        let mut out = Vec::new();
        assert!(unpack(&packed, 20, r.len(), &mut out).is_ok());
        let set = |at: usize, v: u32| {
            let mut p = packed.clone();
            p[at] = v;
            p
        };
        for p in [
            set(0, RUN | 1 << 8),           // a run of one face
            set(0, RUN),                    // of none
            set(2, 0),                      // no corners
            set(2, 257),                    // too many
            set(3, packed[3] & !0xff | 33), // a width above 32
            set(3, packed[3] | 1 << 24),    // a stray byte
        ] {
            let e = unpack(&p, 20, r.len(), &mut out).unwrap_err();
            assert!(e.contains("invalid header"), "{e}");
        }
    }

    #[test]
    fn ids_read_back_and_a_corrupt_header_is_an_error() {
        for ids in [
            vec![],
            vec![7],
            vec![5, 9, 2, 1_000_000, 3],
            vec![u32::MAX - 1, 0],
        ] {
            let mut out = Vec::new();
            pack_ids(&ids, &mut out);
            out.push(0xdead_beef); // what follows: the records
            let mut got = Vec::new();
            let used = unpack_ids(&out, ids.len() as u32, u32::MAX as u64, &mut got).unwrap();
            assert_eq!(got, ids);
            assert_eq!(out[used], 0xdead_beef);
            // Every cut is an error, never a panic.
            for cut in 0..used {
                if !ids.is_empty() || cut < 2 {
                    assert!(unpack_ids(&out[..cut], ids.len() as u32, u64::MAX, &mut got).is_err());
                }
            }
        }
        let mut out = Vec::new();
        pack_ids(&[3, 4], &mut out);
        // An id past the objects, and a width past 32 bits.
        assert!(unpack_ids(&out, 2, 4, &mut Vec::new()).is_err());
        out[1] = 33;
        assert!(unpack_ids(&out, 2, 100, &mut Vec::new()).is_err());
    }

    #[test]
    fn keys_order_numbers_and_invert() {
        let xs = [-f32::MAX, -1.0, -1e-45, -0.0, 0.0, 1e-45, 1.0, f32::MAX];
        for w in xs.windows(2) {
            assert!(key(w[0].to_bits()) < key(w[1].to_bits()));
        }
        for x in xs {
            assert_eq!(unkey(key(x.to_bits())), x.to_bits());
        }
    }
}

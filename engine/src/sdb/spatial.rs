//! The spatial order of a database's objects (version 6).
//!
//! A scene's objects arrive in whatever order its file lists them. A
//! scanned mesh lists its faces in scan order, an exported CAD model by
//! part, a shuffled one in no order at all; a block of such objects spans
//! the whole scene, so no pass can skip it, and consecutive triangles share
//! few corners, so runs ([`super::packed`]) save little.
//!
//! [`SpatialSorter`] puts them in the order of a Z-order (Morton) curve
//! through their boxes' centres, within a memory budget: records gather in
//! a chunk; a full chunk is sorted and written to a temporary file; at the
//! end the files are merged. Each object keeps its input id, stored in its
//! block, so ties, counts and shading see the ids the input gave.
//!
//! The curve needs no bounds known in advance: each coordinate of the
//! centre is taken as its `f32` bit pattern mapped so that integer order is
//! the order of the numbers ([`super::packed::key`]), and the three are
//! interleaved bit by bit. Within a power of two the map is linear, so the
//! curve is the Z-order of the scene's own space; across powers of two it
//! changes scale, as Z-order changes cell, and stays local.

use super::format::RECORD_HEADER_WORDS;
use crate::error::{Error, IoContext};
use crate::shapes::ShapeKind;
use std::collections::BinaryHeap;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Least chunk a sorter gathers before it writes a sorted file.
pub const MIN_CHUNK_BYTES: usize = 256 << 10;
/// Bytes of each file's read buffer while files are merged.
const MERGE_BUFFER: usize = 64 << 10;
/// Most files merged at once (and so, per level, held open): far below
/// the usual limit of 1,024 open files.
const MAX_FAN_IN: usize = 64;

/// The Z-order key of a record (its words, header first): the centre of
/// its box, each coordinate's order-preserving bit pattern interleaved,
/// x in the lowest bit of each triple.
pub fn record_key(record: &[u32]) -> u128 {
    let c = |a: usize| {
        let lo = f32::from_bits(record[2 + a]);
        let hi = f32::from_bits(record[5 + a]);
        // Halves first: the sum of two large numbers may overflow.
        super::packed::key((lo * 0.5 + hi * 0.5).to_bits())
    };
    spread(c(0)) | spread(c(1)) << 1 | spread(c(2)) << 2
}

/// `v`'s bits, bit `i` moved to bit `3 i`.
fn spread(v: u32) -> u128 {
    fn spread16(v: u64) -> u64 {
        let mut x = v & 0xffff;
        x = (x | x << 16) & 0x0000_0000_ff00_00ff;
        x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
        x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
        x = (x | x << 2) & 0x1249_2492_4924_9249;
        x
    }
    spread16(v as u64) as u128 | (spread16((v >> 16) as u64) as u128) << 48
}

/// Words of the record at the start of `w` (a record the writer built).
fn record_len(w: &[u32]) -> usize {
    let kind = ShapeKind::from_u8((w[0] & 0xff) as u8).expect("a record the writer built");
    RECORD_HEADER_WORDS
        + kind
            .payload_words(w[0] >> 8)
            .expect("a record the writer built")
}

/// Sorts records into the spatial order within a memory budget; see the
/// module documentation.
pub struct SpatialSorter {
    /// The chunk: each record as its input id, then its words.
    chunk: Vec<u32>,
    /// Key, input id and place in `chunk` of each record there.
    entries: Vec<(u128, u32, u32)>,
    chunk_words: usize,
    /// Files merged at once.
    fan_in: usize,
    dir: Option<PathBuf>,
    /// Sorted files written so far, each in the chunk's format, with its
    /// level: 0 for a chunk, one more than its inputs' for a merge.
    files: Vec<(u32, std::fs::File)>,
    /// Names the database being written, in errors.
    path: PathBuf,
    /// Sorts by input id alone (back to the input's order) rather than
    /// along the curve.
    by_id: bool,
}

impl SpatialSorter {
    /// A sorter holding at most about `budget` bytes, its sorted files in
    /// `dir` (the system's temporary directory if `None`).
    pub fn new(budget: usize, dir: Option<&Path>, path: &Path) -> SpatialSorter {
        let chunk_bytes = budget.max(MIN_CHUNK_BYTES);
        // A triangle's record is 17 words, and its entry 8 more (a `u128`
        // is aligned to 16 bytes). Half the budget: the vectors grow by
        // doubling.
        SpatialSorter {
            chunk: Vec::new(),
            entries: Vec::new(),
            chunk_words: chunk_bytes / 2 / 4 * 17 / 25,
            fan_in: (chunk_bytes / MERGE_BUFFER).clamp(2, MAX_FAN_IN),
            dir: dir.map(Path::to_path_buf),
            files: Vec::new(),
            path: path.to_path_buf(),
            by_id: false,
        }
    }

    /// A sorter that puts records back in the order of their input ids
    /// (a database in spatial order rewritten in its input's order).
    pub fn by_id(budget: usize, dir: Option<&Path>, path: &Path) -> SpatialSorter {
        SpatialSorter {
            by_id: true,
            ..SpatialSorter::new(budget, dir, path)
        }
    }

    fn key(&self, record: &[u32]) -> u128 {
        if self.by_id { 0 } else { record_key(record) }
    }

    /// Bytes a sorter of `budget` holds at most.
    pub fn held_bytes(budget: usize) -> usize {
        budget.max(MIN_CHUNK_BYTES)
    }

    /// Takes object `id`'s record.
    pub fn push(&mut self, id: u32, record: &[u32]) -> Result<(), Error> {
        if !self.chunk.is_empty() && self.chunk.len() + record.len() + 1 > self.chunk_words {
            self.spill()?;
        }
        self.entries
            .push((self.key(record), id, self.chunk.len() as u32));
        self.chunk.push(id);
        self.chunk.extend_from_slice(record);
        Ok(())
    }

    fn sort_chunk(&mut self) {
        self.entries.sort_unstable_by_key(|&(k, id, _)| (k, id));
    }

    fn temp_file(&self) -> Result<std::fs::File, Error> {
        match &self.dir {
            Some(d) => tempfile::tempfile_in(d).at(d),
            None => tempfile::tempfile().at(std::env::temp_dir()),
        }
    }

    /// Merges `files` into one new sorted file.
    fn merge_to_file(&self, files: Vec<std::fs::File>) -> Result<std::fs::File, Error> {
        let mut out = BufWriter::with_capacity(MERGE_BUFFER, self.temp_file()?);
        merge(files, &self.path, self.by_id, |id, rec| {
            out.write_all(&id.to_le_bytes()).at(&self.path)?;
            out.write_all(bytemuck::cast_slice(rec)).at(&self.path)
        })?;
        self.rewound(out)
    }

    /// The file `out` wrote, flushed and back at its start for reading.
    fn rewound(&self, out: BufWriter<std::fs::File>) -> Result<std::fs::File, Error> {
        let mut file = out
            .into_inner()
            .map_err(|e| Error::io(&self.path, e.into_error()))?;
        file.seek(SeekFrom::Start(0)).at(&self.path)?;
        Ok(file)
    }

    /// Writes the chunk, sorted, to a temporary file; merges the last
    /// files of one level into one of the next whenever they number
    /// `fan_in`, so that few files are open at a time and each record is
    /// merged once per level.
    fn spill(&mut self) -> Result<(), Error> {
        self.sort_chunk();
        let mut out = BufWriter::with_capacity(MERGE_BUFFER, self.temp_file()?);
        for &(_, _, at) in &self.entries {
            let at = at as usize;
            let len = 1 + record_len(&self.chunk[at + 1..]);
            out.write_all(bytemuck::cast_slice(&self.chunk[at..at + len]))
                .at(&self.path)?;
        }
        let file = self.rewound(out)?;
        self.files.push((0, file));
        self.chunk.clear();
        self.entries.clear();
        loop {
            let level = self.files.last().map_or(0, |f| f.0);
            let same = self.files.iter().rev().take_while(|f| f.0 == level).count();
            if same < self.fan_in {
                return Ok(());
            }
            let group = self.files.split_off(self.files.len() - same);
            let merged = self.merge_to_file(group.into_iter().map(|f| f.1).collect())?;
            self.files.push((level + 1, merged));
        }
    }

    /// Gives every record, in the spatial order, to `sink` (input id,
    /// record words).
    pub fn finish(
        mut self,
        mut sink: impl FnMut(u32, &[u32]) -> Result<(), Error>,
    ) -> Result<(), Error> {
        if self.files.is_empty() {
            self.sort_chunk();
            for &(_, id, at) in &self.entries {
                let at = at as usize + 1;
                let len = record_len(&self.chunk[at..]);
                sink(id, &self.chunk[at..at + len])?;
            }
            return Ok(());
        }
        if !self.chunk.is_empty() {
            self.spill()?;
        }
        // Merge buffers take what the chunk took; files beyond that many
        // are merged into fewer first.
        self.chunk = Vec::new();
        self.entries = Vec::new();
        let mut files: Vec<std::fs::File> = std::mem::take(&mut self.files)
            .into_iter()
            .map(|f| f.1)
            .collect();
        while files.len() > self.fan_in {
            let rest = files.split_off(self.fan_in);
            let merged = self.merge_to_file(files)?;
            files = rest;
            files.push(merged);
        }
        merge(files, &self.path, self.by_id, sink)
    }
}

/// One sorted file being merged: its next record.
struct Head {
    key: u128,
    id: u32,
    file: usize,
}

impl PartialEq for Head {
    fn eq(&self, o: &Self) -> bool {
        (self.key, self.id) == (o.key, o.id)
    }
}
impl Eq for Head {}
impl PartialOrd for Head {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Head {
    // Reversed: the heap's greatest is the smallest key.
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        (o.key, o.id).cmp(&(self.key, self.id))
    }
}

/// Reads the next record of a sorted file into `rec` (input id first).
fn read_record(
    r: &mut BufReader<std::fs::File>,
    rec: &mut Vec<u32>,
    path: &Path,
) -> Result<bool, Error> {
    let mut head = [0u32; 1 + RECORD_HEADER_WORDS];
    match r.read_exact(bytemuck::cast_slice_mut(&mut head)) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(false),
        Err(e) => return Err(Error::io(path, e)),
    }
    let len = record_len(&head[1..]);
    rec.clear();
    rec.extend_from_slice(&head);
    rec.resize(1 + len, 0);
    r.read_exact(bytemuck::cast_slice_mut(
        &mut rec[1 + RECORD_HEADER_WORDS..],
    ))
    .at(path)?;
    Ok(true)
}

/// Merges sorted files into `sink`, in key order (or `by_id`, with no
/// key), ties by input id.
fn merge(
    files: Vec<std::fs::File>,
    path: &Path,
    by_id: bool,
    mut sink: impl FnMut(u32, &[u32]) -> Result<(), Error>,
) -> Result<(), Error> {
    let mut readers: Vec<_> = files
        .into_iter()
        .map(|f| BufReader::with_capacity(MERGE_BUFFER, f))
        .collect();
    let mut recs: Vec<Vec<u32>> = vec![Vec::new(); readers.len()];
    let key = |r: &[u32]| if by_id { 0 } else { record_key(r) };
    let mut heap = BinaryHeap::with_capacity(readers.len());
    for (i, r) in readers.iter_mut().enumerate() {
        if read_record(r, &mut recs[i], path)? {
            heap.push(Head {
                key: key(&recs[i][1..]),
                id: recs[i][0],
                file: i,
            });
        }
    }
    while let Some(h) = heap.pop() {
        let i = h.file;
        sink(h.id, &recs[i][1..])?;
        if read_record(&mut readers[i], &mut recs[i], path)? {
            heap.push(Head {
                key: key(&recs[i][1..]),
                id: recs[i][0],
                file: i,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn triangle(c: [f32; 3]) -> Vec<u32> {
        let mut r = vec![ShapeKind::Polygon as u32 | 3 << 8, 0];
        r.extend(c.iter().chain(&c).map(|f| f.to_bits()));
        for _ in 0..3 {
            r.extend(c.iter().map(|f| f.to_bits()));
        }
        r
    }

    #[test]
    fn spread_moves_each_bit_to_every_third() {
        for i in 0..32 {
            assert_eq!(spread(1 << i), 1u128 << (3 * i));
        }
        assert_eq!(spread(u32::MAX).count_ones(), 32);
    }

    #[test]
    fn keys_follow_the_z_order_of_the_centres() {
        // The eight octants of a cube around the origin, in Z order.
        let mut last = 0;
        for i in 0..8 {
            let c = [i & 1, i >> 1 & 1, i >> 2 & 1].map(|b| if b == 1 { 0.5 } else { -0.5 });
            let k = record_key(&triangle(c));
            assert!(i == 0 || k > last, "octant {i}");
            last = k;
        }
    }

    /// Every record comes out once, in key order, ties by id, whether it
    /// fits one chunk or needs files and merges of merges.
    #[test]
    fn chunks_files_and_merges_give_the_same_order() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.sdb");
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        let records: Vec<Vec<u32>> = (0..60_000)
            .map(|i| {
                if i % 10 == 0 {
                    // Ties: the same centre as the object before.
                    triangle([0.25, 0.25, 0.25])
                } else {
                    triangle([next(), next(), next()])
                }
            })
            .collect();
        let mut want: Vec<(u128, u32)> = records
            .iter()
            .enumerate()
            .map(|(i, r)| (record_key(r), i as u32))
            .collect();
        want.sort();
        for budget in [usize::MAX / 64, MIN_CHUNK_BYTES] {
            for fan in [false, true] {
                let mut s = SpatialSorter::new(budget, Some(dir.path()), &path);
                if fan {
                    // Small files, many more of them than one merge takes:
                    // merged level by level while they come.
                    s.chunk_words = 3_000;
                    s.fan_in = 3;
                }
                for (i, r) in records.iter().enumerate() {
                    s.push(i as u32, r).unwrap();
                }
                let spilled = !s.files.is_empty();
                if fan {
                    // About 360 chunks: merged to levels up to 5, with at
                    // most two files a level left open.
                    let top = s.files.iter().map(|f| f.0).max().unwrap();
                    assert!(top >= 4, "{top}");
                    assert!(s.files.len() <= 2 * (top as usize + 1), "{}", s.files.len());
                }
                assert_eq!(spilled, budget == MIN_CHUNK_BYTES || fan);
                let mut got = Vec::new();
                s.finish(|id, rec| {
                    assert_eq!(rec, &records[id as usize][..]);
                    got.push((record_key(rec), id));
                    Ok(())
                })
                .unwrap();
                assert_eq!(got, want, "budget {budget}, many files {fan}");
            }
        }
    }
}

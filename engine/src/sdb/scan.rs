//! A scan: a front-to-back pass over a database's blocks, each read,
//! decompressed, its triangle runs expanded and (the first time) its
//! checksum and records checked; and, once a scan has learned where the
//! blocks lie, passing over the ones a pass has no use for.

use super::block::Block;
use super::database::{BlockSpan, Database, VERIFY_CHECKSUMS};
use super::format::*;
use super::validate::{Checked, validate_records};
use crate::error::{Error, IoContext};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::sync::atomic::Ordering;

/// Counters of one scan.
#[derive(Clone, Copy, Debug, Default)]
pub struct DbStats {
    pub bytes_read: u64,
    pub blocks_read: u64,
    /// Blocks passed over unread.
    pub blocks_skipped: u64,
}

impl Database {
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
            words_from: 0,
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

/// A front-to-back pass over the objects of a [`Database`].
pub struct Scan<'d> {
    db: &'d Database,
    file: File,
    decompressor: Option<zstd::bulk::Decompressor<'static>>,
    /// The decoded block, as 4-byte words, from `words_from` on.
    words: Vec<u32>,
    /// Where the block's records start in `words`: past the stored
    /// block's ids when the block had no runs to expand, and `words` is
    /// the block as stored (see [`super::packed::is_plain`]).
    words_from: usize,
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

    /// Hands the last block's decoded words and ids over to the caller in
    /// exchange for `words` and `ids`, which the next block is decoded
    /// into (their contents do not matter): a block kept past the next
    /// read without a copy.
    /// Returns where the block's records start in the words handed over.
    pub fn swap_block_buffers(&mut self, words: &mut Vec<u32>, ids: &mut Vec<u32>) -> usize {
        std::mem::swap(&mut self.words, words);
        std::mem::swap(&mut self.ids, ids);
        self.words_from
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
        let Some(read) = self.read_block()? else {
            return Ok(None);
        };
        let count = read.header.object_count;
        if self.db.runs {
            if super::packed::is_plain(&self.packed[read.at..], count, self.db.largest_block / 4) {
                // Nothing to expand: the stored block is its records.
                std::mem::swap(&mut self.packed, &mut self.words);
                self.words_from = read.at;
            } else {
                super::packed::unpack(
                    &self.packed[read.at..],
                    count,
                    self.db.largest_block / 4,
                    &mut self.words,
                )
                .map_err(|m| self.err(m))?;
                self.words_from = 0;
            }
        } else {
            self.words_from = 0;
        }
        if self.verify {
            validate_records(
                &self.words[self.words_from..],
                count,
                self.db.scene.materials.len(),
                self.db.models.len(),
            )
            .map_err(|m| self.err(m))?;
        }
        let (index, first) = self.account(&read, self.words.len() - self.words_from)?;
        Ok(Some(Block::from_words(
            index,
            first,
            count,
            &self.words[self.words_from..],
            &self.ids,
        )))
    }

    /// The next block as it is stored, its records and triangle runs
    /// handed to `to` in order, runs not expanded into records (checked
    /// as [`Scan::next_block`] checks their records); `None` after the
    /// last block, else its first object and number of objects. Its
    /// objects' input ids are [`Scan::ids`].
    pub fn next_block_with(
        &mut self,
        to: &mut impl super::packed::Expand,
    ) -> Result<Option<(u64, u32)>, Error> {
        let Some(read) = self.read_block()? else {
            return Ok(None);
        };
        let count = read.header.object_count;
        let materials = self.db.scene.materials.len();
        let models = self.db.models.len();
        let decoded = if self.db.runs {
            let mut checked = Checked::new(to, self.verify.then_some((materials, models)));
            super::packed::expand(
                &self.packed[read.at..],
                count,
                self.db.largest_block / 4,
                &mut checked,
            )
            .map_err(|m| self.err(m))?
        } else {
            if self.verify {
                validate_records(&self.words, count, materials, models).map_err(|m| self.err(m))?;
            }
            to.records(&self.words, count).map_err(|m| self.err(m))?;
            self.words.len()
        };
        let (_, first) = self.account(&read, decoded)?;
        Ok(Some((first, count)))
    }

    /// The input ids of the objects of the block read last (version 6),
    /// else empty.
    pub fn ids(&self) -> &[u32] {
        &self.ids
    }

    /// Reads the next block (its header checked, decompressed, its ids
    /// decoded) into `packed` (version 4 on) or `words`.
    fn read_block(&mut self) -> Result<Option<ReadBlock>, Error> {
        if self.next_index == self.db.block_count {
            if self.next_object != self.db.object_count || self.offset != self.db.blocks_end {
                return Err(self.err(format!(
                    "blocks hold {} objects ending at byte {}, the header says {} objects ending at byte {}",
                    self.next_object, self.offset, self.db.object_count, self.db.blocks_end
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
        if self.offset + BLOCK_HEADER_BYTES as u64 > self.db.blocks_end {
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
        if end > self.db.blocks_end {
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
        let at = if runs {
            self.packed.truncate(raw_len / 4);
            if self.db.ids {
                super::packed::unpack_ids(
                    &self.packed,
                    h.object_count,
                    self.db.object_count,
                    &mut self.ids,
                )
                .map_err(|m| self.err(m))?
            } else {
                0
            }
        } else {
            self.words.truncate(raw_len / 4);
            0
        };
        Ok(Some(ReadBlock { header: h, end, at }))
    }

    /// Counts the block `read`, whose records take `decoded` words, as
    /// read: its index and first object.
    fn account(&mut self, read: &ReadBlock, decoded: usize) -> Result<(u64, u64), Error> {
        let (h, end) = (&read.header, read.end);
        self.stats.bytes_read += BLOCK_HEADER_BYTES as u64 + h.stored_len as u64;
        self.decoded += decoded as u64 * 4;
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
        Ok((index, first))
    }
}

/// A block [`Scan::read_block`] has read: its header, the file offset
/// after it, and where its records start in `packed` (past its ids).
struct ReadBlock {
    header: RawBlockHeader,
    end: u64,
    at: usize,
}

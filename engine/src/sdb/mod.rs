//! The object database (`.sdb`): the paper's binary preprocessed scene.
//!
//! Layout (all little-endian):
//!
//! ```text
//! header   256 bytes: magic, version, compression, counts, scene bounds,
//!          where the tables are; CRC-32 over all of it
//! block 0  32-byte block header + payload (records, or their zstd frame)
//! block 1  ...
//! tables   view, background, lights, materials; CRC-32 in the header
//! ```
//!
//! A block holds whole records, at most [`MAX_BLOCK_RAW`] bytes of them,
//! objects in id order; each block's CRC-32 covers its header and payload.
//! Since version 4 consecutive triangles are stored as runs of shared,
//! bit-packed vertices and one-byte indices ([`packed`]), which a reader
//! expands back into their records.
//! A record is 4-byte words: kind and vertex count, material index, bounding
//! box (six `f32`), then the geometry. The bounding box lets the grid be
//! built without decoding geometry. Tables sit at the end because a streamed
//! scene (NFF, SPD) only knows its lights and materials once it has ended;
//! readers fetch them at open and then read blocks strictly front to back.

mod block;
mod database;
mod format;
mod open;
mod packed;
mod read_ahead;
mod scan;
mod spatial;
mod tables;
mod validate;
mod writer;

pub use crate::scene::ModelRef;
pub(crate) use block::decode_record;
pub use block::{Block, BoxRef, ObjectRef};
pub use database::Database;
pub use format::RECORD_HEADER_WORDS;
pub use format::{
    AGGREGATE_SIZE, BLOCK_TARGET, Compression, MAGIC, MAX_BLOCK_RAW, MAX_LIGHTS, MAX_MATERIALS,
};
pub use packed::{Expand, MAX_RUN_VERTICES, PackCounts, RunGather, StoredRun};
pub use read_ahead::{read_ahead_batch, read_ahead_bytes, scan_blocks};
pub use scan::{DbStats, Scan};
pub use spatial::SpatialSorter;
pub use writer::{DbWriter, WRITE_BUFFER, WriteSummary};

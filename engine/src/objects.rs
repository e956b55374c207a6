//! Every object of a scene in memory: the database's records, concatenated,
//! decoded in place when an object is looked up. The depth-first tracer
//! keeps its scene here; it is the same data, bit for bit, that the
//! breadth-first tracer streams from disk.

use crate::error::Error;
use crate::progress::Progress;
use crate::sdb::{Database, ObjectRef, decode_record};

pub struct ObjectTable {
    words: Vec<u32>,
    /// Word offset of each object's record.
    offsets: Vec<u32>,
}

impl ObjectTable {
    /// Bytes an in-memory copy of `db` takes.
    pub fn estimate_bytes(db: &Database) -> u64 {
        db.decoded_bytes() + 4 * db.object_count()
    }

    pub fn load(db: &Database, progress: &dyn Progress) -> Result<ObjectTable, Error> {
        if db.decoded_bytes() / 4 > u32::MAX as u64 {
            return Err(Error::Invalid(format!(
                "{}: {} bytes of records are too many to hold in memory for the depth-first tracer; use --mode bf",
                db.path().display(),
                db.decoded_bytes()
            )));
        }
        let mut words = Vec::with_capacity((db.decoded_bytes() / 4) as usize);
        let mut offsets = Vec::with_capacity(db.object_count() as usize);
        let mut scan = db.scan()?;
        progress.set_total(db.object_count());
        while let Some(block) = scan.next_block()? {
            let base = words.len();
            let w = block.words();
            let mut pos = 0;
            for _ in 0..block.object_count {
                offsets.push((base + pos) as u32);
                let (_, len) = decode_record(&w[pos..], 0).expect("validated block");
                pos += len;
            }
            words.extend_from_slice(w);
            progress.inc(block.object_count as u64);
        }
        Ok(ObjectTable { words, offsets })
    }

    pub fn len(&self) -> usize {
        self.offsets.len()
    }

    pub fn is_empty(&self) -> bool {
        self.offsets.is_empty()
    }

    /// Object `id` (which must be below `len()`).
    #[inline(always)]
    pub fn get(&self, id: u32) -> ObjectRef<'_> {
        let at = self.offsets[id as usize] as usize;
        decode_record(&self.words[at..], id)
            .expect("validated record")
            .0
    }

    pub fn bytes(&self) -> u64 {
        (self.words.len() * 4 + self.offsets.len() * 4) as u64
    }
}

//! A scan with its reading on a thread of its own: while the caller works
//! on one block, the reader reads, decompresses and prepares the next
//! ones. Decompressing a zstd database was a third of a render's time, on
//! the thread that the shards' threads wait for at every block.
//!
//! The blocks still come in file order, each once; the reader passes over
//! the blocks `skip` names, as [`Scan::skip_block`] does.

use super::block::Block;
use super::scan::{DbStats, Scan};
use crate::error::Error;
use std::sync::mpsc;

/// Blocks the caller takes at a time. A block holds about a thousand
/// objects, a few microseconds of work when few rays are near them, while
/// handing work to the shards' threads and waiting for them costs tens of
/// microseconds of wake-ups: taken one at a time, a fifth of an
/// out-of-core render went to the kernel's scheduler (mount11 and tetra12
/// under 256 MiB: about 20 %; batches of 16: 4.7 and 6.0 %; of 32: 3.0
/// and 3.5 %).
pub const BATCH: usize = 32;
/// The smallest batch worth a reader thread; smaller budgets read on the
/// caller's thread.
pub const MIN_BATCH: usize = 4;

/// Memory a read-ahead scan of `db` in batches of `batch` blocks holds
/// beyond the scan's own buffers: the blocks in flight (a batch in use, a
/// batch read ahead, one being read), each with what was prepared from it
/// (allowed half as much again).
pub fn read_ahead_bytes(db: &super::Database, batch: usize) -> u64 {
    ((2 * batch + 1) * 3 * db.largest_block() / 2) as u64
}

/// The largest batch, from [`MIN_BATCH`] to [`BATCH`] blocks, whose
/// read-ahead fits in `bytes`, or 0 if none does. (A budget too small for
/// batches of 32 gave each block to the shards alone, and two threads
/// spent 40 % of mount11's samples under 96 MiB waking each other.)
pub fn read_ahead_batch(db: &super::Database, bytes: u64) -> usize {
    (MIN_BATCH..=BATCH)
        .rev()
        .find(|&b| read_ahead_bytes(db, b) <= bytes)
        .unwrap_or(0)
}

/// A block the reader has read, with what it prepared from it.
struct Ahead<P> {
    index: u64,
    first_object: u64,
    object_count: u32,
    /// The block's records: `words[from..]`.
    words: Vec<u32>,
    from: usize,
    ids: Vec<u32>,
    prepared: P,
}

/// The next block `skip` does not pass over (once the layout is known,
/// [`Scan::skip_block`] seeks past the others), or `None` after the last.
fn next_wanted<'s>(
    scan: &'s mut Scan<'_>,
    skip: &(dyn Fn(u64) -> bool + Sync),
) -> Result<Option<Block<'s>>, Error> {
    while skip(scan.next_index()) && scan.skip_block()? {}
    scan.next_block()
}

/// A block with what was prepared from it.
pub type Prepared<'a, P> = (Block<'a>, &'a P);

/// What is done with a batch of prepared blocks.
pub type Consume<'c, P> = dyn FnMut(&[Prepared<'_, P>]) -> Result<(), Error> + 'c;

/// Runs `consume` on every block of `scan` that `skip` does not pass
/// over, in file order, with what `prepare` made of it. With a `batch` of
/// blocks (not 0), reading and `prepare` run on a thread of their own, a
/// batch ahead of `consume`, which is given up to `batch` blocks at a
/// time; with 0, all runs on the caller's thread, a block at a time.
/// Returns the scan's counters, or the first error of either side.
pub fn scan_blocks<P: Default + Send>(
    mut scan: Scan<'_>,
    batch_blocks: usize,
    skip: &(dyn Fn(u64) -> bool + Sync),
    prepare: &(dyn Fn(&Block<'_>, &mut P) + Sync),
    consume: &mut Consume<'_, P>,
) -> Result<DbStats, Error> {
    if batch_blocks == 0 {
        let mut p = P::default();
        while let Some(block) = next_wanted(&mut scan, skip)? {
            prepare(&block, &mut p);
            consume(&[(block, &p)])?;
        }
        return Ok(scan.stats());
    }
    std::thread::scope(|s| {
        let (tx, rx) = mpsc::sync_channel::<Result<Ahead<P>, Error>>(batch_blocks);
        let (back, spare) = mpsc::channel::<Ahead<P>>();
        let reader = std::thread::Builder::new()
            .name("sray-read-ahead".into())
            .spawn_scoped(s, move || {
                let mut read = || -> Result<bool, Error> {
                    let Some(block) = next_wanted(&mut scan, skip)? else {
                        return Ok(false);
                    };
                    let mut a = spare.try_recv().unwrap_or_else(|_| Ahead {
                        index: 0,
                        first_object: 0,
                        object_count: 0,
                        words: Vec::new(),
                        from: 0,
                        ids: Vec::new(),
                        prepared: P::default(),
                    });
                    a.index = block.index;
                    a.first_object = block.first_object;
                    a.object_count = block.object_count;
                    prepare(&block, &mut a.prepared);
                    // The block's buffers travel with it (a copy was a
                    // tenth of the reader's time).
                    a.from = scan.swap_block_buffers(&mut a.words, &mut a.ids);
                    // A closed channel: the caller stopped on an error.
                    Ok(tx.send(Ok(a)).is_ok())
                };
                loop {
                    match read() {
                        Ok(true) => {}
                        Ok(false) => break,
                        Err(e) => {
                            let _ = tx.send(Err(e));
                            break;
                        }
                    }
                }
                scan.stats()
            })
            .map_err(|e| Error::Invalid(format!("cannot start a reader thread: {e}")))?;
        let mut outcome = Ok(());
        let mut batch: Vec<Ahead<P>> = Vec::with_capacity(batch_blocks);
        // The reader's error, returned once the blocks before it are used.
        let mut failed = None;
        while failed.is_none() {
            // A full batch, or what is left at the end of the scan.
            while batch.len() < batch_blocks {
                match rx.recv() {
                    Ok(Ok(a)) => batch.push(a),
                    Ok(Err(e)) => {
                        failed = Some(e);
                        break;
                    }
                    Err(_) => break,
                }
            }
            if batch.is_empty() {
                break;
            }
            let blocks: Vec<Prepared<'_, P>> = batch
                .iter()
                .map(|a| {
                    let block = Block::from_words(
                        a.index,
                        a.first_object,
                        a.object_count,
                        &a.words[a.from..],
                        &a.ids,
                    );
                    (block, &a.prepared)
                })
                .collect();
            let done = consume(&blocks);
            drop(blocks);
            if let Err(e) = done {
                outcome = Err(e);
                break;
            }
            for a in batch.drain(..) {
                let _ = back.send(a);
            }
        }
        if let (Ok(()), Some(e)) = (&outcome, failed) {
            outcome = Err(e);
        }
        // Dropping the receiver ends a reader still sending.
        drop(rx);
        let stats = match reader.join() {
            Ok(s) => s,
            Err(panic) => std::panic::resume_unwind(panic),
        };
        outcome.map(|()| stats)
    })
}

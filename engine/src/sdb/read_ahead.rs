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

/// Blocks read ahead of the one in use: one is double buffering (the
/// reader works on the next block while the caller works on this one).
const AHEAD: usize = 1;

/// Memory a read-ahead scan of `db` holds beyond the scan's own buffers:
/// the blocks in flight (read ahead, in use, being read), each with what
/// was prepared from it (allowed half as much again).
pub fn read_ahead_bytes(db: &super::Database) -> u64 {
    ((AHEAD + 2) * 3 * db.largest_block() / 2) as u64
}

/// A block the reader has read, with what it prepared from it.
struct Ahead<P> {
    index: u64,
    first_object: u64,
    object_count: u32,
    words: Vec<u32>,
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

/// Runs `consume` on every block of `scan` that `skip` does not pass
/// over, in file order, with what `prepare` made of it. With `ahead`,
/// reading and `prepare` run on a thread of their own, a block ahead
/// of `consume`; without, all runs on the caller's thread. Returns
/// the scan's counters, or the first error of either side.
pub fn scan_blocks<P: Default + Send>(
    mut scan: Scan<'_>,
    ahead: bool,
    skip: &(dyn Fn(u64) -> bool + Sync),
    prepare: &(dyn Fn(&Block<'_>, &mut P) + Sync),
    consume: &mut dyn FnMut(&Block<'_>, &P) -> Result<(), Error>,
) -> Result<DbStats, Error> {
    if !ahead {
        let mut p = P::default();
        while let Some(block) = next_wanted(&mut scan, skip)? {
            prepare(&block, &mut p);
            consume(&block, &p)?;
        }
        return Ok(scan.stats());
    }
    std::thread::scope(|s| {
        let (tx, rx) = mpsc::sync_channel::<Result<Ahead<P>, Error>>(AHEAD);
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
                        ids: Vec::new(),
                        prepared: P::default(),
                    });
                    a.index = block.index;
                    a.first_object = block.first_object;
                    a.object_count = block.object_count;
                    a.words.clear();
                    a.words.extend_from_slice(block.words());
                    a.ids.clear();
                    a.ids.extend_from_slice(block.ids());
                    prepare(&block, &mut a.prepared);
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
        for a in rx.iter() {
            let a = match a {
                Ok(a) => a,
                Err(e) => {
                    outcome = Err(e);
                    break;
                }
            };
            let block =
                Block::from_words(a.index, a.first_object, a.object_count, &a.words, &a.ids);
            if let Err(e) = consume(&block, &a.prepared) {
                outcome = Err(e);
                break;
            }
            let _ = back.send(a);
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

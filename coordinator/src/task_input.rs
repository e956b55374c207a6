//! A task's input as its worker is sent it (`TaskInput`): the records
//! the worker holds already are named (by the task that left them there),
//! the rest streamed in chunks from the round's files.

use crate::state::Shared;
use crate::task::TaskInput;
use sray_proto::v1;
use sray_proto::wire::{encode, records_per_chunk};
use std::sync::atomic::Ordering;
use tokio::sync::mpsc;
use tonic::Status;

/// One piece of a task's input, in the order the worker reads them.
enum Piece {
    /// Records the worker holds already, named by the task that left
    /// them there.
    Named(v1::RecordChunk),
    /// Rays `at .. at + len` of the round, from the coordinator's files.
    Rays { at: u64, len: u64 },
    /// The task's results, from the coordinator's files.
    Results,
}

/// What the worker `session`, which holds the outputs of the tasks
/// `held`, is sent as the input of `task`: the records it holds named,
/// the others streamed. Err names records that are only at another
/// worker (`records_at_workers`): the task cannot run here.
fn plan(
    task: &v1::Task,
    input: &TaskInput,
    session: &str,
    held: &[u64],
) -> Result<Vec<Piece>, &'static str> {
    // What the worker holds of a task's output, if the output taken
    // was this worker's.
    let holds = |t: u64, s: &str| {
        held.contains(&t) && sray_proto::ids::same(s.as_bytes(), session.as_bytes())
    };
    let named = |kind: v1::RecordKind, task_id: u64, offset: u64, count: u64| {
        Piece::Named(v1::RecordChunk {
            kind: kind as i32,
            data: Vec::new(),
            held: Some(v1::HeldRecords {
                task_id,
                offset,
                count,
            }),
            raw: false,
        })
    };
    let mut pieces = Vec::new();
    let (first, n) = (task.first_ray, task.ray_count);
    let by_intersect = input
        .held
        .intersect
        .as_ref()
        .filter(|(t, s)| holds(*t, s))
        .map(|(t, _)| *t);
    if !task.eye_rays && (input.rays.is_some() || input.held.pinned) {
        if let Some(t) = by_intersect {
            let off = first - input.held.shard_first;
            pieces.push(named(v1::RecordKind::Rays, t, off, n));
        } else {
            // Runs of the range held by the worker are named, the
            // rest sent.
            let mut at = first;
            let end = first + n;
            let mut next = input
                .held
                .rays
                .iter()
                .filter(|g| g.start + g.len > first && g.start < end)
                .peekable();
            while at < end {
                let (upto, mine) = match next.peek() {
                    Some(g) if g.start <= at => {
                        let hi = (g.start + g.len).min(end);
                        let m = holds(g.task, &g.session).then_some((g.task, at - g.start));
                        next.next();
                        (hi, m)
                    }
                    Some(g) => (g.start.min(end), None),
                    None => (end, None),
                };
                if upto <= at {
                    break;
                }
                match mine {
                    Some((t, off)) => pieces.push(named(v1::RecordKind::Rays, t, off, upto - at)),
                    None if input.rays.is_none() => return Err("rays"),
                    None => pieces.push(Piece::Rays { at, len: upto - at }),
                }
                at = upto;
            }
        }
    }
    let shade = task.stage == v1::Stage::Shade as i32;
    match (&input.results, by_intersect) {
        (_, Some(t)) if shade => {
            pieces.push(named(v1::RecordKind::Results, t, input.results_offset, n));
        }
        (Some(_), _) => pieces.push(Piece::Results),
        (None, None) if shade && input.held.pinned => return Err("results"),
        (None, _) => {}
    }
    Ok(pieces)
}

/// The input of `task` for the worker `session` (holding the outputs of
/// the tasks `held`) when all of it is records the worker holds: small
/// enough to go with the task itself, which saves the worker a call.
/// None when records must be streamed, or the task cannot run there.
pub(crate) fn inline(
    task: &v1::Task,
    input: &TaskInput,
    session: &str,
    held: &[u64],
) -> Option<Vec<v1::RecordChunk>> {
    plan(task, input, session, held)
        .ok()?
        .into_iter()
        .map(|p| match p {
            Piece::Named(c) => Some(c),
            Piece::Rays { .. } | Piece::Results => None,
        })
        .collect()
}

/// Sends the input of `task` to the worker `session`, which holds the
/// outputs of the tasks `held`: records it holds are named, the others
/// streamed from the coordinator's files. Runs on a blocking thread.
pub(crate) fn send(
    shared: &Shared,
    task: &v1::Task,
    input: &TaskInput,
    session: &str,
    held: &[u64],
    tx: &mpsc::Sender<Result<v1::RecordChunk, Status>>,
) {
    let send = |c: v1::RecordChunk| {
        let bytes = prost::Message::encoded_len(&c) as u64;
        shared
            .traffic
            .to_workers
            .fetch_add(bytes, Ordering::Relaxed);
        tx.blocking_send(Ok(c)).is_ok()
    };
    // The coordinator's own files failed it: no fault of the worker's.
    let fail = |e: sray_engine::Error| {
        let msg = e.to_string();
        let r = v1::TaskRef {
            task_id: task.task_id,
            attempt: task.attempt,
            session: session.to_string(),
            held: Vec::new(),
        };
        shared.local_fault(&r, &msg);
        let _ = tx.blocking_send(Err(Status::unavailable(format!(
            "the coordinator cannot read the task's input: {msg}"
        ))));
    };
    let pieces = match plan(task, input, session, held) {
        Ok(p) => p,
        Err(what) => {
            let _ = tx.blocking_send(Err(Status::failed_precondition(format!(
                "this worker does not hold the {what} of this task, and the coordinator keeps no copy"
            ))));
            return;
        }
    };
    for piece in pieces {
        let sent = match piece {
            Piece::Named(c) => send(c),
            Piece::Rays { at, len } => {
                let rays = input.rays.as_ref().expect("planned from the files");
                match rays.reader_range(at, len) {
                    Ok(mut rd) => stream_records(&mut rd, v1::RecordKind::Rays, &send, &fail),
                    Err(e) => {
                        fail(e);
                        false
                    }
                }
            }
            Piece::Results => {
                let results = input.results.as_ref().expect("planned from the files");
                match results.reader_range(input.results_offset, task.ray_count) {
                    Ok(mut rd) => stream_records(&mut rd, v1::RecordKind::Results, &send, &fail),
                    Err(e) => {
                        fail(e);
                        false
                    }
                }
            }
        };
        if !sent {
            return;
        }
    }
}

/// Streams a reader's records in encoded chunks; false if the receiver
/// went away or reading failed.
fn stream_records<T: bytemuck::Pod>(
    rd: &mut sray_engine::spill::RecordsReader<'_, T>,
    kind: v1::RecordKind,
    send: &dyn Fn(v1::RecordChunk) -> bool,
    fail: &dyn Fn(sray_engine::Error),
) -> bool {
    let per = records_per_chunk::<T>();
    let mut buf = Vec::with_capacity(per);
    let chunk = |buf: &[T]| v1::RecordChunk {
        kind: kind as i32,
        data: encode(buf),
        held: None,
        raw: false,
    };
    loop {
        match rd.next() {
            Ok(Some(r)) => {
                buf.push(r);
                if buf.len() == per {
                    if !send(chunk(&buf)) {
                        return false;
                    }
                    buf.clear();
                }
            }
            Ok(None) => break,
            Err(e) => {
                fail(e);
                return false;
            }
        }
    }
    buf.is_empty() || send(chunk(&buf))
}

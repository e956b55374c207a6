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
    // What the worker holds of a task's output, if the output taken
    // was this worker's.
    let holds = |t: u64, s: &str| {
        held.contains(&t) && sray_proto::ids::same(s.as_bytes(), session.as_bytes())
    };
    let named = |kind: v1::RecordKind, task_id: u64, offset: u64, count: u64| v1::RecordChunk {
        kind: kind as i32,
        data: Vec::new(),
        held: Some(v1::HeldRecords {
            task_id,
            offset,
            count,
        }),
        raw: false,
    };
    let (first, n) = (task.first_ray, task.ray_count);
    let by_intersect = input
        .held
        .intersect
        .as_ref()
        .filter(|(t, s)| holds(*t, s))
        .map(|(t, _)| *t);
    // Records that are only at the workers (`records_at_workers`)
    // and not at this one: the task cannot run here.
    let lost = |what: &str| {
        let _ = tx.blocking_send(Err(Status::failed_precondition(format!(
            "this worker does not hold the {what} of this task, and the coordinator keeps no copy"
        ))));
    };
    if !task.eye_rays && (input.rays.is_some() || input.held.pinned) {
        if let Some(t) = by_intersect {
            let off = first - input.held.shard_first;
            if !send(named(v1::RecordKind::Rays, t, off, n)) {
                return;
            }
        } else {
            // Runs of the range held by the worker are named, the
            // rest sent.
            let mut at = first;
            let end = first + n;
            let segs = input.held.rays.clone();
            let mut next = segs
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
                    Some((t, off)) => {
                        if !send(named(v1::RecordKind::Rays, t, off, upto - at)) {
                            return;
                        }
                    }
                    None => {
                        let Some(rays) = &input.rays else {
                            return lost("rays");
                        };
                        let mut rd = match rays.reader_range(at, upto - at) {
                            Ok(r) => r,
                            Err(e) => return fail(e),
                        };
                        if !stream_records(&mut rd, v1::RecordKind::Rays, &send, &fail) {
                            return;
                        }
                    }
                }
                at = upto;
            }
        }
    }
    let shade = task.stage == v1::Stage::Shade as i32;
    match (&input.results, by_intersect) {
        (Some(_), Some(t)) | (None, Some(t)) if shade => {
            send(named(v1::RecordKind::Results, t, input.results_offset, n));
        }
        (Some(results), _) => {
            let mut rd = match results.reader_range(input.results_offset, n) {
                Ok(r) => r,
                Err(e) => return fail(e),
            };
            stream_records(&mut rd, v1::RecordKind::Results, &send, &fail);
        }
        (None, None) if shade && input.held.pinned => lost("results"),
        (None, _) => {}
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

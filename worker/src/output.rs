//! A task's output on its way to the coordinator. Records are encoded
//! (deltas, byte planes, zstd: see `sray_proto::wire`) on a thread of
//! their own while the tracer goes on with the task: on the executor's
//! thread the encoding took a fifth of a small job's worker time (one
//! local worker, balls 4), time every task waited for. To a coordinator
//! on this machine (`--raw-records`) they go raw instead: over loopback,
//! compressing and decompressing cost more time than the bytes save (one local worker,
//! balls4: shading 0.118-0.130 s raw against 0.136-0.145 s encoded). Messages
//! leave in the order they were given.

use sray_proto::v1::{self, RecordKind, task_output::Part};
use sray_proto::wire::encode_bytes;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{SyncSender, sync_channel};
use tokio::sync::mpsc;

/// Messages queued for encoding at most: enough to keep the encoder busy,
/// few enough that the tracer cannot run far ahead of the network (each
/// holds up to a megabyte of records).
const QUEUED: usize = 4;

const CLOSED: &str = "the output stream to the coordinator closed";

/// The encoding thread of an executor.
pub struct Encoder {
    tx: Option<SyncSender<Job>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

struct Job {
    out: mpsc::Sender<v1::TaskOutput>,
    closed: Arc<AtomicBool>,
    payload: Payload,
}

enum Payload {
    Records {
        kind: RecordKind,
        size: usize,
        bytes: Vec<u8>,
    },
    Part(Part),
}

impl Encoder {
    /// `raw`: send records as they lie in memory, not encoded.
    pub fn start(raw: bool) -> Encoder {
        let (tx, rx) = sync_channel::<Job>(QUEUED);
        let thread = std::thread::Builder::new()
            .name("sray-encode".into())
            .spawn(move || {
                for job in rx {
                    if job.closed.load(Ordering::Acquire) {
                        continue;
                    }
                    let part = match job.payload {
                        Payload::Records { kind, size, bytes } => Part::Records(v1::RecordChunk {
                            kind: kind as i32,
                            data: if raw {
                                bytes
                            } else {
                                encode_bytes(&bytes, size)
                            },
                            held: None,
                            raw,
                        }),
                        Payload::Part(p) => p,
                    };
                    let msg = v1::TaskOutput { part: Some(part) };
                    if job.out.blocking_send(msg).is_err() {
                        job.closed.store(true, Ordering::Release);
                    }
                }
            })
            .expect("cannot start a thread");
        Encoder {
            tx: Some(tx),
            thread: Some(thread),
        }
    }

    /// Where one task's output goes.
    pub fn output(&self, out: mpsc::Sender<v1::TaskOutput>) -> Output<'_> {
        Output {
            enc: self,
            out,
            closed: Arc::new(AtomicBool::new(false)),
        }
    }
}

/// The thread ends once every queued message is sent.
impl Drop for Encoder {
    fn drop(&mut self) {
        self.tx = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// One task's output stream, through its executor's [`Encoder`].
pub struct Output<'a> {
    enc: &'a Encoder,
    out: mpsc::Sender<v1::TaskOutput>,
    /// Set when the stream was found closed: what follows is dropped.
    closed: Arc<AtomicBool>,
}

impl Output<'_> {
    /// This output if `send`, else none (the records are kept instead).
    pub fn filter(&self, send: bool) -> Option<&Self> {
        send.then_some(self)
    }

    /// Queues records for encoding and sending.
    pub fn records<T: bytemuck::Pod>(&self, kind: RecordKind, recs: &[T]) -> Result<(), String> {
        self.push(Payload::Records {
            kind,
            size: std::mem::size_of::<T>(),
            bytes: bytemuck::cast_slice(recs).to_vec(),
        })
    }

    /// Queues a message to send as it is, after everything queued before.
    pub fn part(&self, part: Part) -> Result<(), String> {
        self.push(Payload::Part(part))
    }

    fn push(&self, payload: Payload) -> Result<(), String> {
        if self.closed.load(Ordering::Acquire) {
            return Err(CLOSED.into());
        }
        let tx = self.enc.tx.as_ref().ok_or(CLOSED)?;
        tx.send(Job {
            out: self.out.clone(),
            closed: self.closed.clone(),
            payload,
        })
        .map_err(|_| CLOSED.to_string())
    }
}

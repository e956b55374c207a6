//! What the coordinator counts for `/metrics` and `sray status`: bytes on
//! the wire, jobs and tasks.

use std::sync::atomic::{AtomicU64, Ordering};

/// Bytes on the wire (records and scene chunks, not protocol framing).
#[derive(Default, Debug)]
pub struct Traffic {
    pub to_workers: AtomicU64,
    pub from_workers: AtomicU64,
    pub scene_bytes: AtomicU64,
    pub scene_chunks: AtomicU64,
}

impl Traffic {
    pub fn snapshot(&self) -> [u64; 4] {
        [
            self.to_workers.load(Ordering::Relaxed),
            self.from_workers.load(Ordering::Relaxed),
            self.scene_bytes.load(Ordering::Relaxed),
            self.scene_chunks.load(Ordering::Relaxed),
        ]
    }
}

/// Counters for `/metrics` and `sray status`: bumped once per job or
/// task (never per ray), so they cost nothing on the hot paths.
#[derive(Default, Debug)]
pub struct Counters {
    pub jobs_submitted: AtomicU64,
    pub jobs_done: AtomicU64,
    pub jobs_failed: AtomicU64,
    /// Tasks completed (the winning attempt), by stage, and verification
    /// samples among them.
    pub tasks_intersect: AtomicU64,
    pub tasks_shade: AtomicU64,
    pub tasks_verification: AtomicU64,
    /// Attempts a worker reported failed.
    pub tasks_failed: AtomicU64,
    /// Rays of completed tasks, by stage.
    pub rays_intersected: AtomicU64,
    pub rays_shaded: AtomicU64,
    /// Verification samples that disagreed with the shard's output.
    pub mismatches: AtomicU64,
    pub workers_registered: AtomicU64,
    /// Tasks given in answer to a NextTask call, and in the reply to the
    /// worker's previous output (`TaskOutput.next`).
    pub given_on_request: AtomicU64,
    pub given_with_output: AtomicU64,
    /// Task inputs sent with their task (`NextTaskReply.input`), and
    /// streamed by a TaskInput call.
    pub inputs_inline: AtomicU64,
    pub inputs_streamed: AtomicU64,
}

//! A job's driver: the breadth-first round loop of the embedded renderer,
//! with each stage cut into shards that workers run.
//!
//! Per round: the rays (eye rays, which workers make themselves, or the
//! previous round's spawned rays, kept in a file here) are split into
//! shards of at most `shard_rays`; each shard is intersected by some
//! worker, which returns its results in ray order. As the shards are
//! contiguous runs of ray ids, the sorted streams merge by concatenation.
//! Then each shard is shaded by some worker, given its rays and results;
//! the colour it contributes is added to the frame (in fixed point, so the
//! order of arrival does not matter) and the rays it spawns, sorted by key,
//! are merged by key into the next round's rays. The image and every count
//! are therefore those of the embedded render, whatever the workers, the
//! shard size or the order of completion.
//!
//! **Verification.** A ray's intersection result, and what shading it
//! contributes and spawns, depend only on the ray, never on the worker,
//! its grid or its memory. So every shard's output is checked, before the
//! stage may end, by re-tracing a random contiguous sample of its rays
//! (`verify_fraction` of them, at least `verify_min_rays`) on a *different*
//! worker and comparing bit for bit: results exactly; spawned rays in the
//! sample's key range exactly; the sample's contributions must all be
//! among the shard's (contributions carry no ray id). When no other worker
//! may take the sample, the coordinator traces it itself. On a mismatch the
//! coordinator re-traces the sample itself (it is the one party trusted),
//! quarantines whichever worker disagrees with it, redoes elsewhere every
//! output of this stage from a worker found lying, and says so in the
//! job's log.
//!
//! **Records at the workers.** Where results and spawned rays stay at
//! the workers that made them, a worker lost with some costs only the
//! shards whose records it held: they are recomputed from the rounds that
//! led to them, on another worker (`recover.rs`). Verification there
//! checks whole shards, picked at random after each round (and each
//! worker's first): the shard and the rounds that led to it run again on
//! another worker, and the counts, the digests of the records each kept
//! and the colour each adds to the frame must agree; on a mismatch the
//! coordinator traces them itself, and a worker found lying is
//! quarantined and the job starts again without it (`held.rs`).
//!
//! **Checkpoints.** At the end of every round the next round's rays, the
//! frame and the totals are journaled (see [`crate::jobs`]); a restarted
//! coordinator resumes the job from there.
//!
//! The rooms: `submit.rs` (jobs in, resumed, run to their end), `job.rs`
//! (a request checked), `rounds.rs` (the round loop), `recover.rs`
//! (lost records recomputed), `held.rs` (their verification), `shards.rs` (a
//! round cut into shards), `stages.rs` (a stage's tasks and their
//! verification), `verify.rs` (comparing samples, the coordinator's own
//! tracer) and `stats.rs` (totals and statistics).

mod held;
mod job;
mod prints;
mod recover;
mod rounds;
mod shards;
mod stages;
mod stats;
mod submit;
mod verify;

pub use submit::{resume_all, submit};

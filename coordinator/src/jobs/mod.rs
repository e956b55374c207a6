//! The coordinator's jobs: who may see them, what their clients are told,
//! and their journal on disk, so that a coordinator that stops (SIGTERM)
//! or dies (SIGKILL, power loss) resumes every unfinished job from its
//! last finished round, and keeps finished images fetchable for
//! `job_retention`.
//!
//! Journal: `DATA_DIR/jobs/ID/`, written at the end of every round:
//!
//! - `rays-R.bin`: the rays of round R (the next one to run), packed
//!   records as on the wire; `frame-R.bin`: the fixed-point frame after
//!   round R - 1 (the sums of every finished round);
//! - `job.json`: the request (the protobuf `JobSpec`, hex), the hash of the
//!   job's secret (never the secret), the round to resume at, the totals
//!   so far and the job's log; written last, so it only ever names files
//!   that are whole;
//! - when the job ends, `image.bin` and `stats.json` (or the error).
//!
//! Every file is written to a temporary name, fsynced and renamed, and the
//! directory fsynced, so a crash at any point leaves the previous round's
//! checkpoint or the new one, never a mix. The scene itself is in the
//! scene store (`DATA_DIR/HASH.sdb`), by content hash.
//!
//! The rooms: `entry.rs` (a job and the table of jobs), `journal.rs` (its
//! record, checkpoints and outcome, read back at start) and `files.rs`
//! (the journal's files, written crash-safely).

mod entry;
mod files;
mod journal;

pub use entry::{JobEntry, JobRefusal, JobState, JobView, Jobs};
pub use files::write_atomic;
pub use journal::{Record, Resume, checkpoint, fail, finish, load_all, load_checkpoint, result};

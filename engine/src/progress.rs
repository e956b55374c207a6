//! Progress reporting for long work (generation, conversion, rendering).
//! The engine only counts; the command line draws the bars.

/// Receives progress of one piece of work. Implementations must be cheap:
/// hot loops call `inc` in batches, not per object.
pub trait Progress: Send + Sync {
    /// Sets the amount of work to do (objects, bytes, rays, ...).
    fn set_total(&self, total: u64);
    /// Records `n` more units done.
    fn inc(&self, n: u64);
    /// Describes the current stage ("depth 2, pass 3").
    fn set_message(&self, msg: &str);
}

/// Progress that goes nowhere: for tests, and when output is not a terminal.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn set_total(&self, _: u64) {}
    fn inc(&self, _: u64) {}
    fn set_message(&self, _: &str) {}
}

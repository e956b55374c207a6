//! A worker node: takes intersection and shading tasks for shards of rays
//! from a coordinator, streams the whole object database through its own
//! grids for each, and sends the results back. Workers only ever call the
//! coordinator, never the other way round.
//!
//! - [`node`]: registration, heartbeats, the task loop;
//! - [`cache`]: the scene cache, by content hash, verified and repaired;
//! - [`exec`]: a job's executor thread around the engine's breadth-first
//!   [`sray_engine::bf::Tracer`];
//! - [`params`]: render settings on the wire.

pub mod cache;
pub mod exec;
mod inputs;
mod kept;
pub mod node;
mod output;
pub mod params;
mod tmp;

pub use node::{WorkerConfig, run};

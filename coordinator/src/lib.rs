//! The cluster coordinator: workers register here, clients submit renders
//! here, and each job's rounds are sharded over the workers.
//!
//! - [`config`]: the coordinator's settings and the limits on requests;
//! - [`state`]: what the coordinator knows: workers, the task queue,
//!   quarantine, the jobs;
//! - [`task`]: a task's input, output and events;
//! - [`service`]: the gRPC calls of `sray.proto`;
//! - [`task_input`], [`task_output`]: a task's records to its worker, and
//!   its output back, checked as it comes;
//! - [`driver`]: a job's round loop, sharded over the workers, and its
//!   verification;
//! - [`jobs`]: who may see a job, its watchers, its journal on disk;
//! - [`scenes`]: object databases served by content hash;
//! - [`server`]: listening, TLS, the token, gRPC health and reflection;
//! - [`status`]: what `sray status` and the dashboard show;
//! - [`http`]: `--http-listen`: `/healthz`, `/metrics`, the dashboard.
//!
//! No two of these files import each other, directly or in a loop
//! (`tests/imports.rs` checks it): types two rooms share live in a third
//! that both import.

pub mod config;
pub mod driver;
pub mod http;
pub mod jobs;
pub mod scenes;
pub mod server;
pub mod service;
pub mod state;
pub mod status;
pub mod task;
pub mod task_input;
pub mod task_output;

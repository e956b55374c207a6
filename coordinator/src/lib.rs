//! The cluster coordinator: workers register here, clients submit renders
//! here, and each job's rounds are sharded over the workers.
//!
//! - [`state`]: workers, the task queue, jobs;
//! - [`service`]: the gRPC calls of `sray.proto`;
//! - [`driver`]: a job's round loop, sharded over the workers;
//! - [`jobs`]: who may see a job, its watchers, its journal on disk;
//! - [`scenes`]: object databases served by content hash;
//! - [`server`]: listening, TLS, the token, gRPC health and reflection;
//! - [`status`]: what `sray status` and the dashboard show;
//! - [`http`]: `--http-listen`: `/healthz`, `/metrics`, the dashboard.

pub mod driver;
pub mod http;
pub mod jobs;
pub mod scenes;
pub mod server;
pub mod service;
pub mod state;
pub mod status;

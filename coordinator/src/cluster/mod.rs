//! Cluster rendering: the coordinator's side.
//!
//! - [`state`]: workers, the task queue, jobs;
//! - [`service`]: the gRPC calls of `sray.proto`;
//! - [`driver`]: a job's round loop, sharded over the workers;
//! - [`scenes`]: object databases served by content hash;
//! - [`server`]: listening, TLS, the token;
//! - [`client`]: submitting a render to a coordinator and watching it;
//! - [`local`]: a coordinator and N worker processes for one render.

pub mod client;
pub mod driver;
pub mod local;
pub mod scenes;
pub mod server;
pub mod service;
pub mod state;

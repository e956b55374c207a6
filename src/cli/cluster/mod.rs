//! Rendering on a cluster from the command line.
//!
//! - [`client`]: submitting a render to a coordinator and watching it;
//! - [`fetch`]: `sray fetch JOB`, a submitted job's image again;
//! - [`status`]: `sray status`, the cluster's workers and jobs;
//! - [`conn`]: the connection flags of every client command;
//! - [`local`]: a coordinator in this process and N worker processes for
//!   one render (`--local-workers`).

pub mod client;
pub mod conn;
pub mod fetch;
pub mod local;
pub mod status;

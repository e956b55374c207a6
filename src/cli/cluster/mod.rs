//! Rendering on a cluster from the command line.
//!
//! - [`client`]: submitting a render to a coordinator and watching it;
//! - [`fetch`]: `sray fetch JOB`, a submitted job's image again;
//! - [`local`]: a coordinator in this process and N worker processes for
//!   one render (`--local-workers`).

pub mod client;
pub mod fetch;
pub mod local;

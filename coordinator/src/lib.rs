//! The coordinator: drives renders and hosts the `sray` command line.

pub mod bench;
pub mod cli;
pub mod cluster;
pub mod job;

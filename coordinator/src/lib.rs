//! The coordinator: drives renders and hosts the `sray` command line.

pub mod cli;
pub mod job;

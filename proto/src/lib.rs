//! The gRPC contract between sray's coordinator, its workers and its
//! clients (`sray.proto`, compiled at build time without a system
//! `protoc`), and the small pieces every side shares: record packing,
//! message limits, the shared-token check and TLS settings.

pub mod auth;
pub mod net;
pub mod wire;

/// The generated messages and services.
#[allow(clippy::all)]
pub mod v1 {
    tonic::include_proto!("sray.v1");
}

/// Bumped whenever the messages or their meaning change incompatibly.
pub const PROTOCOL_VERSION: u32 = 2;

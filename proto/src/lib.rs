//! The gRPC contract between sray's coordinator, its workers and its
//! clients (`sray.proto`, compiled at build time without a system
//! `protoc`), and the small pieces every side shares: record packing,
//! message limits, scene hashes, the token checks and roles, random ids, TLS settings.

pub mod auth;
pub mod colour;
pub mod ids;
pub mod net;
pub mod scene_hash;
pub mod wire;

/// The generated messages and services.
#[allow(clippy::all)]
pub mod v1 {
    tonic::include_proto!("sray.v1");
}

/// The encoded `FileDescriptorSet` of `sray.proto`, for gRPC server
/// reflection.
pub const FILE_DESCRIPTOR_SET: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/sray_descriptor.bin"));

/// Bumped whenever the messages or their meaning change incompatibly.
/// 3: random job ids with secrets, worker sessions, separate roles.
/// 4: compressed records, held records not sent again, grid builds
/// reported.
/// 5: records at the workers (`Task.keep_output`, kept counts in the
/// summary, the jobs running in the heartbeat's answer).
/// 6: raw record chunks (`RecordChunk.raw`).
/// 7: a contribution's `run` (its colour goes to the slots after it too).
/// 8: scenes travel as object database version 4 (triangle runs), which a
/// worker of protocol 7 cannot read: it is refused when it registers, not
/// when its first task fails.
/// 9: scenes from files travel as object database version 6 (objects in
/// spatial order, with their input ids), which a worker of protocol 8
/// cannot read.
/// 10: the digest of kept records (`TaskSummary.kept_digest`), which
/// verification with records at the workers compares.
/// 11: a shading whose records stay at the worker sends its colour packed
/// (`RECORD_KIND_COLOUR`, see [`colour`]) instead of contributions.
pub const PROTOCOL_VERSION: u32 = 11;

//! The gRPC contract (filled in by the cluster work).

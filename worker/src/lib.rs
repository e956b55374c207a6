//! A worker node (filled in by the cluster work).

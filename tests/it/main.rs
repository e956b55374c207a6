//! The end-to-end tests of the `sray` binary, as one test binary.
//!
//! Each file under `tests/` used to be a test binary of its own, and each
//! was linked with thin LTO against every dependency (tokio, tonic, image,
//! rayon, zstd...): those links were most of a clean `cargo test --release`.
//! The files are modules here instead; a test is named by its file, e.g.
//! `cargo test --release --test it cluster_trust::` runs one file's tests.
//!
//! Nothing here changes state of the test process that another test could
//! see: the tests run the real binary (`CARGO_BIN_EXE_sray`) in temporary
//! directories, and process-wide behaviour such as the file-backed
//! allocator of `df_paging` is switched on in that child, never here. A
//! test that must be alone in its process (one that installs a global
//! allocator, sets environment variables, changes the current directory or
//! counts its own threads or memory) belongs in a test binary of its own.
//!
//! Every `.rs` file in this directory must be a `mod` below: cargo does not
//! compile a file that no module names.

mod common;

mod cli_bad_input;
mod cli_bench;
mod cli_gltf;
mod cli_image;
mod cli_instances;
mod cli_limits;
mod cli_meshes;
mod cli_progress;
mod cli_render;
mod cli_scene;
mod cli_spatial;
mod cli_textures;
mod cluster;
mod cluster_faults;
mod cluster_observe;
mod cluster_scale;
mod cluster_trust;
mod cluster_wire;
mod deploy;
mod df_paging;
mod docs_commands;
mod simd_widths;

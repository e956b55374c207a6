//! The engine's integration tests, as one test binary.
//!
//! Each file under `engine/tests/` used to be a test binary of its own,
//! each linked with thin LTO against all the engine's dependencies; the
//! files are modules here instead. A test is named by its file, e.g.
//! `cargo test --release -p sray-engine --test it nff_reader::`.
//!
//! None of these tests changes process-wide state (no global allocator or
//! paging, environment variables, current directory or global thread
//! pool), so sharing one process is safe. A test that must be alone in its
//! process belongs in a test binary of its own.
//!
//! Every `.rs` file in this directory must be a `mod` below: cargo does not
//! compile a file that no module names.

mod common;

mod breadth_first;
mod crowded_voxels;
mod database;
mod df_memory;
mod edge_cases;
mod gltf_lighting;
mod gltf_scenes;
mod gltf_textures;
mod instances;
mod invariance;
mod mesh_readers;
mod mesh_textures;
mod nff_reader;
mod render_contract;
mod self_intersection;
mod spd_reference;
mod texture_tiles;

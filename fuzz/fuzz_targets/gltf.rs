//! The glTF reader on arbitrary bytes (a `.gltf` or `.glb` with only
//! embedded buffers): it must stream the scene into the sink or return an
//! error naming the file, never panic, and every object it emits must be
//! valid and safe to intersect.
#![no_main]

mod common;

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let _ = sray_engine::mesh::gltf_scene::read_gltf_bytes(
        data,
        Path::new("fuzz.glb"),
        None,
        None,
        &mut common::Sink,
        &common::Quiet,
    );
});

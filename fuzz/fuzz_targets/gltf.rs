//! The glTF reader on arbitrary bytes (a `.gltf` or `.glb` with only
//! embedded buffers): it must stream the scene into the sink or return an
//! error naming the file, never panic, and every object it emits must be
//! valid and safe to intersect.
#![no_main]

mod common;

use libfuzzer_sys::fuzz_target;
use sray_engine::Error;
use sray_engine::mesh::MeshOptions;
use sray_engine::scene::{Aabb, Light, Material, SceneSink, View};
use sray_engine::sdb::ModelRef;
use sray_engine::shapes::Shape;
use std::path::Path;

/// A sink that keeps models (as a database does), so that meshes placed
/// more than once take the models' path; it checks what it is given.
#[derive(Default)]
struct ModelSink {
    models: u32,
    open: bool,
}

impl SceneSink for ModelSink {
    fn background(&mut self, _: [f32; 3]) -> Result<(), Error> {
        Ok(())
    }
    fn view(&mut self, _: &View) -> Result<(), Error> {
        Ok(())
    }
    fn light(&mut self, _: &Light) -> Result<(), Error> {
        Ok(())
    }
    fn material(&mut self, _: &Material) -> Result<(), Error> {
        Ok(())
    }
    fn object(&mut self, shape: &Shape<'_>) -> Result<(), Error> {
        common::Sink.object(shape)
    }
    fn begin_model(&mut self) -> Result<(), Error> {
        assert!(!self.open, "a model begun inside another");
        self.open = true;
        Ok(())
    }
    fn end_model(&mut self) -> Result<ModelRef, Error> {
        assert!(self.open, "a model ended that was not begun");
        self.open = false;
        self.models += 1;
        Ok(ModelRef {
            index: self.models - 1,
            bbox: Aabb::EMPTY,
            triangles: 0,
        })
    }
    fn instance(&mut self, model: u32, m: &glam::DAffine3) -> Result<(), Error> {
        assert!(model < self.models && !self.open);
        let _ = sray_engine::models::Placement::new(model, *m);
        Ok(())
    }
    fn takes_models(&self) -> bool {
        true
    }
}

fuzz_target!(|data: &[u8]| {
    let opts = MeshOptions {
        memory: 1 << 30,
        spill_dir: None,
        camera_index: None,
    };
    let _ = sray_engine::mesh::gltf_scene::read_gltf_bytes(
        data,
        Path::new("fuzz.glb"),
        None,
        &opts,
        &mut common::Sink,
        &common::Quiet,
    );
    let _ = sray_engine::mesh::gltf_scene::read_gltf_bytes(
        data,
        Path::new("fuzz.glb"),
        None,
        &opts,
        &mut ModelSink::default(),
        &common::Quiet,
    );
});

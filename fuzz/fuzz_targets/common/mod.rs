//! What the mesh fuzz targets share: a sink that intersects every object
//! it is given, as a renderer would, and a progress that keeps quiet.

use sray_engine::intersect::RayQ;
use sray_engine::math::Vec3;
use sray_engine::mesh::MeshOptions;
use sray_engine::progress::Progress;
use sray_engine::scene::{ImageData, Light, Material, MeshFacts, SceneSink, TextureImage, View};
use sray_engine::texture::Encoding;
use sray_engine::shapes::{Shape, intersect};

/// Discards the scene but tests each object against a few rays.
pub struct Sink;

impl SceneSink for Sink {
    fn background(&mut self, _: [f32; 3]) -> Result<(), sray_engine::Error> {
        Ok(())
    }
    fn view(&mut self, _: &View) -> Result<(), sray_engine::Error> {
        Ok(())
    }
    fn light(&mut self, _: &Light) -> Result<(), sray_engine::Error> {
        Ok(())
    }
    fn material(&mut self, _: &Material) -> Result<(), sray_engine::Error> {
        Ok(())
    }
    fn origin(&mut self, o: [f64; 3]) -> Result<(), sray_engine::Error> {
        assert!(o.iter().all(|c| c.is_finite()));
        Ok(())
    }
    fn mesh(&mut self, _: &MeshFacts) -> Result<(), sray_engine::Error> {
        Ok(())
    }
    fn texture(&mut self, image: &TextureImage) -> Result<u32, sray_engine::Error> {
        // What a render does with an image a reader accepted: decode it.
        let ImageData::Encoded(bytes) = &image.data else {
            panic!("a reader gave a tiled image");
        };
        sray_engine::texture::Texture::decode(bytes, &image.name, Encoding::Srgb)
            .expect("a reader accepted an image that does not decode");
        Ok(0)
    }
    fn object(&mut self, s: &Shape<'_>) -> Result<(), sray_engine::Error> {
        s.validate().expect("a mesh reader emitted an invalid shape");
        let b = s.bounds();
        let c = Vec3::new(
            (b.min[0] as f64 + b.max[0] as f64) / 2.0,
            (b.min[1] as f64 + b.max[1] as f64) / 2.0,
            (b.min[2] as f64 + b.max[2] as f64) / 2.0,
        );
        for d in [Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.3, -0.5, 0.8)] {
            let ray = RayQ::from_vec3(c - d * 10.0, d);
            // A hit's surface, as shading takes it (a textured
            // triangle's attributes interpolated).
            if let Some(t) = intersect::<f64>(s, &b, &ray, 0.0, f64::INFINITY) {
                let _ = s.surface(&ray, t);
            }
            let _ = intersect::<f32>(s, &b, &ray.cast(), 0.0, f32::INFINITY);
        }
        Ok(())
    }
}

/// Progress that reports nothing, warnings included.
pub struct Quiet;

impl Progress for Quiet {
    fn set_total(&self, _: u64) {}
    fn inc(&self, _: u64) {}
    fn set_message(&self, _: &str) {}
    fn warn(&self, _: &str) {}
}

/// A quarter of the inputs (lengths 1 mod 4) get no memory at all, so
/// that every table goes to disk and the external join runs, with sort
/// runs of 16 records; the others resolve faces in memory. Creating the
/// spill files dominates a run's time (run with TMPDIR=/dev/shm), so the
/// disk path gets a share, not half.
#[allow(dead_code)] // not every target reads with options
pub fn options(data: &[u8]) -> MeshOptions {
    MeshOptions {
        memory: if data.len() % 4 == 1 { 0 } else { 64 << 20 },
        spill_dir: None,
        camera_index: None,
    }
}

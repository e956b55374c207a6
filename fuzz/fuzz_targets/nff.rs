//! The NFF reader on arbitrary bytes: it must return a scene or an error
//! naming a line, never panic, never allocate without bound, and every
//! object it accepts must be safe to intersect.
#![no_main]

use libfuzzer_sys::fuzz_target;
use sray_engine::intersect::RayQ;
use sray_engine::math::Vec3;
use sray_engine::nff::read_nff_from;
use sray_engine::progress::NoProgress;
use sray_engine::scene::{Light, Material, SceneSink, View};
use sray_engine::shapes::{Shape, intersect};
use std::path::Path;

/// Discards the scene but tests each object against a few rays, as a
/// renderer would.
struct Sink;

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
    fn object(&mut self, s: &Shape<'_>) -> Result<(), sray_engine::Error> {
        let b = s.bounds();
        let c = Vec3::new(
            (b.min[0] as f64 + b.max[0] as f64) / 2.0,
            (b.min[1] as f64 + b.max[1] as f64) / 2.0,
            (b.min[2] as f64 + b.max[2] as f64) / 2.0,
        );
        for d in [Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.3, -0.5, 0.8)] {
            let ray = RayQ::from_vec3(c - d * 10.0, d);
            let _ = intersect::<f64>(s, &b, &ray, 0.0, f64::INFINITY);
            let _ = intersect::<f32>(s, &b, &ray.cast(), 0.0, f32::INFINITY);
        }
        Ok(())
    }
}

fuzz_target!(|data: &[u8]| {
    let _ = read_nff_from(data, Path::new("fuzz.nff"), &mut Sink, &NoProgress);
});

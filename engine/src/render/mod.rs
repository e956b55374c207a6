//! What every tracer shares: the camera, the shading of a hit, the frame
//! buffer, render options and statistics. The depth-first and breadth-first
//! tracers differ only in the order they find hits; with these shared parts
//! they produce the same image and the same counts.

mod camera;
mod cutout;
mod frame;
mod options;
mod sampling;
mod shade;
mod stats;

pub use camera::Camera;
pub use cutout::Cutouts;
pub use frame::{Contribution, FIXED_ONE, Frame, ImageFormat, to_fixed};
pub use options::{Aggregates, GridRes, Mode, Precision, RenderOptions};
pub use sampling::{EyeRays, MAX_SAMPLES, Sampling};
pub use shade::{Footprint, ShadeLight, ShadeScene, Spawn, brdf, shade};
pub use stats::{KindCounts, RayCounts, RenderStats};

use crate::scene::{Aabb, SceneHeader};

/// Distance below which a secondary or shadow ray ignores hits, so that it
/// does not find the surface it leaves: a fixed fraction of the scene's
/// size, where size is the larger of the bounding box's diagonal and its
/// largest coordinate (precision of a point depends on its magnitude, not
/// only on the scene's extent). Single-precision intersection needs a
/// larger fraction.
pub fn epsilon(bounds: &Aabb, precision: Precision) -> f64 {
    let size = bounds.diagonal().max(bounds.max_abs_coord());
    let size = if size > 0.0 { size } else { 1.0 };
    match precision {
        Precision::Double => size * 1e-7,
        Precision::Single => size * 2e-4,
    }
}

/// The lights of a scene with their colours resolved, as shading uses them.
pub fn shade_scene(
    h: &SceneHeader,
    max_depth: u8,
    eps: f64,
) -> Result<ShadeScene, crate::error::Error> {
    ShadeScene::new(h, max_depth, eps)
}

pub use crate::shapes::KindCounts;
use serde::Serialize;
use std::ops::AddAssign;

/// The SPD's statistics: the same for every tracer on the same scene.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct RayCounts {
    pub eye_rays: u64,
    pub eye_hit_rays: u64,
    pub reflect_rays: u64,
    pub refract_rays: u64,
    pub shadow_rays: u64,
}

impl AddAssign for RayCounts {
    fn add_assign(&mut self, o: Self) {
        self.eye_rays += o.eye_rays;
        self.eye_hit_rays += o.eye_hit_rays;
        self.reflect_rays += o.reflect_rays;
        self.refract_rays += o.refract_rays;
        self.shadow_rays += o.shadow_rays;
    }
}

/// Everything `--stats` reports. Fields that only one tracer has are
/// omitted for the other.
#[derive(Clone, Debug, Default, Serialize)]
pub struct RenderStats {
    pub mode: String,
    pub mode_reason: String,
    pub objects: u64,
    pub width: u32,
    pub height: u32,
    pub depth: u8,
    pub threads: usize,
    pub precision: String,
    /// The SIMD instruction set of the intersection kernels (`avx512`,
    /// `avx2`, `sse`, `neon`, `portable`), for the tracers that use them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub simd: Option<String>,
    pub epsilon: f64,
    #[serde(flatten)]
    pub rays: RayCounts,
    pub intersection_tests: u64,
    pub intersection_tests_by_kind: KindCounts,
    /// Resolution of the main grid.
    pub grid_res: [u32; 3],
    /// Every grid: objects, resolution, bounds.
    pub grids: Vec<crate::grid::GridStat>,
    pub convert_seconds: f64,
    pub preprocess_seconds: f64,
    pub trace_seconds: f64,
    /// The trace time split into intersection tests and shading: always for
    /// the breadth-first tracer; for the depth-first one with `profile`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub intersect_seconds: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shade_seconds: Option<f64>,
    pub total_seconds: f64,
    pub peak_rss_bytes: u64,
    /// Texture tiles read from the database (scenes with tiled textures).
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub textures: Option<crate::texture::TileReads>,
    /// Statistics of one tracer (breadth-first passes, the cluster's
    /// traffic, depth-first paging), flattened into the same object.
    #[serde(flatten)]
    pub details: Option<serde_json::Value>,
}

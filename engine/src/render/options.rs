use super::sampling::Sampling;
use crate::error::Error;
use serde::Serialize;

/// Which tracer runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// In memory, a ray tree at a time (the fast path for scenes that fit).
    Df,
    /// Rays in memory, objects streamed from disk (Nakamaru and Ohno).
    Bf,
    /// Depth-first when the scene fits in the memory budget, else
    /// breadth-first (the paper's Fig. 1).
    Auto,
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Mode, String> {
        match s {
            "df" => Ok(Mode::Df),
            "bf" => Ok(Mode::Bf),
            "auto" => Ok(Mode::Auto),
            _ => Err(format!("unknown mode '{s}' (expected df, bf or auto)")),
        }
    }
}

/// Arithmetic of the intersection tests.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    Single,
    Double,
}

impl std::str::FromStr for Precision {
    type Err = String;
    fn from_str(s: &str) -> Result<Precision, String> {
        match s {
            "single" | "f32" => Ok(Precision::Single),
            "double" | "f64" => Ok(Precision::Double),
            _ => Err(format!(
                "unknown precision '{s}' (expected single or double)"
            )),
        }
    }
}

/// Which tracers hold crowded groups of objects as aggregates, each with
/// a hierarchy of its own (see [`crate::grid::aggregate`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Aggregates {
    /// Breadth-first only. A depth-first voxel too crowded for a list
    /// gets a hierarchy of its objects, which was measured faster than
    /// aggregates held by their boxes (BENCHMARKS.md, "Aggregates").
    #[default]
    Auto,
    /// Both tracers.
    On,
    /// Neither: objects are tested one by one, as the paper does.
    Off,
}

impl Aggregates {
    pub fn breadth_first(self) -> bool {
        self != Aggregates::Off
    }

    pub fn depth_first(self) -> bool {
        self == Aggregates::On
    }
}

/// Grid resolution: chosen from the scene, or given.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum GridRes {
    Auto,
    Fixed([u32; 3]),
}

impl std::str::FromStr for GridRes {
    type Err = String;
    /// `auto`, `N` (N per axis) or `NxMxK`.
    fn from_str(s: &str) -> Result<GridRes, String> {
        if s == "auto" {
            return Ok(GridRes::Auto);
        }
        let parts: Vec<&str> = s.split('x').collect();
        let nums: Result<Vec<u32>, _> = parts.iter().map(|p| p.parse::<u32>()).collect();
        let bad = || format!("grid resolution '{s}' must be auto, N or NxMxK with 1 <= N <= 4096");
        let nums = nums.map_err(|_| bad())?;
        if nums.iter().any(|&n| n == 0 || n > 4096) {
            return Err(bad());
        }
        match nums[..] {
            [n] => Ok(GridRes::Fixed([n, n, n])),
            [a, b, c] => Ok(GridRes::Fixed([a, b, c])),
            _ => Err(bad()),
        }
    }
}

/// Everything that shapes a render besides the scene.
#[derive(Clone, Debug, Serialize)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    /// Maximum depth of the ray tree; the eye ray is depth 1.
    pub max_depth: u8,
    /// Worker threads (0 = all cores).
    pub threads: usize,
    pub grid_res: GridRes,
    /// Voxels per object when the resolution is chosen automatically.
    pub grid_density: f64,
    /// Allow the scene to be split into several grids (`--grids 1` = no).
    pub multiple_grids: bool,
    /// Which tracers hold crowded groups of objects as aggregates.
    pub aggregates: Aggregates,
    pub precision: Precision,
    /// Time the depth-first tracer's intersection queries, to split its
    /// trace time into intersection and shading (costs a little time).
    pub profile: bool,
    /// Eye rays per pixel: 1 traces the pixel corners (the contract's
    /// sampling); a square from 4 up takes jittered samples.
    pub samples: u32,
    /// The kernels' instruction set, when forced (`--simd`); else
    /// `SRAY_SIMD`, else the widest the CPU has. Images and counts are the
    /// same with every one.
    pub simd: Option<crate::simd::Isa>,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            width: 512,
            height: 512,
            max_depth: 5,
            threads: 0,
            grid_res: GridRes::Auto,
            grid_density: crate::grid::DEFAULT_DENSITY,
            multiple_grids: true,
            aggregates: Aggregates::Auto,
            precision: Precision::Double,
            profile: false,
            samples: 1,
            simd: None,
        }
    }
}

/// Largest image side accepted.
pub const MAX_IMAGE_SIDE: u32 = 32_768;
/// Deepest ray tree accepted.
pub const MAX_DEPTH: u8 = 64;

impl RenderOptions {
    pub fn validate(&self) -> Result<(), Error> {
        if self.width == 0
            || self.height == 0
            || self.width > MAX_IMAGE_SIDE
            || self.height > MAX_IMAGE_SIDE
        {
            return Err(Error::Invalid(format!(
                "image size {}x{} is out of range (1..={MAX_IMAGE_SIDE} per side)",
                self.width, self.height
            )));
        }
        if !(self.grid_density > 0.0 && self.grid_density <= 1000.0) {
            return Err(Error::Invalid(format!(
                "grid density {} is out of range (0, 1000] voxels per object",
                self.grid_density
            )));
        }
        if let GridRes::Fixed(r) = self.grid_res {
            let cells: u64 = r.iter().map(|&n| n as u64).product();
            if cells > crate::grid::MAX_CELLS {
                return Err(Error::Invalid(format!(
                    "grid resolution {}x{}x{} has {cells} voxels, more than the {} a grid may have; choose a coarser --grid-res",
                    r[0],
                    r[1],
                    r[2],
                    crate::grid::MAX_CELLS
                )));
            }
        }
        Sampling::new(self.samples)?;
        if self.max_depth == 0 || self.max_depth > MAX_DEPTH {
            return Err(Error::Invalid(format!(
                "depth {} is out of range 1..={MAX_DEPTH} (the eye ray is depth 1)",
                self.max_depth
            )));
        }
        Ok(())
    }

    /// How eye rays sample the image (`samples` checked by `validate`).
    pub fn sampling(&self) -> Sampling {
        Sampling::new(self.samples).unwrap_or(Sampling::Corners)
    }

    /// Number of eye rays.
    pub fn eye_rays(&self) -> u64 {
        self.sampling().eye_rays(self.width, self.height)
    }

    /// Accumulators of the frame (pixel corners, or pixels).
    pub fn frame_slots(&self) -> u64 {
        self.sampling().slots(self.width, self.height)
    }
}

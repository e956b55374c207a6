//! Rust generators for Eric Haines' Standard Procedural Databases, written
//! from the SPD's description of each construction. They stream objects in
//! the SPD's order straight into a [`SceneSink`], so a scene of any size
//! factor needs no NFF text and constant memory.

mod balls;
mod gears;
mod matrix;
mod mount;
mod out;
mod rings;
mod teapot;
mod teapot_data;
mod tetra;
mod tree;

use crate::error::Error;
use crate::progress::Progress;
use crate::scene::SceneSink;
use out::Out;
use std::fmt;
use std::str::FromStr;

/// One of the seven SPD scenes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SpdScene {
    Balls,
    Gears,
    Mount,
    Rings,
    Tetra,
    Tree,
    Teapot,
}

impl SpdScene {
    pub const ALL: [SpdScene; 7] = [
        SpdScene::Balls,
        SpdScene::Gears,
        SpdScene::Mount,
        SpdScene::Rings,
        SpdScene::Tetra,
        SpdScene::Tree,
        SpdScene::Teapot,
    ];

    pub fn name(self) -> &'static str {
        match self {
            SpdScene::Balls => "balls",
            SpdScene::Gears => "gears",
            SpdScene::Mount => "mount",
            SpdScene::Rings => "rings",
            SpdScene::Tetra => "tetra",
            SpdScene::Tree => "tree",
            SpdScene::Teapot => "teapot",
        }
    }

    /// The size factor of the paper's default scenes (teapot: the SPD's
    /// usual 12).
    pub fn default_size(self) -> u32 {
        match self {
            SpdScene::Balls => 4,
            SpdScene::Gears => 4,
            SpdScene::Mount => 6,
            SpdScene::Rings => 7,
            SpdScene::Tetra => 6,
            SpdScene::Tree => 11,
            SpdScene::Teapot => 12,
        }
    }

    /// Number of objects the SPD program writes for size factor `size`,
    /// or `None` if `size` is out of range.
    pub fn object_count(self, size: u32) -> Option<u64> {
        if size == 0 {
            return None;
        }
        let n = size as u128;
        let count: u128 = match self {
            // 1 + 9 + 81 + ... + 9^size spheres, and the floor.
            SpdScene::Balls => {
                if size > 12 {
                    return None;
                }
                (0..=size).map(|k| 9u128.pow(k)).sum::<u128>() + 1
            }
            // size^3 gears of 2 faces and 4*36 sides, and the ground.
            SpdScene::Gears => n * n * n * 146 + 1,
            // 2 * 4^size triangles and 4 spheres.
            SpdScene::Mount => {
                if size > 20 {
                    return None;
                }
                2 * 4u128.pow(size) + 4
            }
            // 5 n (n+1)(2n+1) cylinders and as many spheres, and the wall.
            SpdScene::Rings => 2 * 5 * n * (n + 1) * (2 * n + 1) + 1,
            SpdScene::Tetra => {
                if size > 20 {
                    return None;
                }
                4u128.pow(size)
            }
            SpdScene::Tree => {
                if size > 40 {
                    return None;
                }
                2 * ((1u128 << (size + 1)) - 1) + 1
            }
            // n^2 squares; 32 patches of 2 n^2 triangles less the n
            // degenerate ones at each of the 8 cusp patches.
            SpdScene::Teapot => n * n + 64 * n * n - 8 * n,
        };
        u64::try_from(count).ok()
    }

    /// Largest size factor whose object count fits the database's 32-bit
    /// object ids.
    pub fn max_size(self) -> u32 {
        let mut s = 1;
        while self
            .object_count(s + 1)
            .is_some_and(|c| c <= u32::MAX as u64)
        {
            s += 1;
        }
        s
    }

    /// Streams the scene into `sink`, reporting objects written.
    pub fn generate(
        self,
        size: u32,
        sink: &mut dyn SceneSink,
        progress: &dyn Progress,
    ) -> Result<(), Error> {
        let max = self.max_size();
        if size == 0 || size > max {
            return Err(Error::Invalid(format!(
                "{} size factor {size} is out of range 1..={max}",
                self.name()
            )));
        }
        if let Some(n) = self.object_count(size) {
            progress.set_total(n);
        }
        let mut out = Out::new(sink, progress);
        match self {
            SpdScene::Balls => balls::generate(&mut out, size)?,
            SpdScene::Gears => gears::generate(&mut out, size)?,
            SpdScene::Mount => mount::generate(&mut out, size)?,
            SpdScene::Rings => rings::generate(&mut out, size)?,
            SpdScene::Tetra => tetra::generate(&mut out, size)?,
            SpdScene::Tree => tree::generate(&mut out, size)?,
            SpdScene::Teapot => teapot::generate(&mut out, size)?,
        }
        out.finish();
        Ok(())
    }
}

impl fmt::Display for SpdScene {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for SpdScene {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        SpdScene::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown SPD scene '{s}' (expected one of: {})",
                    SpdScene::ALL.map(|k| k.name()).join(", ")
                )
            })
    }
}

/// The UNC sky blue all SPD scenes share.
const SKY: [f64; 3] = [0.078, 0.361, 0.753];

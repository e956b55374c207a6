//! sray's engine: everything that renders, no networking.
//!
//! - [`scene`]: the scene model and the [`scene::SceneSink`] scene sources
//!   stream into;
//! - [`nff`]: the Neutral File Format, read in constant memory;
//! - [`mesh`]: polygon meshes (PLY, OBJ, OFF), read in bounded memory;
//! - [`spd`]: generators for the Standard Procedural Databases;
//! - [`sdb`]: the object database, read strictly front to back;
//! - [`source`]: scene sources (`.nff`, `.sdb`, `spd:NAME:SIZE`);
//! - [`info`]: what a scene file holds (`sray info`).

pub mod bf;
pub mod df;
pub mod error;
pub mod fsutil;
pub mod grid;
pub mod hit;
pub mod info;
pub mod input;
pub mod intersect;
pub mod job;
pub mod kernels;
pub mod math;
pub mod mesh;
pub mod models;
pub mod nff;
pub mod objects;
pub mod paging;
pub mod progress;
pub mod render;
pub mod scene;
pub mod sdb;
pub mod shapes;
pub mod simd;
pub mod source;
pub mod spd;
pub mod spill;
pub mod sys;
pub mod texture;
pub mod units;

pub use error::Error;

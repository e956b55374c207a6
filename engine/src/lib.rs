//! sray's engine: everything that renders, no networking.
//!
//! The modules in the order a scene flows through them, from a file on
//! disk to the pixels of an image.
//!
//! **1. A scene comes in.**
//! - [`source`]: names a scene: a scene file, an object database, or an
//!   SPD generator (`spd:NAME:SIZE`);
//! - [`input`]: opens a scene file, decompressing gzip or zstd on the fly;
//! - [`nff`], [`mesh`] (PLY, OBJ, OFF and glTF) and [`spd`]: the readers and
//!   generators, each streaming objects in bounded memory into
//! - [`scene`]: the scene model (view, lights, materials, background) and
//!   the [`scene::SceneSink`] every reader writes to;
//! - [`shapes`]: the primitive kinds (sphere, polygon, patch, cone,
//!   instance), one file each.
//!
//! **2. It is stored once, read front to back.**
//! - [`sdb`]: the object database (`.sdb`), the paper's preprocessed scene,
//!   written once and read strictly sequentially, optionally compressed;
//! - [`models`]: models placed by instances, stored once (their grids
//!   are the depth-first tracer's, [`df::models`]);
//! - [`info`]: what a scene file or database holds (`sray info`).
//!
//! **3. Space is divided.**
//! - [`grid`]: uniform spatial subdivision: grid geometry, voxel ranges,
//!   the 3D-DDA, the resolution and the multiple grids of a non-uniform
//!   scene;
//! - [`math`]: the arithmetic everything shares (vectors, boxes, both
//!   precisions).
//!
//! **4. Rays meet objects.**
//! - [`intersect`]: the scalar intersection tests and the ray they take;
//! - [`simd`] and [`kernels`]: the same tests, one primitive against many
//!   rays, on the widest SIMD instruction set the CPU has, bit for bit;
//! - [`hit`]: which primitive a ray hit, and the rule between equal hits.
//!
//! **5. Two tracers.**
//! - [`df`]: depth-first, every object in memory ([`objects`]), rays
//!   walked in packets through the grids; for scenes that fit the budget
//!   ([`paging`] lets a forced one page to disk);
//! - [`bf`]: breadth-first (Nakamaru and Ohno): rays in memory, the
//!   database streamed through the grids once per pass; what every
//!   cluster worker runs;
//! - [`spill`]: temporary files and the external sort the breadth-first
//!   tracer spills to when rays outgrow memory.
//!
//! **6. Pixels come out.**
//! - [`render`]: what both tracers share: camera, shading, frame buffer,
//!   options and statistics;
//! - [`texture`]: image textures (PNG, JPEG) decoded and sampled as glTF
//!   means them (wrap modes, nearest and bilinear filters, transforms);
//! - [`job`]: one render start to finish: resolve the scene, pick the
//!   tracer by size against the memory budget, trace, write the image;
//! - [`fsutil`]: output written atomically; [`progress`]: progress of long
//!   work; [`error`]: the one error type.
//!
//! Small helpers: [`units`] (sizes in bytes as people write them) and
//! [`sys`] (facts about this process, such as its peak memory).

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

pub use df::models;
pub use error::Error;

//! Polygon meshes: PLY, OBJ and OFF files, streamed in bounded memory;
//! and glTF 2.0 scenes of placed meshes ([`gltf_scene`]).
//!
//! A mesh file is a table of vertices and faces that refer to them by
//! index, anywhere in the file. Each reader parses its format into a
//! [`MeshBuilder`], which keeps the tables within a memory budget (on disk
//! when they do not fit) and then resolves faces against vertices, by
//! lookup or by an external join, streaming the faces into a scene sink in
//! file order. See [`builder`] for the join and [`geometry`] for what
//! becomes of each face (polygons kept where planar, others triangulated,
//! degenerate ones skipped).
//!
//! Every reader names the file and the line (text) or byte offset (binary)
//! of bad input, never panics, and never allocates by a count in the file
//! beyond what the file holds.

pub mod builder;
pub mod geometry;
mod gltf_data;
pub mod gltf_scene;
mod mtl;
pub mod obj;
pub mod off;
pub mod ply;
pub(crate) mod text;

pub use builder::{MeshBuilder, MeshSummary, NEUTRAL};

use crate::progress::Progress;
use std::path::PathBuf;

/// How a mesh reader may use memory and disk.
#[derive(Clone, Debug)]
pub struct MeshOptions {
    /// Bytes of vertex and face tables and sort buffers held at most.
    pub memory: u64,
    /// Where tables and sort runs spill (the system's temp directory if
    /// `None`).
    pub spill_dir: Option<PathBuf>,
    /// A glTF scene's camera to look through (see
    /// [`crate::scene::setup::Setup::camera_index`]).
    pub camera_index: Option<usize>,
}

impl Default for MeshOptions {
    fn default() -> Self {
        MeshOptions {
            memory: crate::sys::default_memory_budget(),
            spill_dir: None,
            camera_index: None,
        }
    }
}

/// Warnings a reader collects and reports once each, with a count.
#[derive(Default)]
pub(crate) struct Warnings {
    items: Vec<(String, u64, String)>,
}

impl Warnings {
    /// Counts one occurrence of a kind of problem; `first` describes
    /// where it first happened.
    pub fn add(&mut self, kind: &str, first: impl FnOnce() -> String) {
        if let Some(w) = self.items.iter_mut().find(|w| w.0 == kind) {
            w.1 += 1;
        } else if self.items.len() < 64 {
            self.items.push((kind.to_string(), 1, first()));
        }
    }

    pub fn report(&self, name: &std::path::Path, progress: &dyn Progress) {
        for (kind, n, first) in &self.items {
            if *n == 1 {
                progress.warn(&format!("{}: {kind} ({first})", name.display()));
            } else {
                progress.warn(&format!(
                    "{}: {kind}, {n} times (first {first})",
                    name.display()
                ));
            }
        }
    }
}

/// Reports the summary warning of degenerate faces.
pub(crate) fn report_summary(name: &std::path::Path, s: &MeshSummary, progress: &dyn Progress) {
    if s.degenerate > 0 {
        progress.warn(&format!(
            "{}: skipped {} of {} faces as degenerate (repeated or collinear vertices, no area)",
            name.display(),
            s.degenerate,
            s.faces
        ));
    }
}
